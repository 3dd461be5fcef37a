"""Modal analysis of a planetary gear set: Lin & Parker's translational–rotational model.

Lin & Parker (1999, *J. Vib. Acoust.* 121:316) model sun, ring, carrier and N planets as rigid
bodies with two translations and one rotation each, connected by the mean mesh stiffnesses along
the lines of action and by bearings (springs). At mean stiffness and zero speed (gyroscopic and
centripetal terms dropped, as in their free-vibration analysis) the free vibration solves the
symmetric generalised eigenproblem

    K phi = omega^2 M phi,        f = omega / (2 pi)  (Hz).

**Coordinates (Lin & Parker's, not the twin's).** Bodies in the twin's order sun, ring, carrier,
planets 0..N-1 (docs/conventions.md), three coordinates each, all in metres:

- central member h in (s, r, c): ``x_h, y_h`` = translation in the carrier frame (the twin's
  ``x, y``), ``u_h = r_h theta_h`` with ``r_h`` the base radius (sun, ring) or the centre
  distance ``a`` (carrier) and ``theta_h`` the twin's absolute rotation;
- planet i: ``zeta_i, eta_i`` = *absolute* radial and tangential displacement of the planet
  centre (carrier-frame directions ``e_r(psi_i)``, ``e_t(psi_i)``), ``u_i = rb_p theta_p_i``.
  The twin measures the planet centre relative to its pin, so
  ``zeta_LP = zeta + x_c cos psi_i + y_c sin psi_i`` and
  ``eta_LP = eta - x_c sin psi_i + y_c cos psi_i + a theta_c``
  (conventions.md abbreviates this to "eta_LP = eta + a theta_c" for a carrier that does not
  translate). :func:`lin_parker_transform` gives the matrix ``T`` with ``q_LP = T q_twin``.

Masses: ``m`` on translations, ``I / r^2 = J / r^2`` (kg) on ``u``; the carrier's ``J`` excludes
the planets, whose translational inertia enters through ``zeta_i, eta_i``. Torsional supports
given in N·m/rad act on ``u`` as ``k_theta / r^2`` (N/m).

Mesh deflections (Lin & Parker's eqs., compression positive), ``psi_sn = psi_i - alpha_sp``,
``psi_rn = psi_i + alpha_rp``:

    delta_sp_i = -x_s sin psi_sn + y_s cos psi_sn - zeta_i sin alpha_sp - eta_i cos alpha_sp + u_s + u_i
    delta_rp_i = -x_r sin psi_rn + y_r cos psi_rn + zeta_i sin alpha_rp - eta_i cos alpha_rp + u_r - u_i

i.e. ``delta_sp = e_t(psi - alpha_sp).(d_s - d_p) + u_s + u_p`` and
``delta_rp = e_t(psi + alpha_rp).(d_r - d_p) + u_r - u_p``. In the twin's notation the
ring-mesh line ``e_t(psi + alpha_rp) = -n_rp``: the translational part of the ring-mesh
deflection is ``n_rp . (d_p - d_r)`` (the planet pushes the ring along ``n_rp``). Planet bearing
deflection = planet centre minus pin: ``(zeta_i - x_c cos psi_i - y_c sin psi_i,
eta_i + x_c sin psi_i - y_c cos psi_i - u_c)``. Lin & Parker's ``u`` coordinates hide the radii:
the model presumes kinematically compatible geometry, ``rb_s + rb_p = a cos alpha_sp`` and
``rb_r - rb_p = a cos alpha_rp`` (which ``dtwin.model.gears`` guarantees), and for an example given in
Lin & Parker's own terms any radii may be used (:func:`lin_parker_example` uses 1 m so that
``J = I / r^2`` numerically).

**Torsional reduction** keeps the rotations ``(u_s, u_r, u_c, u_0..u_{N-1})``: translations of
the central members are zero and every planet rides rigidly on its pin (``zeta_LP = 0``,
``eta_LP = u_c``), so ``M_t = T_t^T M T_t``, ``K_t = T_t^T K T_t``; the carrier then carries
``N m_p`` on ``u_c`` (``N m_p a^2`` in kg·m²) and the planet bearings drop out.

**Mode types** (Lin & Parker's classification). For a mass-normalised mode ``phi`` the fractions
of its kinetic energy (``sum M_jj phi_j^2 = 1``) in the central members' translations (``T``) and
rotations (``R``) decide, per group of equal frequencies (relative tolerance ``rtol``):

- ``"rotational"``: ``T < tol`` and ``R >= tol`` (central members only rotate; multiplicity 1);
- ``"translational"``: ``R < tol`` and ``T >= tol`` (central members only translate; pairs);
- ``"planet"``: ``T < tol`` and ``R < tol`` (central members still; multiplicity N - 3 in the
  translational model, N - 1 in the torsional reduction);
- ``"mixed"``: neither (only with unequal planet spacing or other asymmetry).

The torsional reduction has only rotational and planet modes.

Everything up to the eigenvalues is pure JAX: :func:`natural_frequencies` is jittable and
differentiable (e.g. ``jax.jacfwd`` with respect to ``k_sun_planet``; eigenvalue derivatives are
``phi^T dK phi``, the modal strain energy in the changed springs).
"""

