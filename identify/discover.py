"""Discrepancy discovery: where the twin and the measurement disagree, which effect explains it,
add it, refit, and show the held-out gap shrink (issue 8; docs/discovery.md).

**Loop** (:func:`discover`): speed from the data (:func:`dtwin.identify.lines.estimate_speed`); the
base twin simulated over the record; then per step

1. residual lines over 0 … Nyquist (:func:`dtwin.identify.lines.residual_lines`), each with its
   kinematic description;
2. candidates ranked by *coverage*: the share of the residual line power (measured over model)
   lying on their signature (:func:`coverage`); the best `max_refit` are refit;
3. each is refit about the current model (below) and scored on held-out data: statistic ``T``,
   bootstrap p-value, held-out gap (:mod:`dtwin.identify.gap`) and parameter intervals;
4. kept: among candidates with ``p <= alpha / K`` (Bonferroni over the K refit; family-wise level
   `alpha` = 1 % per step) whose main parameter's interval excludes zero, the one with the
   smallest held-out gap. Members of its look-alike group that fit as well (within `tie_db`) or
   were not refit make the step name the *group*; otherwise the member is named;
5. the full (nonlinear) twin is simulated with the fitted effect (confirmation) and becomes the
   current model. Stop when nothing is significant and identified, or at `max_steps`.

Lines still missing at the end are reported as unexplained, with their kinematic description
(or "no kinematic match"), never assigned to an effect that failed the test.

**Model.** The current model's complex Hann spectrum ``Z0`` per record segment (fold) and the
first-order response ``J`` of that spectrum to the candidate's parameters (``jax.jvp`` through
the diffrax solve, exact in parameters that enter the parts linearly) give::

    A_model(theta, g) = g |Z0 + J theta|

The fit compares levels ``L = 20 log10(A + F)`` (``F`` the measured noise floor, added before
the log as in :mod:`dtwin.identify.gap`) with ``optimistix.least_squares`` (Levenberg–Marquardt,
``jac="fwd"``) with a free gain per fold, over the *fit bins*: the candidate's signature bins plus the bins where the
current model has a line. Non-negative parameters are fitted as ``exp(u)``. Starts: the
dominant eigenvector of the signature-weighted response ``sum_k w_k Re(J_k^H J_k)`` scaled to
the excess power, its negative and a third of it (one batched ``vmap``).

The model level includes the expected noise, ``A -> sqrt(A^2 + F^2 / ln 2)``.

**Held-out statistic.** With the parameters fitted on segment A, on segment B the reduction
of the squared level error over the signature bins (levels with the expected noise)::

    T = sum_{k in signature bins of B} [ (L_meas − L_before)^2 − (L_meas − L_after)^2 ]

pooled over both directions (A→B, B→A). (A likelihood ratio of the amplitudes would be more
powerful on a perfect model but punishes every small misfit of a line 40 dB over the floor;
the level error is bounded and robust to the base model's own imperfections.) When the fit
stays at "no effect" T is exactly 0; such ties get a randomised p-value
(:func:`p_value`), so the test is exactly calibrated at every level. Under the null (no effect) the signature bins of the
measurement hold only noise; its distribution is drawn by a parametric bootstrap that repeats
the whole fit on noise spectra with the measured floor's level and the Hann window's bin
correlation, the floor re-estimated in every draw (:func:`null_statistics`), so the p-value is calibrated without asymptotics.

Arrays are padded to fixed sizes (``P_MAX`` parameters, bins to a multiple of ``BIN_BLOCK``) so
that one compilation serves every candidate.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from dtwin.spectrum import amplitude_spectrum, noise_floor

from .gap import FLOOR_BINS, GapResult, gap, named_bands, segment_spectra
from .lines import (
    Kinematics,
    ResidualLine,
    chance_match_probability,
    estimate_speed,
    residual_lines,
)

__all__ = ["CandidateResult", "DiscoveryResult", "DiscoverySettings", "ExtendedModel", "Step",
           "candidate_inputs", "coverage", "discover", "signature_labels", "extended_model", "p_value", "heldout_statistic", "null_statistics", "white_noise_spectra"]

#: Largest number of parameters of one effect (padded with inert parameters).
P_MAX = 4
#: Bins are padded to a multiple of this.
BIN_BLOCK = 128
_LN10_20 = 20.0 / np.log(10.0)
#: Levenberg–Marquardt iterations per fit (the same in the data fit and every bootstrap draw).
MAX_LM_STEPS = 60


class FitInputs(eqx.Module):
    """Per-fold arrays on the selected bins (fold axis first, padded).

    `Z0` (F, K) complex current model (unit gain); `J` (F, K, P) complex response to one unit
    of each parameter; `Y` (F, K) measured amplitude; `floor` (F, K); `fit` and `sig` (F, K)
    masks (1.0/0.0); `nonneg` (P,) mask; `active` (P,) mask of real (unpadded) parameters;
    `log_g0` (F,) base log gains fitted on each fold.
    """

    Z0: jax.Array
    J: jax.Array
    Y: jax.Array
    floor: jax.Array
    fit: jax.Array
    sig: jax.Array
    nonneg: jax.Array
    active: jax.Array
    log_g0: jax.Array


def _theta(u, nonneg, active):
    return jnp.where(active > 0, jnp.where(nonneg > 0, jnp.exp(u), u), 0.0)


def _levels(a, floor):
    return _LN10_20 * jnp.log(a + floor)


def _model_amp(Z0, J, theta, log_g):
    return jnp.exp(log_g) * jnp.abs(Z0 + J @ theta.astype(J.dtype))


def _with_noise(a, floor):
    """Expected RMS amplitude of a line `a` plus noise of median amplitude `floor`:
    ``sqrt(a^2 + F^2 / ln 2)`` (the per-fold fits and the held-out statistic compare levels
    *with* the noise, so noise-only bins do not pull a fitted effect up; the joint fit that
    gives the reported values uses :func:`expected_level`)."""
    return jnp.sqrt(a**2 + floor**2 / np.log(2.0))


def _expected_level_table(n_rho: int = 600, n_phi: int = 256):
    """``h(r) = E[20 log10(|r + n| + 1)]``, n complex Gaussian of median modulus 1 (variance
    ``1 / ln 2``), on a grid uniform in ``asinh(r)`` up to r = 1e3 (polar quadrature; accurate
    to ~1e-4 dB)."""
    sig = np.sqrt(1.0 / (2.0 * np.log(2.0)))
    s_grid = np.linspace(0.0, np.arcsinh(1e3), 1200)
    r = np.sinh(s_grid)
    rho = (np.arange(n_rho) + 0.5) * (9.0 * sig / n_rho)
    w_rho = rho / sig**2 * np.exp(-(rho**2) / (2 * sig**2)) * (9.0 * sig / n_rho)
    w_rho = w_rho / w_rho.sum()
    phi = (np.arange(n_phi) + 0.5) * (2 * np.pi / n_phi)
    n = rho[:, None] * np.exp(1j * phi)[None, :]
    h = np.array([np.sum(w_rho[:, None] * 20 * np.log10(np.abs(ri + n) + 1.0)) / n_phi
                  for ri in r])
    return s_grid, h


_EL_S, _EL_H = _expected_level_table()


def expected_level(a, floor):
    """Expected measured level ``E[20 log10(|a + n| + F)]`` (dB) of a line of amplitude `a`
    in noise of median amplitude `floor` (Rician; :func:`_expected_level_table`). The fit and
    the statistic compare the measured level ``20 log10(Y + F)`` with it: a line near the floor
    reads lower in the log than its RMS amplitude (by ~0.9 dB at the floor, 0.4 dB at 3 F),
    which would otherwise bias every fitted amplitude low. Used by the joint fit (reported
    parameters, their intervals and the profile); the held-out statistic keeps the RMS level
    of :func:`_with_noise`, whose bootstrap calibration the tests check."""
    r = a / floor
    s = jnp.arcsinh(r)
    h_tab = jnp.interp(s, jnp.asarray(_EL_S), jnp.asarray(_EL_H))
    h = jnp.where(r < 1e3, h_tab, _LN10_20 * jnp.log1p(jnp.minimum(r, 1e300)))
    return _LN10_20 * jnp.log(floor) + h


def _residual_fold(params, args):
    Z0, J, Y, floor, fit, nonneg, active, log_g0 = args
    del log_g0
    u, log_g = params[:-1], params[-1]
    th = _theta(u, nonneg, active)
    a = _with_noise(_model_amp(Z0, J, th, log_g), floor)
    return (_levels(a, floor) - _levels(Y, floor)) * fit


def _starts(Z0, J, Y, floor, sig, nonneg, active, log_g0):
    g = jnp.exp(log_g0)
    w = jnp.maximum(Y**2 - (2.0 * floor) ** 2, 0.0) * sig
    Jr = jnp.concatenate([J.real, J.imag], axis=0) * g  # (2K, P)
    ww = jnp.concatenate([w, w])
    M = (Jr * ww[:, None]).T @ Jr + 1e-12 * jnp.eye(J.shape[-1])
    _, vecs = jnp.linalg.eigh(M)
    v = vecs[:, -1] * active
    resp = jnp.sum(sig * jnp.abs(J @ v.astype(J.dtype)) ** 2) * g**2
    s = jnp.sqrt(jnp.sum(w) / jnp.maximum(resp, 1e-300))
    s = jnp.clip(s, 1e-6, 1e6)
    thetas = jnp.stack([s * v, -s * v, s * v / 3.0])

    def to_u(th):
        return jnp.where(nonneg > 0, jnp.log(jnp.maximum(jnp.abs(th), 1e-3)), th)

    us = jax.vmap(to_u)(thetas)
    return jnp.concatenate([us, jnp.full((3, 1), log_g0)], axis=1)


_SOLVER = optx.LevenbergMarquardt(rtol=1e-6, atol=1e-8)


def _solve(fn, y0, args):
    sol = optx.least_squares(fn, _SOLVER, y0, args=args, options=dict(jac="fwd"),
                             max_steps=MAX_LM_STEPS, throw=False)
    r = fn(sol.value, args)
    return sol.value, jnp.sum(r**2)


def fit_fold(Z0, J, Y, floor, fit, sig, nonneg, active, log_g0):
    """Fit one fold: returns ``(params, loss)`` with params = (u (P), log g)."""
    y0s = _starts(Z0, J, Y, floor, sig, nonneg, active, log_g0)
    args = (Z0, J, Y, floor, fit, nonneg, active, log_g0)
    vals, losses = jax.vmap(lambda y0: _solve(_residual_fold, y0, args))(y0s)
    losses = jnp.where(jnp.isfinite(losses), losses, jnp.inf)
    i = jnp.argmin(losses)
    return vals[i], losses[i]


def _stat_fold(params, Z0, J, Y, floor, sig, nonneg, active, log_g0):
    """Held-out contribution of one fold with params fitted on the other: the reduction of the
    squared level error (dB², levels with the expected noise) over the signature bins."""
    u, log_g = params[:-1], params[-1]
    th = _theta(u, nonneg, active)
    lm = _levels(Y, floor)
    l0 = _levels(_with_noise(jnp.exp(log_g0) * jnp.abs(Z0), floor), floor)
    l1 = _levels(_with_noise(_model_amp(Z0, J, th, log_g), floor), floor)
    return jnp.sum(sig * ((lm - l0) ** 2 - (lm - l1) ** 2))


def _heldout(inp: FitInputs, Y):
    """(T, params per fold) for measured amplitudes `Y` (F, K); two folds."""
    p0, _ = fit_fold(inp.Z0[0], inp.J[0], Y[0], inp.floor[0], inp.fit[0], inp.sig[0], inp.nonneg,
                     inp.active, inp.log_g0[0])
    p1, _ = fit_fold(inp.Z0[1], inp.J[1], Y[1], inp.floor[1], inp.fit[1], inp.sig[1], inp.nonneg,
                     inp.active, inp.log_g0[1])
    # gains: the base gain of the scored fold is the one fitted on the training fold
    t01 = _stat_fold(p0, inp.Z0[1], inp.J[1], Y[1], inp.floor[1], inp.sig[1], inp.nonneg,
                     inp.active, inp.log_g0[0])
    t10 = _stat_fold(p1, inp.Z0[0], inp.J[0], Y[0], inp.floor[0], inp.sig[0], inp.nonneg,
                     inp.active, inp.log_g0[1])
    return t01 + t10, jnp.stack([p0, p1])


heldout_statistic = eqx.filter_jit(lambda inp: _heldout(inp, inp.Y))


@eqx.filter_jit
def _null_batch(inp: FitInputs, Ystar, floor_star):
    """Statistics for bootstrap amplitudes `Ystar` and their re-estimated floors (B, F, K)."""

    def one(y, fl):
        return _heldout(eqx.tree_at(lambda i: i.floor, inp, fl), y)[0]

    return jax.vmap(one)(Ystar, floor_star)


def white_noise_spectra(rng: np.random.Generator, n_draws: int, seg_len: int, n_folds: int,
                        bins: np.ndarray | None = None) -> np.ndarray:
    """Hann spectra (amplitude-scaled as :func:`dtwin.identify.gap.segment_spectra`) of unit white
    noise divided by their median amplitude ``2 sqrt(ln 2 sum w^2) / sum w``: shape
    (n_draws, n_folds, bins); multiply by a floor to get noise of that floor."""
    w = np.hanning(seg_len + 1)[:-1]
    med = 2.0 * np.sqrt(np.log(2.0) * np.sum(w**2)) / w.sum()
    x = rng.standard_normal((n_draws, n_folds, seg_len))
    X = np.fft.rfft(x * w, axis=-1) * (2.0 / w.sum())
    if bins is not None:
        X = X[..., bins]
    return X / med


def null_statistics(inp: FitInputs, rng: np.random.Generator, n_draws: int, Z0_full,
                    floor_full, sel: np.ndarray, seg_len: int, chunk: int = 100) -> np.ndarray:
    """Bootstrap draws of the held-out statistic under the null (module docstring).

    Each draw: the current model (gain of its fold) plus complex noise with the measured floor's
    level and the window's bin correlation over the whole spectrum; its floor is re-estimated
    (running median, as for the measurement); then the same fit-and-score on the bins `sel`.
    `Z0_full`, `floor_full`: (F, n_bins)."""
    K = inp.Y.shape[-1]
    F = Z0_full.shape[0]
    g0 = np.exp(np.asarray(inp.log_g0))[:, None]
    out = []
    for i in range(0, n_draws, chunk):
        b = min(chunk, n_draws - i)
        nz = white_noise_spectra(rng, chunk, seg_len, F) * floor_full[None]
        Ys = np.abs(g0 * Z0_full[None] + nz)
        fs = noise_floor(Ys, FLOOR_BINS)
        Yk = _pad_last(Ys[..., sel], K, 1.0)
        Fk = _pad_last(fs[..., sel], K, 1.0)
        t = _null_batch(inp, jnp.asarray(Yk), jnp.asarray(Fk))
        out.append(np.asarray(t)[:b])
    return np.concatenate(out)


def _residual_joint(params, args):
    Z0, J, Y, floor, fit, nonneg, active, log_g0 = args
    P = J.shape[-1]
    del log_g0
    u, log_g = params[:P], params[P:]
    th = _theta(u, nonneg, active)
    a = jnp.exp(log_g)[:, None] * jnp.abs(Z0 + jnp.einsum("fkp,p->fk", J, th.astype(J.dtype)))
    return ((expected_level(a, floor) - _levels(Y, floor)) * fit).reshape(-1)


@eqx.filter_jit
def _fit_joint(inp: FitInputs, start):
    args = (inp.Z0, inp.J, inp.Y, inp.floor, inp.fit, inp.nonneg, inp.active, inp.log_g0)
    val, loss = _solve(_residual_joint, start, args)
    jac = jax.jacfwd(_residual_joint)(val, args)
    r = _residual_joint(val, args)
    return val, loss, jac, r


def fit_joint(inp: FitInputs, fold_params: np.ndarray):
    """Fit shared parameters on both folds (one gain per fold), starting from the better of
    the per-fold fits. **Returns:** ``(params, loss, jacobian, residuals)`` (numpy)."""
    P = inp.J.shape[-1]
    best = None
    for fp in fold_params:
        start = jnp.concatenate([jnp.asarray(fp[:P]), jnp.asarray(fp[P:]).repeat(2)])
        val, loss, jac, r = _fit_joint(inp, start)
        if best is None or float(loss) < best[1]:
            best = (np.asarray(val), float(loss), np.asarray(jac), np.asarray(r))
    return best


@eqx.filter_jit
def _profile_losses(inp: FitInputs, val, scales):
    """Loss of the joint fit with the effect scaled by each of `scales` (gains kept)."""
    args = (inp.Z0, inp.J, inp.Y, inp.floor, inp.fit, inp.nonneg, inp.active, inp.log_g0)
    P = inp.J.shape[-1]
    th = _theta(val[:P], inp.nonneg, inp.active)

    def loss(c):
        # scaled θ back to u (log for non-negative parameters)
        u = jnp.where(inp.nonneg > 0, jnp.log(jnp.maximum(c * th, 1e-300)), c * th)
        r = _residual_joint(jnp.concatenate([u, val[P:]]), args)
        return jnp.sum(r**2)

    return jax.vmap(loss)(scales)


#: χ² quantile (1 degree of freedom) of the amplitude's profile interval at 99 %.
CHI2_1_99 = 6.634896601021214


def amplitude_profile(inp: FitInputs, val, s2: float, chi2: float = CHI2_1_99):
    """Profile interval of the effect's overall amplitude: the scale factors c with
    ``(loss(c θ̂) − loss(θ̂)) / s² <= chi2`` on a grid 0 … 3, and the evidence
    ``(loss(0) − loss(θ̂)) / s²`` (the interval excludes zero when it exceeds `chi2`).

    **Returns:** ``(c_low, c_high, evidence)``."""
    grid = np.linspace(0.0, 3.0, 301)
    losses = np.asarray(_profile_losses(inp, jnp.asarray(val), jnp.asarray(grid)))
    l1 = float(np.min(losses))
    d = (losses - l1) / max(s2, 1e-300)
    inside = np.flatnonzero(d <= chi2)
    evidence = float((losses[0] - l1) / max(s2, 1e-300))
    return float(grid[inside[0]]), float(grid[inside[-1]]), evidence


def theta_of(params: np.ndarray, nonneg: np.ndarray, active: np.ndarray) -> np.ndarray:
    """Fitting units θ from the fitted vector's u part (numpy)."""
    u = np.asarray(params[: len(nonneg)])
    return np.where(active > 0, np.where(nonneg > 0, np.exp(np.clip(u, -700, 700)), u), 0.0)


