"""Mesh stiffness of spur/helical gear pairs: ISO 6336-1 method B and its time-varying waveform.

Three pieces, all pure JAX functions (jittable, vectorised, differentiable in every float
argument):

1. **Mean stiffness from geometry** (ISO 6336-1:2006, clause 9, method B; docs/references.md §4):
   single-pair stiffness ``c'`` and mean mesh stiffness ``c_gamma_alpha`` of a pair, returned for
   the whole face width in N/m (:func:`single_pair_stiffness`, :func:`mesh_stiffness_mean`).
2. **Waveform over a mesh cycle** (docs/conventions.md, "Mesh stiffness"): double tooth contact
   (``1.75 c'``) for ``frac(phase) in [0, eps - 1)``, single contact (``c'``) for
   ``[eps - 1, 1)``; represented by its Fourier series truncated at `n_harmonics` with Lanczos
   sigma factors, so that it is smooth (an adaptive solver needs no jump times), band-limited
   (no aliasing above ``n_harmonics * f_mesh``) and has exactly the mean ``k_mean``
   (:func:`mesh_stiffness_waveform`, :func:`single_pair_from_mean`).
3. **Static transmission error** excitation (:func:`transmission_error`), a zero-mean sum of
   mesh harmonics in metres.

Phases are in mesh cycles (one cycle = one base pitch of travel along the line of action);
the mesh phase as a function of the shaft angles is :func:`dtwin.model.faults.mesh_phases`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero
from jaxtyping import Array, ArrayLike, Float

from ..errors import SpecError

__all__ = [
    "DOUBLE_CONTACT_FACTOR",
    "ISO_C_M",
    "ISO_C_R",
    "cosine_series",
    "mesh_stiffness_mean",
    "mesh_stiffness_waveform",
    "single_pair_from_mean",
    "single_pair_stiffness",
    "transmission_error",
]

#: Stiffness in double contact relative to single contact (ISO 6336-1: c_gamma_alpha =
#: c' (0.75 eps + 0.25) follows from a rectangular wave c' / 1.75 c').
DOUBLE_CONTACT_FACTOR = 1.75
#: ISO 6336-1 theoretical-to-real correction factor for solid gear blanks.
ISO_C_M = 0.8
#: ISO 6336-1 gear blank factor for solid discs.
ISO_C_R = 1.0

_DEG20 = math.radians(20.0)


def _f64(x: ArrayLike) -> Float[Array, "..."]:
    return jnp.asarray(x, dtype=jnp.float64)


def _is_concrete(x) -> bool:
    """True for values known at trace time (checks use numpy on them: JAX would stage them)."""
    return not isinstance(x, jax.core.Tracer)


def _iso_q_prime(zn1, zn2_inv, x1, x2):
    """ISO 6336-1 (method B) minimum flexibility q' of a tooth pair (mm·µm/N).

    `zn2_inv` is 1/zn2 (0 for an internal gear, whose zn is infinite).
    """
    return (
        0.04723
        + 0.15551 / zn1
        + 0.25791 * zn2_inv
        - 0.00635 * x1
        - 0.11654 * x1 / zn1
        - 0.00193 * x2
        - 0.24188 * x2 * zn2_inv
        + 0.00529 * x1**2
        + 0.00182 * x2**2
    )


def single_pair_stiffness(
    z1: ArrayLike,
    z2: ArrayLike,
    face_width: ArrayLike,
    *,
    x1: ArrayLike = 0.0,
    x2: ArrayLike = 0.0,
    internal: bool = False,
    pressure_angle: ArrayLike = _DEG20,
    tangential_force: ArrayLike | None = None,
    K_A: ArrayLike = 1.0,
    hfp_over_mn: ArrayLike = 1.25,
    beta: ArrayLike = 0.0,
) -> Float[Array, "..."]:
    r"""Single-pair tooth stiffness ``c'`` of a gear pair over the whole face width (N/m).

    ISO 6336-1 method B (docs/references.md §4):

    .. math::

        c' = \frac{1}{q'} C_M C_R C_B \cos\beta
             \left(\frac{F_t K_A / b}{100\ \mathrm{N/mm}}\right)^{1/4} \quad [\mathrm{N/(mm\,µm)}]

    with ``q'`` the polynomial of ISO 6336-1 method B in the virtual tooth numbers
    ``zn = z / cos^3 beta`` and profile shifts, ``C_M = 0.8``, ``C_R = 1`` (solid blanks),
    ``C_B = (1 + 0.5 (1.2 - h_fP/m_n)) (1 - 0.02 (20° - alpha_Pn))`` (alpha in degrees). The
    load factor applies only while the line load ``F_t K_A / b`` is below 100 N/mm (it is 1
    above, and when `tangential_force` is None). The result per mm of face width and per µm
    is multiplied by ``b`` (mm) and 1e6 to give N/m: ``c'[N/m] = c'[N/(mm µm)] * b[m] * 1e9``.

    For an internal mesh (`internal=True`, gear 2 is the ring) ISO 6336-1 takes the ring's
    ``zn`` as infinite in ``q'``. For an external pair, gear 1 is the pinion: if ``z1 > z2`` the
    two gears (and their profile shifts) are swapped, as ISO's coefficients are not symmetric.

    **Arguments:**

    - `z1`, `z2`: tooth numbers (gear 2 is the internal gear when `internal`).
    - `face_width`: common face width b (m).
    - `x1`, `x2`: profile shift coefficients (1).
    - `internal`: True for an internal (ring) mesh.
    - `pressure_angle`: normal pressure angle of the basic rack alpha_Pn (rad).
    - `tangential_force`: nominal transverse tangential force at the reference circle F_t (N),
      or None for a line load of at least 100 N/mm.
    - `K_A`: application factor (1).
    - `hfp_over_mn`: dedendum of the basic rack over the normal module (1).
    - `beta`: helix angle (rad).

    **Returns:** ``c'`` for the whole face width (N/m).

    Reference: ISO 6336-1:2006, clause 9 (tooth stiffness parameters, method B).
    """
    z1, z2, b = _f64(z1), _f64(z2), _f64(face_width)
    x1, x2, beta = _f64(x1), _f64(x2), _f64(beta)
    for name, val in (("z1", z1), ("z2", z2), ("face_width", b)):
        if _is_concrete(val) and bool(np.any(np.asarray(val) <= 0)):
            raise SpecError([(name, f"must be positive, got {val}")])
    cos_b = jnp.cos(beta)
    if not internal:
        swap = z1 > z2
        z1, z2, x1, x2 = (
            jnp.where(swap, z2, z1),
            jnp.where(swap, z1, z2),
            jnp.where(swap, x2, x1),
            jnp.where(swap, x1, x2),
        )
        zn2_inv = cos_b**3 / z2
    else:
        zn2_inv = jnp.zeros_like(z2)
    zn1 = z1 / cos_b**3
    q_prime = _iso_q_prime(zn1, zn2_inv, x1, x2)
    c_th = 1.0 / q_prime  # N/(mm µm)
    alpha_deg = jnp.rad2deg(_f64(pressure_angle))
    c_b = (1.0 + 0.5 * (1.2 - _f64(hfp_over_mn))) * (1.0 - 0.02 * (20.0 - alpha_deg))
    c_iso = c_th * ISO_C_M * ISO_C_R * c_b * cos_b
    if tangential_force is not None:
        line_load = _f64(tangential_force) * _f64(K_A) / (b * 1e3)  # N/mm
        c_iso = c_iso * jnp.minimum(line_load / 100.0, 1.0) ** 0.25
    return c_iso * b * 1e9


def mesh_stiffness_mean(
    z1: ArrayLike,
    z2: ArrayLike,
    face_width: ArrayLike,
    eps_alpha: ArrayLike,
    *,
    x1: ArrayLike = 0.0,
    x2: ArrayLike = 0.0,
    internal: bool = False,
    pressure_angle: ArrayLike = _DEG20,
    tangential_force: ArrayLike | None = None,
    K_A: ArrayLike = 1.0,
    hfp_over_mn: ArrayLike = 1.25,
    beta: ArrayLike = 0.0,
) -> Float[Array, "..."]:
    r"""Mean mesh stiffness ``k_mean = c_gamma_alpha b`` of a gear pair (N/m).

    .. math:: c_{\gamma\alpha} = c' (0.75\,\varepsilon_\alpha + 0.25)

    (ISO 6336-1:2006, clause 9, method B), with ``c'`` from :func:`single_pair_stiffness`
    (already for the whole face width). The same keywords as there.

    **Arguments:** as :func:`single_pair_stiffness`, plus `eps_alpha`, the transverse contact
    ratio (1).

    **Returns:** mean mesh stiffness over a mesh cycle (N/m).
    """
    c1 = single_pair_stiffness(
        z1, z2, face_width, x1=x1, x2=x2, internal=internal, pressure_angle=pressure_angle,
        tangential_force=tangential_force, K_A=K_A, hfp_over_mn=hfp_over_mn, beta=beta,
    )
    return c1 * (0.75 * _f64(eps_alpha) + 0.25)


def single_pair_from_mean(k_mean: ArrayLike, eps_alpha: ArrayLike) -> Float[Array, "..."]:
    r"""Single-pair stiffness ``c'`` that gives the mean `k_mean` at contact ratio `eps_alpha`.

    .. math:: c' = k_{mean} / (0.75\,\varepsilon_\alpha + 0.25)

    Inverse of the ISO 6336-1 mean (docs/conventions.md). **Arguments:** `k_mean` (N/m),
    `eps_alpha` (1). **Returns:** ``c'`` (N/m).
    """
    return _f64(k_mean) / (0.75 * _f64(eps_alpha) + 0.25)


def _materialised(a, b):
    """`(a, b)` unchanged (exact products with 1 and 0), computed once.

    XLA's CPU fusion counts float64 `cos` and `sin` as cheap and re-evaluates them, with
    everything between them and their consumer, inside every fusion that consumes the result;
    the mesh stiffness feeds the mesh force, the stiffness floor and the sensor filter (and, in
    a forward-mode Jacobian, the tangents of each), so the whole harmonic sum ran three to
    five times per vector-field evaluation. A product with the identity is a dot, which XLA
    neither fuses nor duplicates. It also gives the sum one fusion of its own, compiled alike
    in every program, so a twin with a severity-0 fault keeps the healthy stiffness bit for
    bit (`dtwin.model.faults.mesh_stiffnesses`).
    """
    ab = jnp.eye(2, dtype=a.dtype) @ jnp.stack([a, b]).reshape(2, -1)
    return ab[0].reshape(a.shape), ab[1].reshape(b.shape)


def _cosine_series_and_slope(x, coef, slope: bool = True):
    """``sum_n coef_n cos(2 pi n x)`` and its derivative in x (with `slope` False, the sum
    twice: the derivative is not computed).

    The harmonics come from one cosine and one sine per phase by angle addition,
    ``(c_{n+1}, s_{n+1}) = (c_n c_1 - s_n s_1, s_n c_1 + c_n s_1)`` (rounding grows like n ulp:
    ~1e-14 of the amplitude at 200 harmonics), a chain of element-wise products that XLA
    fuses into one loop with the sums."""
    theta = 2.0 * jnp.pi * x
    c1, s1 = jnp.cos(theta), jnp.sin(theta)
    c, s = c1, s1
    y = coef[..., 0] * c1
    d = coef[..., 0] * s1
    for k in range(1, coef.shape[-1]):
        c, s = c * c1 - s * s1, s * c1 + c * s1
        y = y + coef[..., k] * c
        if slope:
            d = d + (k + 1) * coef[..., k] * s
    return _materialised(y, -2.0 * jnp.pi * d if slope else y)


@jax.custom_jvp
def cosine_series(x: Float[Array, "..."], coef: Float[Array, "... m"]) -> Float[Array, "..."]:
    r"""``sum_n coef_n cos(2 pi n x)``, ``n = 1..m`` along the last axis of `coef` (`x` in
    cycles, broadcast against ``coef[..., 0]``).

    Written for the solver's inner loop, where the mesh-stiffness waveform is the twin's most
    expensive operation: the harmonics come from one cosine and one sine per phase by angle
    addition (XLA's float64 cosine costs more than the few products that replace each of
    the `m` cosines), and the derivative rule reuses that recurrence,
    ``d/dx = -2 pi sum_n n coef_n sin(2 pi n x)``, where JAX's rule for `cos` evaluates `m`
    sines more for a tangent; the sum (and its slope) are computed once per evaluation
    (`_materialised`); the speed-up on the paper's gearbox is measured in benchmarks/README.md
    ("Fit"). Agrees with the direct sum to
    rounding (~1e-15 of the amplitude at 12 harmonics); differentiable to any order (the rule
    is itself JAX).
    """
    return _cosine_series_and_slope(x, coef, slope=False)[0]


def _cosine_series_jvp(primals, tangents):
    x, coef = primals
    dx, dcoef = tangents
    y, slope = _cosine_series_and_slope(x, coef)
    dy = jnp.zeros_like(y)
    if not isinstance(dx, SymbolicZero):
        dy = dy + slope * dx
    if not isinstance(dcoef, SymbolicZero):
        dy = dy + cosine_series(x, dcoef)  # linear in the coefficients
    return y, dy


cosine_series.defjvp(_cosine_series_jvp, symbolic_zeros=True)


def _check_eps(eps):
    if _is_concrete(eps) and bool(np.any((np.asarray(eps) < 1.0) | (np.asarray(eps) >= 2.0))):
        raise SpecError(
            [("eps_alpha", f"the single/double contact waveform needs 1 <= eps_alpha < 2, got "
              f"{eps}; check the tooth geometry (addenda, centre distance)")]
        )


def mesh_stiffness_waveform(
    phase: ArrayLike,
    k_mean: ArrayLike,
    eps_alpha: ArrayLike,
    *,
    n_harmonics: int = 12,
) -> Float[Array, "..."]:
    r"""Time-varying mesh stiffness (N/m) as a smooth, band-limited function of the mesh phase.

    The ideal waveform alternates between double contact ``1.75 c'`` for
    ``frac(phase) in [0, d)``, ``d = eps - 1``, and single contact ``c'`` for ``[d, 1)``; with
    ``c' = k_mean / (0.75 eps + 0.25)`` its mean is ``k_mean``. Its Fourier series, truncated
    at ``M = n_harmonics`` and smoothed with Lanczos sigma factors, is

    .. math::

        k(\phi) = k_{mean} + 0.75\,c' \sum_{n=1}^{M} \sigma_n \frac{2 \sin(n \pi d)}{n \pi}
                  \cos\bigl(2\pi n (\phi - d/2)\bigr),
        \qquad \sigma_n = \operatorname{sinc}\frac{n}{M + 1}

    so the mean is exactly ``k_mean`` (every harmonic integrates to zero over a cycle), the
    Gibbs overshoot is suppressed, and the function is smooth in `phase`, `k_mean` and
    `eps_alpha`. Inputs broadcast against each other.

    **Arguments:**

    - `phase`: mesh phase (mesh cycles), any shape.
    - `k_mean`: mean mesh stiffness (N/m).
    - `eps_alpha`: transverse contact ratio, ``1 <= eps < 2`` (1).
    - `n_harmonics`: number of harmonics kept (static int, >= 1).

    **Returns:** stiffness (N/m), the broadcast shape of the inputs.

    Reference: ISO 6336-1 (c' and c_gamma_alpha); C. Lanczos, *Applied Analysis* (1956), ch. IV
    (sigma factors).
    """
    if n_harmonics < 1:
        raise SpecError([("n_harmonics", f"must be >= 1, got {n_harmonics}")])
    phase, k_mean, eps = _f64(phase), _f64(k_mean), _f64(eps_alpha)
    _check_eps(eps)
    c1 = single_pair_from_mean(k_mean, eps)
    d = eps - 1.0
    n = jnp.arange(1, n_harmonics + 1, dtype=jnp.float64)
    sigma = jnp.sinc(n / (n_harmonics + 1))
    coef = sigma * 2.0 * jnp.sin(jnp.pi * n * d[..., None]) / (jnp.pi * n)
    x = phase - 0.5 * d
    x = x - jax.lax.stop_gradient(jnp.round(x))  # reduced to one cycle (accurate cosines)
    ripple = cosine_series(x, coef)
    return k_mean + (DOUBLE_CONTACT_FACTOR - 1.0) * c1 * ripple


def transmission_error(
    phase: ArrayLike,
    amplitude: ArrayLike,
    harmonics: Sequence[float] | ArrayLike = (1.0,),
    phases: Sequence[float] | ArrayLike | None = None,
) -> Float[Array, "..."]:
    r"""Static transmission error of a mesh (m): a zero-mean sum of mesh harmonics.

    .. math:: e(\phi) = A \sum_{h=1}^{H} a_h \sin(2\pi h \phi + \varphi_h)

    **Arguments:**

    - `phase`: mesh phase (mesh cycles), any shape.
    - `amplitude`: A, amplitude of the first listed harmonic when ``a_1 = 1`` (m).
    - `harmonics`: relative amplitudes ``a_h`` of mesh harmonics 1, 2, … (1).
    - `phases`: phase angles ``varphi_h`` (rad), same length as `harmonics`; zeros if None.

    **Returns:** the transmission error (m), shape of `phase`; its mean over a mesh cycle is 0.

    Reference: docs/references.md §4 (typical amplitude 20 µm for a module-5 set).
    """
    phase = _f64(phase)
    a = _f64(harmonics).reshape(-1)
    ph = jnp.zeros_like(a) if phases is None else _f64(phases).reshape(-1)
    if a.shape != ph.shape:
        raise SpecError([("phases", f"needs {a.shape[0]} values (one per harmonic), got "
                          f"{ph.shape[0]}")])
    h = jnp.arange(1, a.shape[0] + 1, dtype=jnp.float64)
    terms = a * jnp.sin(2.0 * jnp.pi * h * phase[..., None] + ph)
    return _f64(amplitude) * jnp.sum(terms, axis=-1)