from __future__ import annotations

import math
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..errors import ParameterError, SpecError
from .lumped import LumpedParameters, make_lumped
from .lumped import replace as _replace

Model = Literal["translational", "torsional"]
MODELS: tuple[str, ...] = ("translational", "torsional")
MODE_TYPES: tuple[str, ...] = ("rotational", "translational", "planet", "mixed")

_CENTRAL = ("s", "r", "c")


def _check_model(model: str) -> None:
    if model not in MODELS:
        raise SpecError(
            [("model", f"unknown modal model {model!r}; use 'translational' or 'torsional'")]
        )


def coordinate_names(n_planets: int, model: Model = "translational") -> tuple[str, ...]:
    """Names of the modal coordinates in order, e.g. ``("x_s", "y_s", "u_s", ..., "u_p2")``.

    **Arguments:**

    - `n_planets`: number of planets N.
    - `model`: ``"translational"`` (3(N+3) coordinates) or ``"torsional"`` (N+3).

    **Returns:** a tuple of names; ``x, y`` translations and ``u = r theta`` (m) of sun ``s``, ring
    ``r``, carrier ``c``; planet i: ``zeta_pi``, ``eta_pi``, ``u_pi`` (Lin & Parker's coordinates).
    """
    _check_model(model)
    if model == "torsional":
        return tuple(f"u_{h}" for h in _CENTRAL) + tuple(f"u_p{i}" for i in range(n_planets))
    names: list[str] = []
    for h in _CENTRAL:
        names += [f"x_{h}", f"y_{h}", f"u_{h}"]
    for i in range(n_planets):
        names += [f"zeta_p{i}", f"eta_p{i}", f"u_p{i}"]
    return tuple(names)


def _n_full(lp: LumpedParameters) -> int:
    return 3 * (lp.n_planets + 3)


def _torsional_reduction(lp: LumpedParameters) -> Float[Array, "full reduced"]:
    """Constraint matrix ``T_t`` with ``q_LP = T_t q_t`` (planets ride on their pins)."""
    n = lp.n_planets
    t = np.zeros((_n_full(lp), n + 3))
    for j in range(3):  # u_s, u_r, u_c
        t[3 * j + 2, j] = 1.0
    for i in range(n):
        base = 9 + 3 * i
        t[base + 1, 2] = 1.0  # eta_i = u_c (pin moves tangentially with the carrier)
        t[base + 2, 3 + i] = 1.0  # u_i
    return jnp.asarray(t, dtype=jnp.float64)


def _full_mass_matrix(lp: LumpedParameters) -> Float[Array, "dof dof"]:
    one = jnp.ones((), dtype=jnp.float64)
    diag = [
        lp.m_sun * one, lp.m_sun * one, lp.J_sun / lp.rb_sun**2,
        lp.m_ring * one, lp.m_ring * one, lp.J_ring / lp.rb_ring**2,
        lp.m_carrier * one, lp.m_carrier * one, lp.J_carrier / lp.centre_distance**2,
    ]
    for _ in range(lp.n_planets):
        diag += [lp.m_planet * one, lp.m_planet * one, lp.J_planet / lp.rb_planet**2]
    return jnp.diag(jnp.stack(diag))