def model_amplitudes(Z0, J, theta, log_g) -> np.ndarray:
    """``g |Z0 + J theta|`` per fold (numpy), `log_g` shape (F,)."""
    Z = np.asarray(Z0) + np.einsum("fkp,p->fk", np.asarray(J), np.asarray(theta))
    return np.exp(np.asarray(log_g))[:, None] * np.abs(Z)


# =============================================================================== the search
_Z99 = 2.5758293035489004


@dataclasses.dataclass(frozen=True)
class DiscoverySettings:
    """Settings of :func:`discover` (defaults documented in ``docs/discovery.md``).

    - `alpha`: family-wise level of each step's decision (Bonferroni over the candidates refit
      in the step): a candidate is kept only with p ≤ alpha / (number refit).
    - `n_boot`: bootstrap draws of the null statistic per candidate (raised to K / alpha so that
      the smallest attainable p-value lies below the level).
    - `threshold_db`, `excess_db`, `tolerance_bins`: residual-line detection (dtwin.identify.lines).
    - `max_steps`: budget of effects added; `max_refit`: candidates refit per step (by coverage).
    - `min_coverage`: a candidate must cover this fraction of the residual line power.
    - `tie_db`: members of one look-alike group whose held-out gaps differ by less are not told
      apart (the group is named).
    - `confidence`: level of the parameter intervals (identified: interval excludes zero).
    - `rtol`, `atol`: solver tolerances of the model simulations; `response`: ``"fd"`` or
      ``"jvp"`` (:meth:`ExtendedModel.ensure_responses`).
    """

    n_folds: int = 2
    alpha: float = 0.01
    n_boot: int = 400
    threshold_db: float = 12.0
    excess_db: float = 6.0
    tolerance_bins: float = 0.25
    max_steps: int = 3
    max_refit: int = 4
    min_coverage: float = 0.05
    tie_db: float = 0.2
    confidence: float = 0.99
    seed: int = 0
    rtol: float = 1e-4
    atol: float = 1e-4
    response: str = "fd"

    def solver(self):
        """Solver options of the model simulations (forward-mode responses)."""
        from dtwin.simulate import SolverOptions

        return SolverOptions(rtol=self.rtol, atol=self.atol, adjoint="forward")


