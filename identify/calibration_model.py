"""The linearised model of a calibration (:func:`dtwin.identify.calibrate.calibrate`): the twin
prepared with the fitted parameters' layout, its response and Jacobian by forward mode, the
spectral data and the closed-form sensor response, and the Levenberg–Marquardt fits.

**Model.** The twin is simulated once at the record's speed (estimated from its spectrum) and
the sensor signal's first-order response to the fitted parameters is computed with forward-mode
derivatives through the diffrax solve (``jax.jacfwd``). The window coefficients enter after
the ODE and the transmission error linearly, so ``y(θ) = y_0 + J θ`` is exact in the former and
first-order in the latter two. Complex Hann spectra of each record segment then give
``A(θ) = |H(f)| |Z_0 + J_Z θ|``, compared with the measured ``A_meas`` as levels
``20 log10(A + F)`` (``F`` the measured noise floor; model side with its expected noise,
``sqrt(A² + F²)``, as :mod:`dtwin.identify.residuals`) over the bins of the gearbox's line
families (``k f_c`` below the first mesh band, ``m f_m + n f_c`` with ``|n| ≤ 10``) and of every
measured line. Gaussian priors keep undetermined parameters at their initial values.

**Contact.** The linearised response knows nothing of the teeth parting: a transmission error
larger than the mesh's deflection under load fits the records' mesh lines just as well, to
first order, while the twin simulated in full then parts its teeth every mesh cycle — a clipped
contact, whose harmonics reach far above the sampling rate and fold back as lines that move
with the speed (measured on an independent four-planet gearbox: docs/calibration.md, "Teeth
that part"). A healthy gearbox under load keeps its teeth in contact, so the fit does too: the
residuals carry one row per sample of each mesh's least deflection over the planets over one
carrier period, first order in θ like the signal (``d0 + J_d (θ − θ_lin)``, from the same
forward-mode solve), ``max(−d, 0) / (CONTACT_TOL d̄)`` with ``d̄`` the mesh's mean deflection —
zero, and without gradient, while the teeth stay in contact. Where the twin simulated in full
still parts its teeth, the calibration linearises again at its values, where the rows see it.

**Damping.** The mesh damping enters as ``log ζ`` (θ's last entry), and the response is not
first order in it: at a resonance ``Z ∝ 1/ζ``, which the linearised response predicts as
``Z_0 (1 − Δ)`` for ``Z_0 e^{−Δ}``. A fit free to move ``log ζ`` by more than that holds can
buy a lower linearised loss with a damping the twin does not follow (measured on an independent
four-planet gearbox: ζ 0.07 → 0.45 in one linearisation, the full twin 1.7 dB from its
prediction). Each linearisation therefore trusts ``log ζ`` within :func:`zeta_step` of its
point — where the first-order error of a resonant line reaches the departure the calibration
reports (`CalibrationSettings.relinearize_db`) — through one row,
``max(|Δ| − step, 0) / (CONTACT_TOL step)``; a fit that reaches the bound is linearised again
there, so a damping the records ask for is reached in steps the linearisation follows.

**The fits.** Levenberg–Marquardt in coordinates where every Jacobian column has unit norm,
run in short runs (`CalibrationSettings.run_steps`), each started where the last one ended
with column scales taken there, until a run no longer lowers the loss: one long run from
θ = 0 can crawl on a shallow slope far above the minimum.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from dtwin.errors import FitError, SpecError
from dtwin.model.lumped import replace as replace_lumped
from dtwin.model.parts.imperfections import MeshOffsets, load_share_offsets
from dtwin.model.parts.mesh_excitation import MeshExcitation
from dtwin.model.parts.transfer_path import PlanetPassTransferPath, window_cosine_coefficients
from dtwin.model.registry import N_EXCITATION_HARMONICS
from dtwin.simulation.simulate import SolverOptions, settling_sequence, simulate
from dtwin.spec import Spec
from dtwin.spec.build import build_twin

from .calibration_settings import CalibrationSettings, window_terms_for
from .gap import THRESHOLD_DB
from .lines import Kinematics
from .stopping import StallStopping

__all__ = ["mesh_harmonics"]

_DB = 20.0 / math.log(10.0)
#: Unit (m) of the transmission-error coordinates in θ.
_TE_UNIT = 1e-8
#: Unit of the load-share coordinates in θ (1 % of planet 0's share).
_SHARE_UNIT = 0.01
#: The contact rows' scale: a mesh's least deflection falling below zero by this fraction of
#: the mean deflection costs as much as one prior standard deviation (module docstring,
#: "Contact").
CONTACT_TOL = 0.02
#: Samples of the least deflection (per mesh) the contact rows hold, over one carrier period.
CONTACT_SAMPLES = 1024


def zeta_step(relinearize_db: float) -> float:
    """The largest change of ``log zeta_mesh`` one linearisation is trusted with (module
    docstring, "Damping"): the step ``Δ`` at which a resonant line, ``Z ∝ 1/ζ``, predicted to
    first order as ``Z_0 (1 − Δ)`` instead of ``Z_0 e^{−Δ}``, is `relinearize_db` (dB) low —
    the departure at which a calibration reports its twin as departing. 0.41 at 1 dB."""
    from scipy.optimize import brentq

    target = 10.0 ** (-relinearize_db / 20.0)
    # (1 − Δ) e^Δ falls from 1 to 0 on [0, 1]
    return float(brentq(lambda d: (1.0 - d) * math.exp(d) - target, 0.0, 1.0, xtol=1e-14))
#: Memory (bytes) the response's tangents may take at once, and what one tangent takes per
#: sample of the DAQ's oversampled grid (measured: 1.0–1.4 kB on the paper's gearbox, the
#: torsional twin): the Jacobian is formed in batches of tangents within this budget.
_TANGENT_BUDGET, _TANGENT_BYTES_PER_SAMPLE = 2**30, 1500


# ------------------------------------------------------------------------------------ the model
@dataclasses.dataclass(frozen=True)
class _Layout:
    """Positions of the parameter groups in θ and their scales (θ is nondimensional)."""

    n_window: int  # free window coefficients c_1 … c_{K-1}
    n_harm: int  # mesh harmonics of the excitation
    c_init: tuple[float, ...]
    window_scale: float
    te_scale: float
    n_share: int = 0  # free load shares of planets 1 … N-1 (0: not fitted)
    share_init: tuple[float, ...] = ()
    f_sun: float = 0.0  # Hz, the speed at which the shares hold
    i_share_part: int = -1  # the MeshOffsets part that carries them

    @property
    def size(self) -> int:
        return self.n_window + 2 * self.n_harm + self.n_share + 1

    @property
    def i_share(self) -> int:
        return self.n_window + 2 * self.n_harm

    @property
    def i_zeta(self) -> int:
        return self.size - 1


def mesh_harmonics(settings: CalibrationSettings, fs: float, f_mesh: float) -> int:
    """Mesh harmonics whose transmission error calibration fits: `settings.mesh_harmonics`, or
    every one below 0.45 × the rate `fs` (Hz), at most
    :data:`dtwin.model.registry.N_EXCITATION_HARMONICS` (those with a registry name); `f_mesh` (Hz)."""
    return settings.mesh_harmonics or max(1, min(int(0.45 * fs / f_mesh),
                                                 N_EXCITATION_HARMONICS))


def _prepare_twin(spec: Spec, f_sun: float, kind: str | None, settings: CalibrationSettings,
                  n_harm: int, fit_shares: bool = False):
    twin = build_twin(spec, kind=kind, f_sun=f_sun)
    i_path = next((i for i, p in enumerate(twin.parts) if isinstance(p, PlanetPassTransferPath)),
                  None)
    if i_path is None:
        raise SpecError([("sensor", "the twin has no planet-pass transfer path to calibrate")])
    path = twin.parts[i_path]
    K = settings.window_terms or window_terms_for(twin.n_planets)
    if path.window_harmonics is not None:
        c = np.zeros(K)
        w = np.asarray(path.window_harmonics)[:K]
        c[: w.size] = w
    else:
        c = window_cosine_coefficients(float(path.window_exponent), K)
    twin = eqx.tree_at(lambda t: t.parts[i_path].window_harmonics, twin,
                       jnp.asarray(c, dtype=jnp.float64), is_leaf=lambda x: x is None)
    i_exc = next((i for i, p in enumerate(twin.parts) if isinstance(p, MeshExcitation)), None)
    if i_exc is None:
        twin = twin.with_parts(MeshExcitation.zeros(n_harm))
        i_exc = len(twin.parts) - 1
    else:
        old = twin.parts[i_exc]
        pad = max(0, n_harm - old.n_harmonics)

        def grow(a):
            return jnp.concatenate([a, jnp.zeros(pad)])[:n_harm]

        twin = eqx.tree_at(lambda t: t.parts[i_exc], twin,
                           MeshExcitation(grow(old.sun_cos), grow(old.sun_sin),
                                          grow(old.ring_cos), grow(old.ring_sin)))
    # θ of the excitation in units of _TE_UNIT (of the order of the parametric excitation's
    # effect at the mesh harmonics), so every θ column has a similar scale for the LM steps
    layout = _Layout(K - 1, n_harm, tuple(float(v) for v in c), max(abs(c[0]), 1e-12),
                     _TE_UNIT)
    if fit_shares:
        n = twin.n_planets
        old_shares = spec["imperfections"]["load_sharing"]
        s0 = np.ones(n) if old_shares is None else np.asarray(old_shares, float)
        i_ls = next((i for i, p in enumerate(twin.parts) if isinstance(p, MeshOffsets)), None)
        if i_ls is None:
            twin = twin.with_parts(MeshOffsets(jnp.zeros(n), jnp.zeros(n)))
            i_ls = len(twin.parts) - 1
        layout = dataclasses.replace(layout, n_share=n - 1,
                                     share_init=tuple(float(v) for v in s0 / s0[0]),
                                     f_sun=float(f_sun), i_share_part=i_ls)
    return twin, i_path, i_exc, layout


def _shares(theta, layout: _Layout):
    """The planets' relative load shares (planet 0 = 1) at θ."""
    s0 = jnp.asarray(layout.share_init, dtype=jnp.float64)
    return s0.at[1:].add(_SHARE_UNIT * theta[layout.i_share: layout.i_share + layout.n_share])