@eqx.filter_jit
def mass_matrix(lp: LumpedParameters, model: Model = "translational") -> Float[Array, "dof dof"]:
    """Mass matrix in Lin & Parker's coordinates (kg).

    ``M = diag(m_s, m_s, J_s/rb_s^2, m_r, m_r, J_r/rb_r^2, m_c, m_c, J_c/a^2,
    [m_p, m_p, J_p/rb_p^2] * N)``; the torsional reduction is ``T_t^T M T_t`` (its carrier entry
    is ``J_c/a^2 + N m_p``).

    **Arguments:**

    - `lp`: lumped parameters (masses kg, inertias kg·m², radii m).
    - `model`: ``"translational"`` or ``"torsional"``.

    **Returns:** symmetric positive-definite matrix, shape (3(N+3), 3(N+3)) or (N+3, N+3), kg.

    Reference: Lin & Parker (1999), eq. (2).
    """
    _check_model(model)
    m = _full_mass_matrix(lp)
    if model == "torsional":
        t = _torsional_reduction(lp)
        return t.T @ m @ t
    return m


def _e_t(angle: Float[Array, "..."]) -> Float[Array, "... 2"]:
    return jnp.stack([-jnp.sin(angle), jnp.cos(angle)], axis=-1)


def _spring_vectors(
    lp: LumpedParameters,
) -> tuple[Float[Array, "N dof"], Float[Array, "N dof"], Float[Array, "2N dof"]]:
    """Deflection gradients ``g`` (delta = g . q) of the sun meshes, ring meshes, planet bearings."""
    n = lp.n_planets
    psi = lp.planet_angles
    a_s, a_r = lp.alpha_sp, lp.alpha_rp
    one = jnp.ones((n, 1), dtype=jnp.float64)
    zero3 = jnp.zeros((n, 3), dtype=jnp.float64)
    eye = jnp.eye(n, dtype=jnp.float64)
    # sun mesh: e_t(psi - a_s).(d_s - d_p) + u_s + u_p
    sun = jnp.concatenate([_e_t(psi - a_s), one], axis=1)
    row_sp = jnp.stack([-jnp.sin(a_s), -jnp.cos(a_s), jnp.ones((), dtype=jnp.float64)])
    g_sp = jnp.concatenate([sun, zero3, zero3, jnp.kron(eye, row_sp[None, :])], axis=1)
    # ring mesh: e_t(psi + a_r).(d_r - d_p) + u_r - u_p
    ring = jnp.concatenate([_e_t(psi + a_r), one], axis=1)
    row_rp = jnp.stack([jnp.sin(a_r), -jnp.cos(a_r), -jnp.ones((), dtype=jnp.float64)])
    g_rp = jnp.concatenate([zero3, ring, zero3, jnp.kron(eye, row_rp[None, :])], axis=1)
    # planet bearing: radial zeta - x_c cos psi - y_c sin psi,
    #                 tangential eta + x_c sin psi - y_c cos psi - u_c
    c, s_ = jnp.cos(psi), jnp.sin(psi)
    zero = jnp.zeros_like(psi)
    carrier = jnp.stack(
        [jnp.stack([-c, -s_, zero], axis=1), jnp.stack([s_, -c, -jnp.ones_like(psi)], axis=1)],
        axis=1,
    ).reshape(2 * n, 3)
    pin = jnp.kron(eye, jnp.asarray([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], dtype=jnp.float64))
    zero3b = jnp.zeros((2 * n, 3), dtype=jnp.float64)
    g_b = jnp.concatenate([zero3b, zero3b, carrier, pin], axis=1)
    return g_sp, g_rp, g_b


def _per_planet(value: ArrayLike, n: int, name: str) -> Float[Array, " N"]:
    v = jnp.asarray(value, dtype=jnp.float64)
    if v.ndim > 1 or (v.ndim == 1 and v.shape[0] != n):
        raise SpecError([(name, f"needs a scalar or {n} values (one per planet), got shape {v.shape}")])
    return jnp.broadcast_to(v, (n,))