class ExtendedModel:
    """The base twin plus every candidate's parts, parametrised by one vector of fitting units
    (θ = 0: the base twin, bit for bit). One compilation serves the base simulation, the
    confirmation simulations and the responses of every candidate (``jax.jvp``)."""

    def __init__(self, base_twin, effects, kin: Kinematics, daq, n_samples: int,
                 f_sun: float, solver=None, response_mode: str = "fd"):
        from dtwin.simulate import SolverOptions

        self.base_twin = base_twin
        self.effects = tuple(effects)
        self.kin = kin
        self.daq = daq
        self.n = int(n_samples)
        self.duration = n_samples / daq.sample_rate
        self.f_sun = float(f_sun)
        self.solver = solver or SolverOptions(adjoint="forward")
        if response_mode not in ("fd", "jvp"):
            raise ValueError(f"response_mode must be 'fd' or 'jvp', got {response_mode!r}")
        self.response_mode = response_mode
        self.parameters = [e.parameters(base_twin) for e in self.effects]
        for ps in self.parameters:
            for p in ps:
                p.register()
        sizes = [len(ps) for ps in self.parameters]
        if max(sizes, default=0) > P_MAX:
            raise ValueError(f"an effect has more than {P_MAX} parameters")
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self.scales = np.concatenate([[p.scale for p in ps] for ps in self.parameters]
                                     or [np.zeros(0)])
        self._columns: dict[int, np.ndarray] = {}
        self._base: np.ndarray | None = None
        self._disk = _disk_path(self)
        if self._disk is not None and self._disk.exists():
            with np.load(self._disk) as z:
                self._base = z["base"] if "base" in z else None
                self._columns = {int(k[4:]): z[k] for k in z.files if k.startswith("col_")}

    def _save(self) -> None:
        if self._disk is None:
            return
        arrays = {f"col_{j}": v for j, v in self._columns.items()}
        if self._base is not None:
            arrays["base"] = self._base
        tmp = self._disk.with_suffix(".tmp.npz")
        np.savez(tmp, **arrays)
        tmp.replace(self._disk)

    @property
    def size(self) -> int:
        return int(self.offsets[-1])

    def slice(self, i: int) -> slice:
        return slice(int(self.offsets[i]), int(self.offsets[i + 1]))

    def twin(self, theta_units):
        """The twin at fitting units `theta_units` (all effects)."""
        theta = jnp.asarray(theta_units) * jnp.asarray(self.scales)
        parts = []
        for i, e in enumerate(self.effects):
            parts += list(e.parts(theta[self.slice(i)], self.base_twin, self.kin))
        return self.base_twin.with_parts(*parts)

    def signal(self, theta_units) -> np.ndarray:
        """Simulated sensor signal (no noise) at `theta_units`."""
        return np.asarray(_ext_signal(self, jnp.asarray(theta_units, dtype=jnp.float64)))

    def base_signal(self) -> np.ndarray:
        if self._base is None:
            self._base = self.signal(np.zeros(self.size))
            self._save()
        return self._base

    def ensure_responses(self, indices: Sequence[int]) -> None:
        """Compute the responses of effects `indices`, one column per parameter.

        ``response="fd"`` (default): forward difference with a step of one fitting unit (the
        effect's typical amplitude scale), ``(s(h e_j) − s(0)) / h`` — one simulation per
        parameter, no extra compilation; exact up to the effect's own nonlinearity, which the
        confirmation simulation checks. ``response="jvp"``: forward-mode ``jax.jvp`` through the
        solve (exact derivative; about two simulations plus a compilation).
        """
        missing = [j for i in indices for j in range(self.slice(i).start, self.slice(i).stop)
                   if j not in self._columns]
        for j in missing:
            tangent = np.zeros(self.size)
            tangent[j] = 1.0
            if self.response_mode == "jvp":
                primal, tang = _ext_jvp(self, jnp.zeros(self.size), jnp.asarray(tangent))
                if self._base is None:
                    self._base = np.asarray(primal)
                self._columns[j] = np.asarray(tang)
            else:
                self._columns[j] = self.signal(tangent) - self.base_signal()
            self._save()

    def response(self, i: int) -> np.ndarray:
        """d signal / d θ (fitting units) of effect `i` at θ = 0: shape (n, p_i)."""
        sl = self.slice(i)
        self.ensure_responses([i])
        return np.stack([self._columns[j] for j in range(sl.start, sl.stop)], axis=1)