def _carrier_order_lines(kin: Kinematics, freqs, A, F) -> int:
    """How many orders ``k f_c`` below the first mesh band, k not a multiple of N, stand above
    the line threshold in the mean spectrum of the records (A, F: (rec, half, bins))."""
    a, f = A.mean(axis=(0, 1)), F.mean(axis=(0, 1))
    df = freqs[1] - freqs[0]
    count = 0
    for k in range(1, int((kin.f_mesh - 2 * kin.n_planets * kin.f_carrier) / kin.f_carrier)):
        if k % kin.n_planets == 0:
            continue
        b = int(round(k * kin.f_carrier / df))
        if b + 1 < a.size and np.max(a[b - 1: b + 2] / f[b - 1: b + 2]) > 10 ** (THRESHOLD_DB / 20):
            count += 1
    return count


def _apply(twin, theta, layout: _Layout, i_path: int, i_exc: int):
    """`twin` with the calibration vector θ written in (differentiable)."""
    c0 = jnp.asarray(layout.c_init, dtype=jnp.float64)
    c = c0.at[1:].add(layout.window_scale * theta[: layout.n_window])
    twin = eqx.tree_at(lambda t: t.parts[i_path].window_harmonics, twin, c)
    h = layout.n_harm
    te = theta[layout.n_window: layout.n_window + 2 * h] * layout.te_scale
    exc = twin.parts[i_exc]
    twin = eqx.tree_at(lambda t: (t.parts[i_exc].ring_cos, t.parts[i_exc].ring_sin), twin,
                       (exc.ring_cos + te[:h], exc.ring_sin + te[h:]))
    if layout.n_share:
        # clearances from the static balance of the twin before θ's damping (which they do not
        # depend on): linear in the shares, so forward-mode tangents stay exact
        e = load_share_offsets(twin, _shares(theta, layout), layout.f_sun)
        twin = eqx.tree_at(lambda t: t.parts[layout.i_share_part], twin, MeshOffsets(e, e))
    s = jnp.exp(theta[layout.i_zeta])
    lp = twin.lp
    lp = replace_lumped(lp, zeta_sun_planet=lp.zeta_sun_planet * s,
                        zeta_ring_planet=lp.zeta_ring_planet * s)
    return eqx.tree_at(lambda t: t.lp, twin, lp)


