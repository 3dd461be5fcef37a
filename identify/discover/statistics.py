"""The held-out statistic of a candidate and its bootstrap null (the statistics of
:func:`dtwin.identify.discover.discover`; docs/discovery.md).

The linearised model ``A(theta, g) = g |Z0 + J theta|`` of one candidate on its fit bins, the
per-fold fits (Levenberg–Marquardt), the held-out statistic ``T``, the bootstrap null of ``T``
on noise spectra, the joint fit and the profile interval of the effect's overall amplitude.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from dtwin.errors import SettingsError
from dtwin.signal.spectrum import noise_floor

from ..fit import batch_mode
from ..gap import FLOOR_BINS, levels
from ..stopping import StallStopping

#: Parameter counts an effect's arrays are padded to (with inert parameters): the smallest
#: that holds it, so candidates of up to 4 parameters share the compiled fits and bootstrap and
#: do not pay for the larger size; the last is the largest number of parameters of one effect.
P_SIZES = (4, 6)
P_MAX = P_SIZES[-1]
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
    return (levels(a, floor) - levels(Y, floor)) * fit


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
#: Relative loss decrease below which a fold fit stops (`StallStopping`).
FOLD_LOSS_RTOL = 1e-6


# The fold fits stop on a stalled loss (`dtwin.identify.stopping.StallStopping`): a
# non-negative parameter is fitted as ``θ = exp(u)``; when the data put its optimum at θ = 0 —
# the rule rather than the exception in the bootstrap draws under the null — ``u`` walks
# towards −∞ by ever smaller loss decreases and the Cauchy test on the step in ``u`` never
# holds (60 of 60 steps in most draws). The data's statistic and every draw of its null use
# the same rule, so the bootstrap stays calibrated (docs/discovery.md, "When a fold fit stops").
_FOLD_SOLVER = StallStopping(rtol=1e-6, atol=1e-8, loss_rtol=FOLD_LOSS_RTOL)


def _solve(fn, y0, args, solver=_SOLVER):
    sol = optx.least_squares(fn, solver, y0, args=args, options=dict(jac="fwd"),
                             max_steps=MAX_LM_STEPS, throw=False)
    r = fn(sol.value, args)
    return sol.value, jnp.sum(r**2)


def fit_fold(Z0, J, Y, floor, fit, sig, nonneg, active, log_g0):
    """Fit one fold from three starts (:func:`_starts`; Levenberg–Marquardt that also stops
    on a stalled loss, :class:`~dtwin.identify.stopping.StallStopping`): returns
    ``(params, loss)`` of the best, with params = (u (P), log g)."""
    y0s = _starts(Z0, J, Y, floor, sig, nonneg, active, log_g0)
    args = (Z0, J, Y, floor, fit, nonneg, active, log_g0)
    vals, losses = jax.vmap(lambda y0: _solve(_residual_fold, y0, args, _FOLD_SOLVER))(y0s)
    losses = jnp.where(jnp.isfinite(losses), losses, jnp.inf)
    i = jnp.argmin(losses)
    return vals[i], losses[i]


def _stat_fold(params, Z0, J, Y, floor, sig, nonneg, active, log_g0):
    """Held-out contribution of one fold with params fitted on the other: the reduction of the
    squared level error (dB², levels with the expected noise) over the signature bins."""
    u, log_g = params[:-1], params[-1]
    th = _theta(u, nonneg, active)
    lm = levels(Y, floor)
    l0 = levels(_with_noise(jnp.exp(log_g0) * jnp.abs(Z0), floor), floor)
    l1 = levels(_with_noise(_model_amp(Z0, J, th, log_g), floor), floor)
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
def _null_batch(inp: FitInputs, Ystar, floor_star, mode: str = "vmap"):
    """Statistics for bootstrap amplitudes `Ystar` and their re-estimated floors (B, F, K),
    the draws batched by ``jax.vmap`` or run one after the other by ``jax.lax.map``
    (:func:`dtwin.identify.fit.batch_mode`: ``map`` on a CPU, where a vmapped batch runs every
    draw's Levenberg–Marquardt loop until the slowest draw's ends — 2.2 s against 2.8 s CPU for
    50 draws of 1024 bins)."""

    def one(y, fl):
        return _heldout(eqx.tree_at(lambda i: i.floor, inp, fl), y)[0]

    if mode == "map":
        return jax.lax.map(lambda a: one(*a), (Ystar, floor_star))
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
                    floor_full, sel: np.ndarray, seg_len: int, chunk: int = 100,
                    stop: tuple[float, float] | None = None) -> np.ndarray:
    """Bootstrap draws of the held-out statistic under the null (module docstring).

    Each draw: the current model (gain of its fold) plus complex noise with the measured floor's
    level and the window's bin correlation over the whole spectrum; its floor is re-estimated
    (running median, as for the measurement); then the same fit-and-score on the bins `sel`.
    `Z0_full`, `floor_full`: (F, n_bins).

    `stop = (T, level)`: draw in chunks and stop as soon as the draws exceeding the observed
    statistic `T` already number more than ``level (n_draws + 1)`` — then the p-value of the
    full `n_draws` would exceed `level` whatever the remaining draws give, so the decision
    ``p <= level`` is the one the full bootstrap makes (the sequential Monte Carlo test of
    Besag & Clifford 1991, Biometrika 78, 301–304, with the decision of the fixed-size test).
    The draws made so far are returned."""
    mode = batch_mode("auto")
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
        t = _null_batch(inp, jnp.asarray(Yk), jnp.asarray(Fk), mode)
        out.append(np.asarray(t)[:b])
        if stop is not None:
            t_obs = np.round(stop[0] / T_RESOLUTION) * T_RESOLUTION
            drawn = np.round(np.concatenate(out) / T_RESOLUTION) * T_RESOLUTION
            if np.sum(drawn > t_obs) > stop[1] * (n_draws + 1):
                break
    return np.concatenate(out)


def _residual_joint(params, args):
    Z0, J, Y, floor, fit, nonneg, active, log_g0 = args
    P = J.shape[-1]
    del log_g0
    u, log_g = params[:P], params[P:]
    th = _theta(u, nonneg, active)
    a = jnp.exp(log_g)[:, None] * jnp.abs(Z0 + jnp.einsum("fkp,p->fk", J, th.astype(J.dtype)))
    return ((expected_level(a, floor) - levels(Y, floor)) * fit).reshape(-1)


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


def normal_quantile(confidence: float) -> float:
    """Two-sided standard normal quantile ``z`` at `confidence` (2.576 at 99 %, 1.960 at
    95 %): a parameter's interval is ``value ± z sigma``."""
    if not 0.0 < confidence < 1.0:
        raise SettingsError(f"confidence must lie in (0, 1), got {confidence!r}")
    return float(jax.scipy.stats.norm.ppf(0.5 + confidence / 2.0))