def _ext_signal_impl(model: ExtendedModel, theta):
    from dtwin.simulate import simulate

    res = simulate(model.twin(theta), duration=model.duration, f_sun=model.f_sun, daq=model.daq,
                   solver=model.solver, check=False)
    return res.signal


_MODEL_CACHE: dict = {}


def _disk_path(model: ExtendedModel):
    """Where the base signal and responses persist between processes: only when the
    environment variable ``DTWIN_DISCOVER_CACHE`` names a folder (off by default)."""
    import hashlib
    import os
    from pathlib import Path

    root = os.environ.get("DTWIN_DISCOVER_CACHE")
    if not root:
        return None
    key = "|".join([_fingerprint(model.base_twin), repr(model.effects), repr(model.kin),
                    repr(model.daq), str(model.n), repr(model.f_sun), repr(model.solver),
                    repr(model.scales.tolist()), model.response_mode])
    Path(root).mkdir(parents=True, exist_ok=True)
    return Path(root) / (hashlib.sha1(key.encode()).hexdigest() + ".npz")


def _fingerprint(twin) -> str:
    import hashlib

    leaves, treedef = jax.tree_util.tree_flatten(eqx.filter(twin, eqx.is_array))
    h = hashlib.sha1(str(treedef).encode())
    h.update(str(jax.tree_util.tree_structure(twin)).encode())
    for leaf in leaves:
        h.update(np.asarray(leaf).tobytes())
    return h.hexdigest()