@eqx.filter_jit
def stiffness_matrix(
    lp: LumpedParameters,
    model: Model = "translational",
    k_sun_planet: ArrayLike | None = None,
    k_ring_planet: ArrayLike | None = None,
    k_torsion_planet: ArrayLike = 0.0,
) -> Float[Array, "dof dof"]:
    """Stiffness matrix in Lin & Parker's coordinates (N/m).

    ``K = sum_i k_sp_i g_sp_i g_sp_i^T + k_rp_i g_rp_i g_rp_i^T + k_p (g_b g_b^T)_i
    + diag(k_bearing on x, y) + diag(k_theta / r^2 on u)`` with ``g`` the deflection gradients of
    the module docstring; the torsional reduction is ``T_t^T K T_t``.

    **Arguments:**

    - `lp`: lumped parameters (stiffnesses N/m, torsional supports N·m/rad, angles rad).
    - `model`: ``"translational"`` or ``"torsional"``.
    - `k_sun_planet`, `k_ring_planet`: mesh stiffnesses (N/m), scalar or one per planet; default
      the mean values ``lp.k_sun_planet``, ``lp.k_ring_planet``.
    - `k_torsion_planet`: torsional spring from each planet's rotation to ground (N·m/rad),
      default 0. Lin & Parker's planets have none; attaching one removes the rigid-body mode.

    **Returns:** symmetric positive-semidefinite matrix (N/m), shape as :func:`mass_matrix`.

    Reference: Lin & Parker (1999), eqs. (1)–(4), Table 1.
    """
    _check_model(model)
    n = lp.n_planets
    k_sp = _per_planet(lp.k_sun_planet if k_sun_planet is None else k_sun_planet, n, "k_sun_planet")
    k_rp = _per_planet(
        lp.k_ring_planet if k_ring_planet is None else k_ring_planet, n, "k_ring_planet"
    )
    k_tp = jnp.asarray(k_torsion_planet, dtype=jnp.float64)
    g_sp, g_rp, g_b = _spring_vectors(lp)
    k_mesh = (g_sp.T * k_sp) @ g_sp + (g_rp.T * k_rp) @ g_rp
    k_bear = lp.k_bearing_planet * (g_b.T @ g_b)
    supports = [
        lp.k_bearing_sun, lp.k_bearing_sun, lp.k_torsion_sun / lp.rb_sun**2,
        lp.k_bearing_ring, lp.k_bearing_ring, lp.k_torsion_ring / lp.rb_ring**2,
        lp.k_bearing_carrier, lp.k_bearing_carrier, lp.k_torsion_carrier / lp.centre_distance**2,
    ]
    zero = jnp.zeros((), dtype=jnp.float64)
    for _ in range(n):
        supports += [zero, zero, k_tp / lp.rb_planet**2]
    k = k_mesh + k_bear + jnp.diag(jnp.stack([jnp.asarray(s, dtype=jnp.float64) for s in supports]))
    k = 0.5 * (k + k.T)
    if model == "torsional":
        t = _torsional_reduction(lp)
        return t.T @ k @ t
    return k


@eqx.filter_jit
def lin_parker_transform(lp: LumpedParameters) -> Float[Array, "dof dof"]:
    """Matrix ``T`` mapping the twin's coordinates to Lin & Parker's: ``q_LP = T q_twin``.

    Twin coordinates per body (sun, ring, carrier, planets; docs/conventions.md): central
    ``x, y`` (m, carrier frame), rotation ``theta`` (rad, absolute); planet ``zeta, eta`` (m,
    relative to the pin), ``theta_p`` (rad, absolute). Then ``u_h = r_h theta_h``,
    ``zeta_LP = zeta + x_c cos psi + y_c sin psi``,
    ``eta_LP = eta - x_c sin psi + y_c cos psi + a theta_c``, ``u_p = rb_p theta_p``.
    The twin's matrices at zero speed are ``T^T M T`` and ``T^T K T``.

    **Arguments:**

    - `lp`: lumped parameters (radii m, planet angles rad).

    **Returns:** square matrix of size 3(N+3) (m per m or m per rad).
    """
    n = lp.n_planets
    nd = _n_full(lp)
    t = jnp.eye(nd, dtype=jnp.float64)
    t = t.at[2, 2].set(lp.rb_sun).at[5, 5].set(lp.rb_ring).at[8, 8].set(lp.centre_distance)
    psi = lp.planet_angles
    for i in range(n):
        p = 9 + 3 * i
        t = t.at[p, 6].set(jnp.cos(psi[i])).at[p, 7].set(jnp.sin(psi[i]))
        t = t.at[p + 1, 6].set(-jnp.sin(psi[i])).at[p + 1, 7].set(jnp.cos(psi[i]))
        t = t.at[p + 1, 8].set(lp.centre_distance)
        t = t.at[p + 2, p + 2].set(lp.rb_planet)
    return t