def chi2_quantile(confidence: float) -> float:
    """χ² quantile with one degree of freedom at `confidence`, ``z²`` (6.635 at 99 %, 3.841 at
    95 %; Abramowitz & Stegun 1964, table 26.8): the threshold of the profile interval and
    of the evidence in :func:`is_identified`."""
    return normal_quantile(confidence) ** 2


def is_identified(c_low: float, evidence: float, main: float, confidence: float) -> bool:
    """Whether an effect is identified at `confidence`: its profile interval of the overall
    amplitude (:func:`amplitude_profile` with ``chi2_quantile(confidence)``) excludes zero,
    i.e. the evidence ``(loss(0) − loss(θ̂)) / s²`` exceeds the χ² quantile, and the main
    parameter is positive."""
    return bool(c_low > 0.0 and evidence > chi2_quantile(confidence) and main > 0)


def residual_variance(inp: FitInputs, r, n_params: int) -> float:
    """Residual variance ``s² = ‖r‖² / (m − n_params)`` of the joint fit (`r` its residuals,
    `m` the fit bins of every fold, `n_params` the effect's parameters plus one gain per
    fold): the scale of the profile and of the delta-method covariance ``s² (JᵀJ)⁻¹``."""
    m_eff = int(np.sum(np.asarray(inp.fit)))
    return float(np.sum(np.asarray(r) ** 2)) / max(m_eff - n_params, 1)


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



def padded_size(p: int) -> int:
    """The padded parameter count of an effect of `p` parameters (:data:`P_SIZES`)."""
    return next(k for k in P_SIZES if k >= p)


def _pad_last(arr, K, value):
    return np.concatenate([arr, np.full(arr.shape[:-1] + (K - arr.shape[-1],), value, arr.dtype)],
                          axis=-1)