def extended_model(base_twin, effects, kin, daq, n_samples, f_sun, solver=None,
                   response_mode: str = "fd") -> ExtendedModel:
    """An :class:`ExtendedModel`, cached by its content (base twin values and structure,
    effects, kinematics, DAQ, length, speed), so repeated searches on records of the same
    machine reuse the base simulation and the responses."""
    key = (_fingerprint(base_twin), tuple(effects), kin, daq, int(n_samples), float(f_sun),
           solver, response_mode)
    if key not in _MODEL_CACHE:
        _MODEL_CACHE[key] = ExtendedModel(base_twin, effects, kin, daq, n_samples, f_sun, solver,
                                          response_mode)
    return _MODEL_CACHE[key]


def _ext_signal(model: ExtendedModel, theta):
    # no outer jit: `simulate` builds its time grid with concrete values; its solve is jitted
    # (and cached by the twin's structure), so repeated calls do not recompile
    return _ext_signal_impl(model, theta)


def _ext_jvp(model: ExtendedModel, theta, tangent):
    return jax.jvp(lambda th: _ext_signal_impl(model, th), (theta,), (tangent,))


# ------------------------------------------------------------------------------ results
@dataclasses.dataclass
class CandidateResult:
    """One candidate refit in a step."""

    name: str
    group: str
    coverage: float
    matched: list[ResidualLine]
    statistic: float = float("nan")
    p_value: float = float("nan")
    gap_after: float = float("nan")
    identified: bool = False
    significant: bool = False
    theta: np.ndarray | None = None
    sigma: np.ndarray | None = None
    main: float = float("nan")
    main_sigma: float = float("nan")
    main_interval: tuple[float, float] = (float("nan"), float("nan"))
    evidence: float = float("nan")
    log_gains: np.ndarray | None = None

    def to_dict(self) -> dict:
        return dict(name=self.name, group=self.group, coverage=self.coverage,
                    statistic=self.statistic, p_value=self.p_value, gap_after=self.gap_after,
                    identified=self.identified, significant=self.significant,
                    main=self.main, main_sigma=self.main_sigma,
                    main_interval=list(self.main_interval), evidence=self.evidence)


@dataclasses.dataclass
class Step:
    """One accepted effect: what was added, why, with which values, and the gaps."""

    number: int
    effect: str
    group: str
    named: str
    indistinguishable_from: list[str]
    matched_lines: list[ResidualLine]
    parameters: list[dict]
    main: dict
    p_value: float
    level: float
    gap_before: GapResult
    gap_after: GapResult
    gap_confirmed: GapResult
    candidates: list[CandidateResult]
    #: the effect's own label (its signature) of each matched line
    matched_labels: list[str] = dataclasses.field(default_factory=list)

    def to_dict(self) -> dict:
        return dict(
            number=self.number, effect=self.effect, group=self.group, named=self.named,
            indistinguishable_from=self.indistinguishable_from,
            matched_lines=[dict(r.to_dict(), signature=lab) for r, lab in
                           zip(self.matched_lines, self.matched_labels or
                               [""] * len(self.matched_lines), strict=True)],
            parameters=self.parameters, main=self.main, p_value=self.p_value, level=self.level,
            gap_before=self.gap_before.to_dict(), gap_after=self.gap_after.to_dict(),
            gap_confirmed=self.gap_confirmed.to_dict(),
            candidates=[c.to_dict() for c in self.candidates])


@dataclasses.dataclass
class DiscoveryResult:
    """Outcome of :func:`discover` (``to_dict`` for JSON; spectra kept for the figures)."""

    kinematics: Kinematics
    f_sun: float
    sample_rate: float
    settings: DiscoverySettings
    steps: list[Step]
    initial_gap: GapResult
    final_gap: GapResult
    unexplained: list[ResidualLine]
    extra_in_model: list[ResidualLine]
    chance_match_probability: float
    stop_reason: str
    last_candidates: list[CandidateResult]
    freqs: np.ndarray
    measured: np.ndarray
    models: list[np.ndarray]
    residuals: list[list[ResidualLine]]
    timing_s: float = 0.0

    @property
    def named(self) -> list[str]:
        return [s.named for s in self.steps]

    @property
    def groups(self) -> list[str]:
        return [s.group for s in self.steps]

    def to_dict(self) -> dict:
        return dict(
            f_sun=self.f_sun, sample_rate=self.sample_rate,
            kinematics=dataclasses.asdict(self.kinematics),
            settings=dataclasses.asdict(self.settings),
            steps=[s.to_dict() for s in self.steps],
            initial_gap=self.initial_gap.to_dict(), final_gap=self.final_gap.to_dict(),
            unexplained=[r.to_dict() for r in self.unexplained],
            extra_in_model=[r.to_dict() for r in self.extra_in_model],
            chance_match_probability=self.chance_match_probability,
            stop_reason=self.stop_reason,
            last_candidates=[c.to_dict() for c in self.last_candidates],
            timing_s=self.timing_s)


# ------------------------------------------------------------------------------ helpers
def _bins_of(freqs_hz: list[float], df: float, n_bins: int, half: int = 1) -> np.ndarray:
    mask = np.zeros(n_bins, bool)
    for f in freqs_hz:
        k = int(round(f / df))
        mask[max(k - half, 0): min(k + half + 1, n_bins)] = True
    return mask


def _log_gain(Y, Z0, floor, thr_db) -> float:
    thr = floor * 10 ** (thr_db / 20.0)
    a0 = np.abs(Z0)
    sel = (Y > thr) & (a0 > 0) & (a0 > 1e-12 * max(a0.max(), 1e-300))
    sel &= a0 * np.exp(np.median(np.log(Y[sel] / a0[sel])) if sel.any() else 1.0) > thr \
        if sel.any() else sel
    if not sel.any():
        return 0.0
    return float(np.median(np.log(Y[sel] / a0[sel])))