def _generalised_eigh(
    m: Float[Array, "dof dof"], k: Float[Array, "dof dof"]
) -> tuple[Float[Array, " dof"], Float[Array, "dof dof"]]:
    """Solve ``K phi = lambda M phi`` via Cholesky ``M = L L^T``: ``L^-1 K L^-T v = lambda v``."""
    chol = jnp.linalg.cholesky(m)
    a = jax.scipy.linalg.solve_triangular(chol, k, lower=True)
    a = jax.scipy.linalg.solve_triangular(chol, a.T, lower=True).T
    a = 0.5 * (a + a.T)
    lam, v = jnp.linalg.eigh(a)
    phi = jax.scipy.linalg.solve_triangular(chol.T, v, lower=False)
    return lam, phi


def _frequencies_from_eigenvalues(lam: Float[Array, " dof"]) -> Float[Array, " dof"]:
    """``f = sqrt(max(lambda, 0)) / 2 pi`` with a gradient that stays finite at 0."""
    pos = lam > 0.0
    safe = jnp.where(pos, lam, 1.0)
    return jnp.where(pos, jnp.sqrt(safe), 0.0) / (2.0 * jnp.pi)


@eqx.filter_jit
def natural_frequencies(
    lp: LumpedParameters,
    model: Model = "translational",
    k_sun_planet: ArrayLike | None = None,
    k_ring_planet: ArrayLike | None = None,
    k_torsion_planet: ArrayLike = 0.0,
) -> Float[Array, " dof"]:
    """Natural frequencies (Hz, ascending) of the model at mean mesh stiffness; jittable.

    ``f_j = sqrt(lambda_j) / (2 pi)`` with ``K phi_j = lambda_j M phi_j`` (rigid-body modes give
    0). Differentiable with respect to every float field of `lp` and the stiffness arguments.

    **Arguments:** as :func:`stiffness_matrix`.

    **Returns:** 3(N+3) (translational) or N+3 (torsional) frequencies in Hz.
    """
    m = mass_matrix(lp, model)
    k = stiffness_matrix(lp, model, k_sun_planet, k_ring_planet, k_torsion_planet)
    lam, _ = _generalised_eigh(m, k)
    return _frequencies_from_eigenvalues(lam)


@eqx.filter_jit
def _solve(lp, model, k_sun_planet, k_ring_planet, k_torsion_planet):
    m = mass_matrix(lp, model)
    k = stiffness_matrix(lp, model, k_sun_planet, k_ring_planet, k_torsion_planet)
    lam, phi = _generalised_eigh(m, k)
    return _frequencies_from_eigenvalues(lam), phi, jnp.diag(m)