class _Contact(NamedTuple):
    """The meshes' least deflection over the planets, first order in θ, at the samples
    `_response` was given (module docstring, "Contact"): ``d0 + J (θ − θ_lin)`` (m), both
    meshes' samples in a row, and the smaller of the two meshes' mean deflections (m, over the
    record and the planets: the static deflection under the load)."""

    d0: np.ndarray  # (M,)
    J: np.ndarray  # (M, P)
    mean: float


def _response(twin, layout, i_path, i_exc, daq, n, f_sun, settings, theta_lin,
              contact_idx=None):
    """The signal at `theta_lin`, its Jacobian (n, P) by forward mode through the solve, and
    the sun and ring meshes' least deflection over the planets at the samples `contact_idx`
    with its Jacobian (a :class:`_Contact`; None without `contact_idx` or where the meshes
    carry no load)."""
    fs = float(daq.sample_rate)
    solver = settings.solver or SolverOptions(periodic="auto")
    idx = jnp.asarray(np.arange(0) if contact_idx is None else contact_idx, dtype=jnp.int32)

    def linearise(solver):
        def sig(theta):
            tw = _apply(twin, theta, layout, i_path, i_exc)
            res = simulate(tw, duration=n / fs, f_sun=f_sun, daq=daq, discard=settings.discard,
                           solver=solver, check=False)
            o = res.outputs
            least = jnp.concatenate([o["least_deflection_sun_planet"][idx],
                                     o["least_deflection_ring_planet"][idx]])
            mean = jnp.minimum(jnp.mean(o["deflection_sun_planet"]),
                               jnp.mean(o["deflection_ring_planet"]))
            return res.signal[:n], res.periodic_defect, least, mean

        # evaluated eagerly, not as one compiled program: compiled, it rounds differently, and
        # the calibration's weakly determined directions then lead its fit to another optimum
        return jax.linearize(sig, jnp.asarray(theta_lin, dtype=jnp.float64))

    # one period of the gear set tiled is the response only where the start-up transient has
    # died out within the settling time (as `simulate` checks with concrete values): otherwise the
    # tiles' joins put a broadband hump under the twin's lightly damped modes. Settle longer,
    # then integrate the whole record.
    for option in settling_sequence(solver):
        (y0, defect, least0, mean), jvp_fn = linearise(option)
        if defect is None or float(defect) <= solver.periodic_tolerance:
            break
    # the tangents in batches: all at once, they held ~170 MB each for a 3 s record at 10 kHz
    # (5.9 GB in all for 25 of them); each batch runs the solve again
    eye = jnp.eye(layout.size)
    batch = _tangent_batch(n * daq.oversample)

    def tangents(v):
        out = jvp_fn(v)
        return out[0], out[2]

    parts = [jax.vmap(tangents, in_axes=1, out_axes=1)(eye[:, i: i + batch])
             for i in range(0, layout.size, batch)]
    J = np.concatenate([np.asarray(p[0]) for p in parts], axis=1)
    y0 = np.asarray(y0)
    if not (np.all(np.isfinite(y0)) and np.all(np.isfinite(J))):
        raise FitError("the twin's simulation failed at the "
                       + ("spec's values" if not np.any(np.asarray(theta_lin)) else
                          "calibration's values") + " (non-finite signal); check the spec with "
                       "`dtwin spec check`")
    contact = None
    if contact_idx is not None and float(mean) > 0:
        Jd = np.concatenate([np.asarray(p[1]) for p in parts], axis=1)
        if np.all(np.isfinite(Jd)):
            contact = _Contact(np.asarray(least0), Jd, float(mean))
    return y0, J, contact