def _pad_last(arr, K, value):
    return np.concatenate([arr, np.full(arr.shape[:-1] + (K - arr.shape[-1],), value, arr.dtype)],
                          axis=-1)


def _pad(arr, K, value):
    pad = K - arr.shape[-1] if arr.ndim <= 2 else K - arr.shape[1]
    if arr.ndim == 3:
        return np.concatenate([arr, np.full((arr.shape[0], pad, arr.shape[2]), value,
                                            arr.dtype)], axis=1)
    return np.concatenate([arr, np.full(arr.shape[:-1] + (pad,), value, arr.dtype)], axis=-1)


def _dilate(mask, half=1):
    out = mask.copy()
    for s in range(1, half + 1):
        out[..., s:] |= mask[..., :-s]
        out[..., :-s] |= mask[..., s:]
    return out


def coverage(effect, kin: Kinematics, lines: list[ResidualLine], tol: float, f_max: float):
    """Fraction of the residual (measured-side) line power an effect's signature covers, and
    the lines matched."""
    sig = np.array([s.frequency for s in effect.signature(kin, f_max)])
    meas = [r for r in lines if r.side == "measured"]
    total = sum(r.power_excess for r in meas)
    if sig.size == 0 or total <= 0:
        return 0.0, []
    matched = [r for r in meas if np.min(np.abs(sig - r.frequency)) <= tol]
    return float(sum(r.power_excess for r in matched) / total), matched


def candidate_inputs(Z0, Jc, Y, floor, sig, model_line, nonnegative, log_g0):
    """The padded :class:`FitInputs` of one candidate on the bins that matter (its signature
    bins `sig` and *all* the current model's line bins `model_line`, so the refitted gain is
    set by every line and cannot trade the effect against the lines near its signature;
    masks of shape (F, K)).

    **Returns:** ``(inputs, selected bin indices, padded size)``."""
    fit_m = sig | model_line
    sel = np.flatnonzero(fit_m.any(axis=0))
    K = int(np.ceil(max(len(sel), 1) / BIN_BLOCK) * BIN_BLOCK)
    F, _, p = Jc.shape
    J_pad = np.concatenate([Jc[:, sel], np.zeros((F, len(sel), P_MAX - p))], axis=-1)
    nonneg = np.array(list(nonnegative) + [False] * (P_MAX - p), float)
    active = np.array([1.0] * p + [0.0] * (P_MAX - p))
    inp = FitInputs(
        jnp.asarray(_pad(Z0[:, sel], K, 0.0)), jnp.asarray(_pad(J_pad, K, 0.0)),
        jnp.asarray(_pad(Y[:, sel], K, 1.0)), jnp.asarray(_pad(floor[:, sel], K, 1.0)),
        jnp.asarray(_pad(fit_m[:, sel].astype(float), K, 0.0)),
        jnp.asarray(_pad(sig[:, sel].astype(float), K, 0.0)),
        jnp.asarray(nonneg), jnp.asarray(active), jnp.asarray(np.asarray(log_g0, float)))
    return inp, sel, K


#: Statistics below this (nats) count as zero: a fit that stays at "no effect" gives 0 up to
#: rounding, and such ties must not be broken by rounding noise.
T_RESOLUTION = 1e-6


def p_value(t: float, t_null: np.ndarray, rng: np.random.Generator | None = None) -> float:
    """Bootstrap p-value ``(#{T* > T} + U (#{T* = T} + 1)) / (B + 1)``, U uniform on (0, 1]
    (randomised ties; statistics rounded to :data:`T_RESOLUTION`): uniform under the null even
    when T has a point mass at 0. With `rng` None, U = 1 (conservative)."""
    r = T_RESOLUTION
    t_null = np.round(np.asarray(t_null) / r) * r
    t = np.round(t / r) * r
    u = 1.0 if rng is None else 1.0 - rng.uniform()
    return float((np.sum(t_null > t) + u * (np.sum(t_null == t) + 1)) / (len(t_null) + 1))


def _adapted(effects, context) -> list:
    """The effects specialised by their :meth:`~dtwin.identify.effects.AbstractEffect.adapt` (those
    returning ``None`` withdrawn)."""
    out = []
    for e in effects:
        a = e.adapt(context)
        if a is not None:
            out.append(a)
    return out


def signature_labels(effect, kin: Kinematics, lines: list[ResidualLine], tol: float,
                     f_max: float) -> list[str]:
    """For each line, the label of the nearest signature line of `effect` within `tol` (Hz),
    or "" (the effect's own kinematic description, e.g. bearing frequencies)."""
    sig = effect.signature(kin, f_max)
    if not sig:
        return ["" for _ in lines]
    fs = np.array([s.frequency for s in sig])
    out = []
    for r in lines:
        i = int(np.argmin(np.abs(fs - r.frequency)))
        out.append(sig[i].label if abs(fs[i] - r.frequency) <= tol else "")
    return out