class ModalResult(eqx.Module):
    """Natural frequencies, mass-normalised mode shapes and mode types of a planetary set.

    **Fields:**

    - `frequencies`: natural frequencies (Hz), ascending, shape (dof,).
    - `mode_shapes`: mass-normalised modes as columns, ``Phi^T M Phi = I``, ``Phi^T K Phi =
      diag((2 pi f)^2)``, in Lin & Parker's coordinates (m per sqrt(kg)), shape (dof, dof).
    - `central_translation`, `central_rotation`: fraction of each mode's kinetic energy in the
      central members' translations / rotations (1), shape (dof,).
    - `mode_types`: ``"rotational"``, ``"translational"``, ``"planet"`` or ``"mixed"`` per mode.
    - `multiplicities`: number of modes sharing each mode's frequency (within ``rtol``).
    - `coordinates`: coordinate names (:func:`coordinate_names`).
    - `model`: ``"translational"`` or ``"torsional"``.
    - `n_planets`: N.
    """

    frequencies: Float[Array, " mode"]
    mode_shapes: Float[Array, "dof mode"]
    central_translation: Float[Array, " mode"]
    central_rotation: Float[Array, " mode"]
    mode_types: tuple[str, ...] = eqx.field(static=True)
    multiplicities: tuple[int, ...] = eqx.field(static=True)
    coordinates: tuple[str, ...] = eqx.field(static=True)
    model: str = eqx.field(static=True)
    n_planets: int = eqx.field(static=True)

    def groups(self) -> list[dict]:
        """Distinct frequencies: one dict per group of equal frequencies, ascending.

        Each dict has ``frequency`` (Hz, mean of the group), ``type``, ``multiplicity`` and
        ``modes`` (indices into `frequencies`).
        """
        out: list[dict] = []
        f = np.asarray(self.frequencies)
        i = 0
        while i < len(f):
            m = self.multiplicities[i]
            idx = list(range(i, i + m))
            out.append(
                {
                    "frequency": float(np.mean(f[idx])),
                    "type": self.mode_types[i],
                    "multiplicity": m,
                    "modes": idx,
                }
            )
            i += m
        return out

    def of_type(self, mode_type: str) -> Float[Array, " k"]:
        """Frequencies (Hz) of all modes of one type, with repetitions, ascending."""
        if mode_type not in MODE_TYPES:
            raise SpecError([("mode_type", f"unknown mode type {mode_type!r}; use one of {MODE_TYPES}")])
        idx = [j for j, t in enumerate(self.mode_types) if t == mode_type]
        return self.frequencies[jnp.asarray(idx, dtype=jnp.int32)] if idx else jnp.zeros(
            (0,), dtype=jnp.float64)


def _group_by_frequency(f: np.ndarray, rtol: float) -> list[list[int]]:
    atol = rtol * float(np.max(f)) if f.size else 0.0
    groups: list[list[int]] = []
    for j, fj in enumerate(f):
        if groups and abs(fj - f[groups[-1][0]]) <= rtol * max(fj, f[groups[-1][0]]) + atol:
            groups[-1].append(j)
        else:
            groups.append([j])
    return groups