def _tangent_batch(n_samples: int) -> int:
    """How many tangents of a response over `n_samples` samples of the oversampled grid are
    formed at once (at least one): `_TANGENT_BUDGET` over `_TANGENT_BYTES_PER_SAMPLE` each."""
    return max(1, _TANGENT_BUDGET // (_TANGENT_BYTES_PER_SAMPLE * n_samples))


def _family_bins(kin: Kinematics, freqs: np.ndarray) -> np.ndarray:
    """Bins (±1) of the healthy line families: k f_c below the first mesh band and
    m f_m + n f_c, |n| ≤ 10, below Nyquist."""
    df = freqs[1] - freqs[0]
    f_top = freqs[-1]
    fr = [k * kin.f_carrier for k in range(1, int((kin.f_mesh - 10 * kin.f_carrier)
                                                  / kin.f_carrier) + 1)]
    m = 1
    while m * kin.f_mesh - 10 * kin.f_carrier < f_top:
        fr += [m * kin.f_mesh + n * kin.f_carrier for n in range(-10, 11)]
        m += 1
    k = np.rint(np.asarray(fr) / df).astype(int)
    k = np.concatenate([k - 1, k, k + 1])
    mask = np.zeros(len(freqs), bool)
    mask[k[(k > 0) & (k < len(freqs))]] = True
    return mask


class _Data(eqx.Module):
    """Arrays of one fit: rows are (record, half) pairs."""

    Z0: jax.Array  # (rows, bins) complex: the model's spectra at the linearisation point
    JZ: jax.Array  # (rows, bins, P) complex
    theta_lin: jax.Array  # (P,): the linearisation point
    A: jax.Array  # measured amplitudes (rows, bins)
    F: jax.Array  # measured floors (rows, bins)
    S: jax.Array  # fit-bin weights (rows, bins)
    W: jax.Array  # response-solve weights (rows, bins): measured lines
    B: jax.Array  # knot basis (bins, knots)
    prior_sd: jax.Array  # (P,)
    smooth: float = eqx.field(static=True)
    frf_prior: float = eqx.field(static=True)
    # the teeth stay in contact (module docstring, "Contact"): the meshes' least deflection,
    # first order in θ, kept above zero; None: no constraint
    contact_d0: jax.Array | None = None  # (M,) m, at theta_lin
    contact_J: jax.Array | None = None  # (M, P) m per unit of θ
    contact_scale: float = 1.0  # m: CONTACT_TOL × the mean deflection
    # the change of log ζ (θ's last entry) the linearisation is trusted with (module docstring,
    # "Damping"); inf: no bound
    zeta_step: float = eqx.field(static=True, default=math.inf)


def _frf_solve(absZ, data: _Data):
    """Closed-form knot gains (dB) for the model amplitudes |Z| (variable projection)."""
    D = data.A  # measured
    lvl = _DB * (jnp.log(D + 1e-300) - jnp.log(absZ + 1e-300))
    lvl = jnp.clip(lvl, -200.0, 200.0)
    # only lines the model also has inform the response (a line the twin cannot make, e.g. an
    # alias or an unrelated tone, would otherwise drag it): weight by the model line's height
    # within 60 dB of the model's strongest line, at the linearisation point — at θ, a fit
    # could cancel a measured line in the twin (a first-order combination of the excitation)
    # to drop it from the response's solve and let the smoothness prior set the knot it held
    Z0 = jnp.abs(data.Z0)
    rel = _DB * (jnp.log(Z0 + 1e-300) - jnp.log(jnp.max(Z0, axis=-1, keepdims=True)))
    W = data.W * jax.nn.sigmoid((rel + 60.0) / 3.0)
    B = data.B
    k = B.shape[1]
    BtWB = jnp.einsum("rb,bi,bj->ij", W, B, B)
    BtWy = jnp.einsum("rb,bi,rb->i", W, B, lvl)
    wsum = jnp.maximum(jnp.sum(W), 1.0)
    mean = jnp.sum(W * lvl) / wsum
    P = jnp.eye(k) / data.frf_prior**2
    if k >= 3:
        L = jnp.asarray(np.diff(np.eye(k), n=2, axis=0))
        P = P + L.T @ L / data.smooth**2
    return jnp.linalg.solve(BtWB + P, BtWy + (jnp.eye(k) / data.frf_prior**2) @ (mean *
                                                                               jnp.ones(k)))


@eqx.filter_jit
def _model_amp(theta, data: _Data):
    d = (theta - data.theta_lin).astype(data.JZ.dtype)
    Z = data.Z0 + jnp.einsum("rbp,p->rb", data.JZ, d)
    absZ = jnp.abs(Z)
    G = _frf_solve(absZ, data)
    g = 10.0 ** ((data.B @ G) / 20.0)
    return g[None, :] * absZ, G


def _residuals(theta, data: _Data):
    A_mod, _ = _model_amp(theta, data)
    F = data.F
    l_meas = jnp.log(data.A + F)
    l_mod = jnp.log(jnp.sqrt(A_mod**2 + F**2) + F)
    r = _DB * (l_meas - l_mod) * data.S
    return jnp.concatenate([r.ravel(), _contact_rows(theta, data), _zeta_rows(theta, data),
                            theta / data.prior_sd])


def _zeta_rows(theta, data: _Data):
    """The row that keeps log ζ within `zeta_step` of the linearisation point (module
    docstring, "Damping"): ``max(|Δ| − step, 0) / (CONTACT_TOL step)``, zero and without
    gradient inside the bound; none without one."""
    if not math.isfinite(data.zeta_step):
        return jnp.zeros(0)
    d = jnp.abs(theta[-1:] - data.theta_lin[-1:])
    return jnp.maximum(d - data.zeta_step, 0.0) / (CONTACT_TOL * data.zeta_step)


def _contact_rows(theta, data: _Data):
    """Rows that keep the teeth in contact (module docstring, "Contact"): ``max(−d, 0) /
    (CONTACT_TOL d̄)`` at each sample of the meshes' least deflection ``d`` (first order in θ,
    d̄ its mean); zero, with no gradient, while every mesh stays in contact; none without a
    loaded mesh."""
    if data.contact_d0 is None:
        return jnp.zeros(0)
    d = data.contact_d0 + data.contact_J @ (theta - data.theta_lin)
    return jnp.maximum(-d, 0.0) / data.contact_scale


@eqx.filter_jit
def _residuals_and_jacobian(theta, data: _Data):
    """The residuals at `theta` and their Jacobian (forward mode), as one compiled program."""
    return _residuals(theta, data), jax.jacfwd(_residuals)(theta, data)


def _column_scales(r, Jr, n_prior: int) -> tuple[float, jax.Array]:
    """½‖r‖² and 1 / (norm of each data column of the residual Jacobian `Jr`), from the
    residuals and Jacobian at a point (the last `n_prior` rows are the prior's): the LM iterates
    on ``u = θ / scale``, in which every column has unit norm (the window's c_3 moves the
    planet-pass line ~10⁴ times more per unit than an excitation coefficient moves a mesh
    line)."""
    norms = jnp.sqrt(jnp.sum(Jr[:-n_prior] ** 2, axis=0))
    return float(0.5 * jnp.sum(r**2)), 1.0 / jnp.maximum(norms, 1e-9 * jnp.max(norms))


def _scaled_residuals(u, args):
    data, scale = args
    return _residuals(u * scale, data)


def _fit(data: _Data, theta0, max_steps: int, loss_rtol: float, run_steps: int,
         restart_rtol: float):
    """θ at the fit's end, its Levenberg–Marquardt steps (all runs), whether it stopped
    before `max_steps` with its loss settled, and its loss there (½‖r‖², prior rows included).

    A Levenberg–Marquardt run from θ0 can settle on a shallow slope, its trust region small
    and its column scales those of θ0, and crawl (the loss falling by ~1e-4 of itself per step
    for hundreds of steps) well above the minimum. The fit is therefore a sequence of runs of
    at most `run_steps` steps, each from where the last one ended with column scales taken
    there and a fresh trust region, until a run lowers the loss by no more than
    `restart_rtol` of itself (converged) or the runs' steps reach `max_steps` (not).
    """
    solver = StallStopping(rtol=1e-8, atol=1e-10, loss_rtol=loss_rtol)
    P = theta0.shape[0]
    theta = jnp.asarray(theta0)
    # one residual-and-Jacobian evaluation per run gives the loss where the last run ended and
    # the column scales of the next
    loss, scale = _column_scales(*_residuals_and_jacobian(theta, data), P)
    steps = 0
    while steps < max_steps:
        # a module-level function with the scales among the arguments: fits of equal shapes
        # (the two halves, every run) share one compilation
        sol = optx.least_squares(_scaled_residuals, solver, theta / scale, args=(data, scale),
                                 max_steps=min(run_steps, max_steps - steps), throw=False)
        steps += int(sol.stats["num_steps"])
        new = sol.value * scale
        new_loss, new_scale = _column_scales(*_residuals_and_jacobian(new, data), P)
        if not new_loss < loss:  # LM accepts only steps that lower the loss: nothing moved
            return np.asarray(theta), steps, True, float(loss)
        theta, drop, loss, scale = new, loss - new_loss, new_loss, new_scale
        if drop <= restart_rtol * (loss + drop):
            return np.asarray(theta), steps, True, float(loss)
    return np.asarray(theta), steps, False, float(loss)