# ------------------------------------------------------------------------------ discover
def discover(
    record,
    spec,
    *,
    sample_rate: float | None = None,
    base_twin=None,
    kind: str | None = None,
    candidates: Sequence | None = None,
    settings: DiscoverySettings = DiscoverySettings(),
    log=None,
) -> DiscoveryResult:
    """Find what the twin is missing, name it, add it, refit, and repeat (docs/discovery.md).

    **Arguments:**

    - `record`: a :class:`dtwin.io.Record` (first channel) or a 1-D signal with `sample_rate`.
    - `spec`: the gearbox spec (`dtwin.spec.Spec`, path or mapping): kinematics, DAQ and the
      base twin (``build_twin(spec, kind=kind)``) unless `base_twin` is given (e.g. the twin
      fitted by :func:`dtwin.identify.fit.fit`).
    - `candidates`: effects to try (default: :func:`dtwin.identify.effects.registered_effects`).
    - `settings`: :class:`DiscoverySettings`.
    - `log`: a callable receiving progress lines (default: silent).

    **Returns:** :class:`DiscoveryResult`.
    """
    import time

    from dtwin.build import build_twin, daq_from_spec
    from dtwin.spec import Spec, load_spec
    from dtwin.spectrum import as_signal

    from .effects import registered_effects

    t_start = time.perf_counter()
    say = log or (lambda s: None)
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    x, fs = as_signal(record, sample_rate)
    n = (len(x) // (2 * settings.n_folds)) * 2 * settings.n_folds
    x = x[:n] - np.mean(x[:n])
    candidates = list(candidates) if candidates is not None else registered_effects()

    # 1. speed from the data, kinematics
    kin0 = Kinematics.from_spec(spec)
    freqs_full, a_full = amplitude_spectrum(x, fs, "hann")
    f_est = estimate_speed(freqs_full, np.asarray(a_full), kin0)
    f_sun = kin0.f_sun if abs(f_est / kin0.f_sun - 1) < 2e-4 else f_est
    kin = Kinematics.from_spec(spec, f_sun)
    f_max = fs / 2
    say(f"speed {f_sun:.4f} Hz (estimated {f_est:.4f}); fm {kin.f_mesh:.2f} Hz")

    # 2. the extended model
    if base_twin is None:
        base_twin = build_twin(spec, kind=kind, f_sun=f_sun)
    daq = daq_from_spec(spec, sample_rate=fs, snr_db=None)
    # candidates specialised to the machine (spec, base twin) first, then to the record (the
    # base twin's residual lines); a second model only when the record changed the set
    from .effects.base import EffectContext

    ctx = EffectContext(spec, base_twin, kin, threshold_db=settings.threshold_db)
    originals = candidates
    candidates = _adapted(originals, ctx)
    model = extended_model(base_twin, candidates, kin, daq, n, f_sun, settings.solver(),
                           settings.response)
    m_sig = model.base_signal()
    _, Zb = segment_spectra(m_sig, fs, settings.n_folds)
    _, Yb = segment_spectra(x, fs, settings.n_folds)
    lgb = [_log_gain(np.abs(Yb[f]), Zb[f], noise_floor(np.abs(Yb[f]), FLOOR_BINS),
                     settings.threshold_db) for f in range(settings.n_folds)]
    _, m_b = amplitude_spectrum(m_sig * float(np.exp(np.mean(lgb))), fs, "hann")
    floor_b = noise_floor(np.asarray(a_full), FLOOR_BINS)
    lines_b = residual_lines(freqs_full, np.asarray(a_full), np.asarray(m_b), kin,
                             threshold_db=settings.threshold_db, excess_db=settings.excess_db,
                             tolerance_bins=settings.tolerance_bins, f_max=f_max)
    ctx = dataclasses.replace(ctx, freqs=freqs_full, measured=np.asarray(a_full),
                              model=np.asarray(m_b), floor=floor_b, lines=tuple(lines_b))
    with_data = _adapted(originals, ctx)
    if with_data != candidates:
        say("candidates specialised to the record: "
            + ", ".join(repr(e) for e in with_data if e not in candidates))
        candidates = with_data
        model = extended_model(base_twin, candidates, kin, daq, n, f_sun, settings.solver(),
                               settings.response)
        m_sig = model.base_signal()
    theta_units = np.zeros(model.size)

    # spectra
    freqs, Yc = segment_spectra(x, fs, settings.n_folds)
    Y = np.abs(Yc)
    floor = noise_floor(Y, FLOOR_BINS)
    df = freqs[1] - freqs[0]
    nb = len(freqs)
    bands = named_bands(kin, f_max)
    floor_full = noise_floor(np.asarray(a_full), FLOOR_BINS)
    tol_full = settings.tolerance_bins * (freqs_full[1] - freqs_full[0])
    chance = chance_match_probability(kin, tol_full, f_max)
    rng = np.random.default_rng(settings.seed)
    seg_len = n // settings.n_folds
    rows = []

    def fold_gains(Z0):
        return np.array([_log_gain(Y[f], Z0[f], floor[f], settings.threshold_db)
                         for f in range(settings.n_folds)])

    def heldout_gap(a_model_folds):
        return gap(freqs, Y, a_model_folds, bands, floor, settings.threshold_db)

    def swap(v):
        return v[::-1]

    steps: list[Step] = []
    models, residual_sets = [], []
    added: set[str] = set()
    stop = "budget"
    last_cands: list[CandidateResult] = []
    initial_gap = None
    for step_no in range(1, settings.max_steps + 2):
        _, Z0 = segment_spectra(m_sig, fs, settings.n_folds)
        lg0 = fold_gains(Z0)
        # held-out gap of the current model: gains fitted on the other fold
        gap_now = heldout_gap(np.exp(swap(lg0))[:, None] * np.abs(Z0))
        if initial_gap is None:
            initial_gap = gap_now
        g_full = float(np.exp(np.mean(lg0)))
        _, m_full = amplitude_spectrum(m_sig * g_full, fs, "hann")
        m_full = np.asarray(m_full)
        models.append(m_full)
        lines = residual_lines(freqs_full, np.asarray(a_full), m_full, kin,
                               threshold_db=settings.threshold_db, excess_db=settings.excess_db,
                               tolerance_bins=settings.tolerance_bins, f_max=f_max)
        residual_sets.append(lines)
        if step_no > settings.max_steps:
            break
        say(f"step {step_no}: held-out gap {gap_now.total:.2f} dB, "
            f"{sum(r.side == 'measured' for r in lines)} residual lines")
        # 3. rank by coverage
        ranked = []
        cov_all: dict[str, float] = {}
        for i, e in enumerate(candidates):
            if e.name in added:
                continue
            cov, matched = coverage(e, kin, lines, tol_full, f_max)
            cov_all[e.name] = cov
            if cov >= settings.min_coverage:
                ranked.append((cov, i, matched))
        ranked.sort(key=lambda t: -t[0])
        ranked = ranked[: settings.max_refit]
        if not ranked:
            stop = "no candidate covers the residual lines"
            last_cands = []
            break
        K_tried = len(ranked)
        level = settings.alpha / K_tried
        # the smallest attainable p-value 1/(B+1) must lie below the level alpha/K
        n_boot = max(settings.n_boot, int(np.ceil(K_tried / settings.alpha)))
        model.ensure_responses([i for _, i, _ in ranked])
        model_line = _dilate(np.abs(Z0) * np.exp(lg0)[:, None]
                             > floor * 10 ** (settings.threshold_db / 20.0))
        results: list[CandidateResult] = []
        for cov, i, matched in ranked:
            e = candidates[i]
            cr = CandidateResult(e.name, e.group, cov, matched)
            say(f"  refit {e.name} (coverage {cov:.2f})")
            Jt = model.response(i)  # (n, p)
            _, Jc = segment_spectra(Jt.T, fs, settings.n_folds)  # (p, F, K)
            Jc = np.moveaxis(Jc, 0, -1)  # (F, K, p)
            sig_lines = [s.frequency for s in e.signature(kin, f_max)]
            sig = np.broadcast_to(_bins_of(sig_lines, df, nb), Y.shape)
            if not getattr(e, "modifies_model_lines", False):
                sig = sig & ~model_line
            ps = model.parameters[i]
            p = Jc.shape[-1]
            inp, sel, K = candidate_inputs(Z0, Jc, Y, floor, sig, model_line,
                                           [q.nonnegative for q in ps], lg0)
            nonneg = np.asarray(inp.nonneg)
            active = np.asarray(inp.active)
            T, fold_params = heldout_statistic(inp)
            T = float(T)
            fold_params = np.asarray(fold_params)
            # held-out gap with the linearised model, parameters from the other fold
            a_lin = np.zeros_like(Y)
            for f in range(settings.n_folds):
                pf = fold_params[1 - f]
                th = theta_of(pf, nonneg, active)[:p]
                a_f = np.exp(pf[-1]) * np.abs(Z0[f] + Jc[f] @ th)
                a_lin[f] = a_f
            cr.gap_after = heldout_gap(a_lin).total
            cr.statistic = T
            # bootstrap null
            t_null = null_statistics(inp, rng, n_boot, Z0, floor, sel, seg_len)
            cr.p_value = p_value(T, t_null, rng)
            cr.significant = cr.p_value <= level and cr.gap_after < gap_now.total
            # joint fit and intervals
            val, loss, jac, r = fit_joint(inp, fold_params)
            m_eff = int(np.sum(np.asarray(inp.fit)))
            n_par = p + settings.n_folds
            keep = np.r_[np.arange(p), P_MAX + np.arange(settings.n_folds)]
            Jk = jac[:, keep]
            s2 = float(np.sum(r**2)) / max(m_eff - n_par, 1)
            try:
                cov_u = s2 * np.linalg.inv(Jk.T @ Jk)
            except np.linalg.LinAlgError:
                cov_u = np.full((n_par, n_par), np.inf)
            u = val[:p]
            dth = np.where(nonneg[:p] > 0, np.exp(np.clip(u, -700, 700)), 1.0)  # dθ/du
            th_units = theta_of(val, nonneg, active)[:p]
            scales = model.scales[model.slice(i)]
            cr.theta = th_units * scales
            cr.sigma = np.sqrt(np.abs(np.diag(cov_u)[:p])) * dth * scales
            gmain = np.asarray(jax.grad(e.main)(jnp.asarray(cr.theta)))
            cov_th = cov_u[:p, :p] * np.outer(dth * scales, dth * scales)
            cr.main = float(e.main(jnp.asarray(cr.theta)))
            cr.main_sigma = float(np.sqrt(max(gmain @ cov_th @ gmain, 0.0)))
            z = _Z99 if settings.confidence == 0.99 else float(
                jax.scipy.stats.norm.ppf(0.5 + settings.confidence / 2))
            # identified: the profile interval of the overall amplitude excludes zero (more
            # reliable than the delta method for a norm near zero, and scale-free)
            c_lo, c_hi, evidence = amplitude_profile(inp, val, s2)
            cr.main_interval = (c_lo * cr.main, c_hi * cr.main)
            cr.evidence = evidence
            cr.identified = bool(c_lo > 0.0 and evidence > CHI2_1_99 and cr.main > 0)
            del z
            cr.log_gains = val[P_MAX:]
            say(f"    T {T:.1f} p {cr.p_value:.4f} (level {level:.4f}) gap {cr.gap_after:.2f} dB "
                f"main {cr.main:.3g} [{cr.main_interval[0]:.3g}, {cr.main_interval[1]:.3g}] "
                f"identified {cr.identified}")
            results.append(cr)
            rows.append(cr)
        last_cands = results
        ok = [c for c in results if c.significant and c.identified]
        if not ok:
            stop = "no candidate significant and identified"
            break
        best = min(ok, key=lambda c: c.gap_after)
        i_best = next(i for i, e in enumerate(candidates) if e.name == best.name)
        members = [e.name for e in candidates if e.group == best.group and e.name != best.name]
        tried = {c.name: c for c in results}
        # a member not refit is told apart only when its signature covers (almost) none of
        # the residual lines; one that covers them but was not refit may fit as well
        ties = [nm for nm in members
                if (nm not in tried and cov_all.get(nm, 0.0) >= settings.min_coverage)
                or (nm in tried and (not np.isfinite(tried[nm].gap_after)
                                     or tried[nm].gap_after - best.gap_after < settings.tie_db))]
        named = best.name if not ties else best.group
        # confirm with the full (nonlinear) model at the joint fit
        theta_units = theta_units.copy()
        theta_units[model.slice(i_best)] = best.theta / model.scales[model.slice(i_best)]
        m_sig = model.signal(theta_units)
        _, Z1 = segment_spectra(m_sig, fs, settings.n_folds)
        lg1 = fold_gains(Z1)
        gap_conf = heldout_gap(np.exp(swap(lg1))[:, None] * np.abs(Z1))
        gap_lin = best.gap_after
        e_best = candidates[i_best]
        params = [dict(name=q.name, unit=q.unit, value=float(v), sigma=float(s),
                       interval=[float(v - _Z99 * s), float(v + _Z99 * s)])
                  for q, v, s in zip(model.parameters[i_best], best.theta, best.sigma, strict=True)]
        main = dict(name=e_best.main_name, unit=e_best.main_unit, value=best.main,
                    sigma=best.main_sigma,
                    interval=list(best.main_interval),
                    interval_kind="profile of the overall amplitude, 99 %",
                    delta_method_sigma=best.main_sigma,
                    typical_range=list(e_best.typical_range), typical_note=e_best.typical_note)
        gap_after = dataclasses.replace(gap_now, total=gap_lin,
                                        bands=dict(gap_now.bands, all=gap_lin))
        steps.append(Step(step_no, best.name, best.group, named, ties, best.matched, params, main,
                          best.p_value, level, gap_now, gap_after, gap_conf, results,
                          signature_labels(e_best, kin, best.matched, tol_full, f_max)))
        added.add(best.name)
        say(f"  added {best.name} (named {named}); gap {gap_now.total:.2f} → {gap_lin:.2f} dB "
            f"(confirmed {gap_conf.total:.2f})")
    final_lines = residual_sets[-1]
    unexplained = [r for r in final_lines if r.side == "measured"]
    extra = [r for r in final_lines if r.side == "model"]
    _, Zf = segment_spectra(m_sig, fs, settings.n_folds)
    lgf = fold_gains(Zf)
    final_gap = heldout_gap(np.exp(swap(lgf))[:, None] * np.abs(Zf))
    del floor_full
    return DiscoveryResult(kin, f_sun, fs, settings, steps, initial_gap, final_gap, unexplained,
                           extra, chance, stop, last_cands, freqs_full, np.asarray(a_full), models,
                           residual_sets, time.perf_counter() - t_start)