def modal_analysis(
    lp: LumpedParameters,
    model: Model = "translational",
    *,
    k_sun_planet: ArrayLike | None = None,
    k_ring_planet: ArrayLike | None = None,
    k_torsion_planet: ArrayLike = 0.0,
    tol: float = 1e-4,
    rtol: float = 1e-6,
) -> ModalResult:
    """Natural frequencies, mass-normalised modes and Lin & Parker mode types.

    Solves ``K phi = (2 pi f)^2 M phi`` (:func:`mass_matrix`, :func:`stiffness_matrix`) by
    Cholesky reduction and ``jnp.linalg.eigh``; groups equal frequencies
    (``|f_i - f_j| <= rtol max(f_i, f_j) + rtol f_max``) and classifies each group by the central
    members' share of kinetic energy (module docstring). Not jittable (returns strings); use
    :func:`natural_frequencies` inside ``jit``/``grad``.

    **Arguments:**

    - `lp`: lumped parameters.
    - `model`: ``"translational"`` (Lin & Parker, 3(N+3) DOF) or ``"torsional"`` (N+3 DOF).
    - `k_sun_planet`, `k_ring_planet`, `k_torsion_planet`: as :func:`stiffness_matrix`.
    - `tol`: energy fraction (1) below which the central translations / rotations count as still.
    - `rtol`: relative tolerance (1) for equal frequencies.

    **Returns:** a :class:`ModalResult`.

    Reference: Lin & Parker (1999), J. Vib. Acoust. 121:316–321, Table 2.
    """
    _check_model(model)
    if not (0.0 < tol < 1.0) or not (0.0 < rtol < 1.0):
        raise SpecError([("tol/rtol", f"tolerances must lie in (0, 1), got tol={tol}, rtol={rtol}")])
    f, phi, m_diag = _solve(lp, model, k_sun_planet, k_ring_planet,
                            jnp.asarray(k_torsion_planet, dtype=jnp.float64))
    names = coordinate_names(lp.n_planets, model)
    energy = m_diag[:, None] * phi**2  # kinetic-energy distribution per mode (columns sum 1)
    trans_idx = [j for j, s in enumerate(names) if s[:2] in ("x_", "y_")]
    rot_idx = [j for j, s in enumerate(names) if s in ("u_s", "u_r", "u_c")]
    t_frac = (
        jnp.sum(energy[jnp.asarray(trans_idx)], axis=0) if trans_idx else jnp.zeros_like(f)
    )
    r_frac = jnp.sum(energy[jnp.asarray(rot_idx)], axis=0)
    f_np, t_np, r_np = np.asarray(f), np.asarray(t_frac), np.asarray(r_frac)
    types: list[str] = [""] * len(f_np)
    mult: list[int] = [0] * len(f_np)
    for g in _group_by_frequency(f_np, rtol):
        tg, rg = float(np.max(t_np[g])), float(np.max(r_np[g]))
        if tg < tol and rg < tol:
            kind = "planet"
        elif tg < tol:
            kind = "rotational"
        elif rg < tol:
            kind = "translational"
        else:
            kind = "mixed"
        for j in g:
            types[j] = kind
            mult[j] = len(g)
    return ModalResult(
        frequencies=f,
        mode_shapes=phi,
        central_translation=t_frac,
        central_rotation=r_frac,
        mode_types=tuple(types),
        multiplicities=tuple(mult),
        coordinates=names,
        model=model,
        n_planets=lp.n_planets,
    )


SENSITIVITY_PARAMETERS: tuple[str, ...] = (
    "k_sun_planet", "k_ring_planet", "k_bearing_sun", "k_bearing_ring", "k_bearing_carrier",
    "k_bearing_planet", "k_torsion_ring",
)


def _check_parameter(parameter: str) -> None:
    if parameter not in LumpedParameters.__dataclass_fields__ or parameter in (
        "z_sun", "z_planet", "z_ring", "n_planets", "planet_angles"
    ):
        raise ParameterError(
            f"cannot differentiate with respect to {parameter!r}; use a scalar float field of "
            f"LumpedParameters such as {', '.join(SENSITIVITY_PARAMETERS)}"
        )


def frequency_sensitivities(
    lp: LumpedParameters,
    parameters: tuple[str, ...] = SENSITIVITY_PARAMETERS,
    model: Model = "translational",
    *,
    relative: bool = True,
) -> dict[str, Float[Array, " dof"]]:
    """Sensitivity of every natural frequency to lumped parameters, by forward-mode autodiff.

    ``relative=True`` gives ``(p / f) df/dp`` (1; 0 for a rigid-body mode): for a stiffness this
    is half the fraction of the mode's strain energy stored in the springs that ``p`` scales,
    ``(p / f) df/dp = phi^T (p dK/dp) phi / (2 lambda)``, so the values of all stiffnesses of one
    mode sum to 1/2 (f is homogeneous of degree 1/2 in the stiffnesses). ``relative=False``
    gives ``df/dp`` (Hz per unit of `p`). One ``jax.jacfwd`` over all `parameters`.

    **Arguments:**

    - `lp`: lumped parameters.
    - `parameters`: names of scalar float fields of :class:`~dtwin.model.lumped.LumpedParameters`
      (registry names), default the mesh, bearing and ring torsional stiffnesses.
    - `model`: ``"translational"`` or ``"torsional"``.
    - `relative`: relative (dimensionless) or absolute sensitivity.

    **Returns:** dict name -> one value per mode, in the order of :func:`natural_frequencies`.
    For a repeated frequency whose degeneracy the parameter preserves (equal planets) the
    derivative is that of the repeated value.
    """
    _check_model(model)
    parameters = tuple(parameters)
    for p in parameters:
        _check_parameter(p)
    rows = _sensitivity(lp, parameters, model, relative)
    return {p: rows[i] for i, p in enumerate(parameters)}