def _pad(arr, K, value):
    pad = K - arr.shape[-1] if arr.ndim <= 2 else K - arr.shape[1]
    if arr.ndim == 3:
        return np.concatenate([arr, np.full((arr.shape[0], pad, arr.shape[2]), value,
                                            arr.dtype)], axis=1)
    return np.concatenate([arr, np.full(arr.shape[:-1] + (pad,), value, arr.dtype)], axis=-1)




def candidate_inputs(Z0, Jc, Y, floor, sig, model_line, nonnegative, log_g0,
                     size: int | None = None):
    """The padded :class:`FitInputs` of one candidate on the bins that matter (its signature
    bins `sig` and *all* the current model's line bins `model_line`, so the refitted gain is
    set by every line and cannot trade the effect against the lines near its signature;
    masks of shape (F, K)). Padded to a multiple of :data:`BIN_BLOCK`, at least `size`
    (candidates padded to one size share the compiled fits and bootstrap).

    **Returns:** ``(inputs, selected bin indices, padded size)``."""
    fit_m = sig | model_line
    sel = np.flatnonzero(fit_m.any(axis=0))
    K = int(np.ceil(max(len(sel), size or 1, 1) / BIN_BLOCK) * BIN_BLOCK)
    F, _, p = Jc.shape
    P = padded_size(p)
    J_pad = np.concatenate([Jc[:, sel], np.zeros((F, len(sel), P - p))], axis=-1)
    nonneg = np.array(list(nonnegative) + [False] * (P - p), float)
    active = np.array([1.0] * p + [0.0] * (P - p))
    inp = FitInputs(
        jnp.asarray(_pad(Z0[:, sel], K, 0.0)), jnp.asarray(_pad(J_pad, K, 0.0)),
        jnp.asarray(_pad(Y[:, sel], K, 1.0)), jnp.asarray(_pad(floor[:, sel], K, 1.0)),
        jnp.asarray(_pad(fit_m[:, sel].astype(float), K, 0.0)),
        jnp.asarray(_pad(sig[:, sel].astype(float), K, 0.0)),
        jnp.asarray(nonneg), jnp.asarray(active), jnp.asarray(np.asarray(log_g0, float)))
    return inp, sel, K


def score_statistic(r, nuisance, columns, mask=None):
    """Rao's score (Lagrange-multiplier) statistic of adding `columns` to a model whose
    residuals at the restricted fit are `r`, with `nuisance` columns free in both (Rao 1948,
    Proc. Cambridge Philos. Soc. 44, 50–57; the regression form of Breusch & Pagan 1980, Rev.
    Econ. Stud. 47, 239–253): in the local linear
    model ``r ≈ N a + X b + e``, e white with variance estimated under the restriction ``b = 0``,

        S = (RSS_N − RSS_NX) / (RSS_N / (m − n_N))

    with ``RSS_N`` the residual sum of squares after projecting out the nuisance columns,
    ``RSS_NX`` after projecting out both, `m` the rows and ``n_N`` the nuisance rank. For a
    model linear in b it is the score form of the refit's F test:
    ``S = (m − n_N) q F / (m − n_N − q + q F)`` with `q` the rank the columns add and
    ``F = ((RSS_N − RSS_NX) / q) / (RSS_NX / (m − n_N − q))``; under the restriction it is
    χ² with `q` degrees of freedom for large `m`.

    **Arguments:** `r` (m,), `nuisance` (m, n_N), `columns` (m, q) real; `mask` (m,) rows that
    count (default all). **Returns:** ``(S, q)``, q the rank the columns add (0: S = 0)."""
    r = np.asarray(r, float)
    N = np.asarray(nuisance, float).reshape(len(r), -1)
    X = np.asarray(columns, float).reshape(len(r), -1)
    if mask is not None:
        keep = np.asarray(mask, bool)
        r, N, X = r[keep], N[keep], X[keep]
    m = len(r)

    def project_out(A, B, scale):
        # rank of A counted against `scale` (the columns' norms before any projection)
        if A.shape[1] == 0:
            return B, 0
        u, sv, _ = np.linalg.svd(A, full_matrices=False)
        rank = int(np.sum(sv > scale * 1e-8)) if scale > 0 else 0
        u = u[:, :rank]
        return B - u @ (u.T @ B), rank

    def norm(A):
        return float(np.max(np.linalg.norm(A, axis=0), initial=0.0))

    rX, n_N = project_out(N, np.column_stack([r, X]), norm(N))
    r_n, X_n = rX[:, 0], rX[:, 1:]
    rss_n = float(r_n @ r_n)
    r_nx, q = project_out(X_n, r_n[:, None], norm(X))
    rss_nx = float(r_nx[:, 0] @ r_nx[:, 0])
    if q == 0 or rss_n <= 0.0 or m - n_N <= 0:
        return 0.0, q
    return (rss_n - rss_nx) / (rss_n / (m - n_N)), q