def frequency_sensitivity(
    lp: LumpedParameters,
    parameter: str = "k_sun_planet",
    model: Model = "translational",
    *,
    relative: bool = True,
) -> Float[Array, " dof"]:
    """Sensitivity of every natural frequency to one lumped parameter (see
    :func:`frequency_sensitivities`): ``(p / f) df/dp`` (1) or ``df/dp`` (Hz per unit of `p`).
    """
    return frequency_sensitivities(lp, (parameter,), model, relative=relative)[parameter]


@eqx.filter_jit
def _sensitivity(lp, parameters, model, relative):
    p0 = jnp.stack([jnp.asarray(getattr(lp, p), dtype=jnp.float64) for p in parameters])

    def freqs(p: Float[Array, " P"]) -> Float[Array, " dof"]:
        return natural_frequencies(
            _replace(lp, **{name: p[i] for i, name in enumerate(parameters)}), model)

    f = freqs(p0)
    dfdp = jax.jacfwd(freqs)(p0).T  # (P, dof)
    if not relative:
        return dfdp
    big = f > 1e-6 * jnp.max(f)
    return jnp.where(big[None, :], p0[:, None] * dfdp / jnp.where(big, f, 1.0)[None, :], 0.0)


def lin_parker_example(n_planets: int = 3) -> LumpedParameters:
    """Lin & Parker's (1999) example planetary set (their Table 1), equally spaced planets.

    Masses sun 0.4, ring 2.35, carrier 5.43, planet 0.66 kg; I/r^2 sun 0.39, ring 3.0, carrier
    6.29, planet 0.61 kg; k_sp = k_rp = 5e8 N/m; bearings 1e8 N/m (sun, ring, carrier, planets);
    ring torsional support 1e9 N/m on u_r; sun and carrier torsional 0; pressure angle 24.6 deg
    on both meshes. Lin & Parker give these in their u = r theta coordinates; to carry them in
    `LumpedParameters` all radii (base radii and centre distance) are set to 1 m, so that J
    (kg·m²) equals I/r² (kg) and the ring's 1e9 N/m equals 1e9 N·m/rad. The tooth counts
    (Zs = 30, Zp = 30, Zr = 90, contact ratios 1.6) are placeholders the modal model does not
    use; the radii are not a real gear geometry (only the modal analysis may use this set).

    **Arguments:**

    - `n_planets`: N >= 1 (Lin & Parker's example has 3; their multiplicity results hold for any).

    **Returns:** :class:`~dtwin.model.lumped.LumpedParameters`.
    """
    if n_planets < 1:
        raise SpecError([("n_planets", f"must be >= 1, got {n_planets}")])
    alpha = math.radians(24.6)
    return make_lumped(
        z_sun=30, z_planet=30, z_ring=90, n_planets=n_planets,
        planet_angles=2.0 * np.pi * np.arange(n_planets) / n_planets,
        rb_sun=1.0, rb_planet=1.0, rb_ring=1.0, centre_distance=1.0,
        alpha_sp=alpha, alpha_rp=alpha, eps_sp=1.6, eps_rp=1.6,
        phase0_sp=0.0, phase0_rp=0.0,
        m_sun=0.4, m_ring=2.35, m_carrier=5.43, m_planet=0.66,
        J_sun=0.39, J_ring=3.0, J_carrier=6.29, J_planet=0.61,
        k_sun_planet=5e8, k_ring_planet=5e8,
        k_bearing_sun=1e8, k_bearing_ring=1e8, k_bearing_carrier=1e8, k_bearing_planet=1e8,
        k_torsion_sun=0.0, k_torsion_ring=1e9, k_torsion_carrier=0.0,
        zeta_sun_planet=0.0, zeta_ring_planet=0.0, zeta_support=0.0,
    )


__all__ = [
    "MODELS",
    "MODE_TYPES",
    "ModalResult",
    "coordinate_names",
    "frequency_sensitivities",
    "frequency_sensitivity",
    "lin_parker_example",
    "lin_parker_transform",
    "mass_matrix",
    "modal_analysis",
    "natural_frequencies",
    "stiffness_matrix",
]