def score_columns(Z0, J, Y, floor, log_g0):
    """The residual, nuisance and candidate columns of the screening score test
    (:func:`screen_score`) at zero amplitude, per fold and bin (rows fold-major).

    The level model of the fit, ``ℓ(s) = 20 log10(sqrt(s + F² / ln 2) + F)`` with the line
    power ``s = g² |Z0 + J θ|²``, has at θ = 0

    - the gain columns ``∂ℓ/∂ log g = ℓ'(s0) 2 s0`` (one per fold, nuisance);
    - the linear columns ``∂ℓ/∂θ_j = ℓ'(s0) 2 g² Re(conj(Z0) J_j)``: an effect that changes
      lines the model already has (a housing resonance, a time-varying path);
    - the power column ``ℓ'(s0) g² |J v|²``: a line the model lacks has no first derivative
      in θ at θ = 0 (``|J θ|`` is not differentiable there: the information is singular), so
      it is tested in its power ``φ = t²`` along ``θ = t v``, in which the level is linear
      to first order (the classical test of a sinusoid of unknown phase is one on power).
      ``v`` is the direction in which added power most reduces the residual, the top
      eigenvector of ``G = Σ r⊥ ℓ' g² Re(Jᴴ J)`` (r⊥ the residual with the gains projected
      out); with no positive eigenvalue, no power column (power can only be added).

    `Z0` (F, K) complex, `J` (F, K, p) complex, `Y`, `floor` (F, K), `log_g0` (F,).
    **Returns:** ``(r, nuisance, columns)`` with r = measured − model level (F·K,)."""
    Z0 = np.asarray(Z0)
    J = np.asarray(J)
    F, K, p = J.shape
    g2 = np.exp(2.0 * np.asarray(log_g0, float))[:, None]
    s0 = g2 * np.abs(Z0) ** 2
    q = np.sqrt(s0 + floor**2 / np.log(2.0))
    dl = _LN10_20 / ((q + floor) * 2.0 * q)
    r = (_LN10_20 * (np.log(Y + floor) - np.log(q + floor))).reshape(-1)
    nuis = np.zeros((F, K, F))
    for f in range(F):
        nuis[f, :, f] = (dl * 2.0 * s0)[f]
    nuis = nuis.reshape(F * K, F)
    lin = (dl[..., None] * 2.0 * g2[..., None] * np.real(np.conj(Z0)[..., None] * J))
    lin = lin.reshape(F * K, p)
    # the residual with the gains projected out, for the direction of the power column
    a, *_ = np.linalg.lstsq(nuis, r, rcond=None)
    r_perp = (r - nuis @ a).reshape(F, K)
    w = r_perp * dl * g2
    G = np.real(np.einsum("fk,fki,fkj->ij", w, np.conj(J), J))
    ev, vecs = np.linalg.eigh(0.5 * (G + G.T))
    cols = [lin]
    if ev[-1] > 0:
        v = vecs[:, -1]
        cols.append((dl * g2 * np.abs(J @ v) ** 2).reshape(F * K, 1))
    return r, nuis, np.concatenate(cols, axis=1)


def screen_score(Z0, J, Y, floor, log_g0, bins):
    """Score statistic of one candidate at zero amplitude (:func:`score_columns`,
    :func:`score_statistic`) on the bins `bins` (F, K mask): one Jacobian column per
    parameter and no refit. **Returns:** ``(S, q, log10 p)``, p the χ²_q tail of S (the
    screening's ranking key: comparable across candidates with different q)."""
    from scipy.stats import chi2

    r, nuis, cols = score_columns(Z0, J, Y, floor, log_g0)
    S, q = score_statistic(r, nuis, cols, np.asarray(bins, bool).reshape(-1))
    log10p = float(chi2.logsf(S, q) / np.log(10.0)) if q > 0 else 0.0
    return float(S), int(q), log10p


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

