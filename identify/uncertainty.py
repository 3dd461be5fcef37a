"""Uncertainty and identifiability of a fit, from the Jacobian at the optimum.

With ``J = ∂r/∂θ`` (``jax.jacfwd`` of the residuals at the solution θ*, in the nondimensional
coordinates of :mod:`dtwin.identify.params`), ``m`` residuals and ``p`` free parameters:

**Residual variance** ``s² = ‖r‖² / (m - p - q)`` (``q`` = 1 per record whose gain is profiled
out).

**Correlated neighbours.** Neighbouring spectral points are not independent: the Hann window
leaks every line into ~3 bins, so the same noise moves neighbouring log-amplitudes together, and
``s²(JᵀJ)⁻¹`` — which counts every bin as a new observation — would be too small by about the
window's equivalent noise bandwidth (1.5 bins for Hann) or more. We estimate the correlation
``ρ(ℓ)`` of the residuals at lags ``ℓ = 1 … 4`` inside each band (pairs of points of the same
group, :func:`dtwin.identify.residuals.point_groups`), truncated at its first non-positive value, build
the banded correlation matrix ``C`` (zero across bands) and use the sandwich

.. math:: \\operatorname{Cov}(θ) = s² (JᵀJ)^{-1} Jᵀ C J (JᵀJ)^{-1}

(generalised least squares would weight by ``C⁻¹``; the sandwich keeps the fit unweighted and
makes its covariance honest). The effective number of independent points, ``m_eff = m / κ`` with
``κ = 1 + 2 Σ ρ(ℓ)``, is reported; for pure white noise through a Hann window ``κ ≈ 1.9``.

**Physical covariance** ``D Cov(θ) D`` with ``D = diag(dx/dθ)``; 95 % intervals are
``x(θ* ± 1.96 σ_θ)`` mapped through the transform (so a log parameter's interval is asymmetric
and never negative, a logit one never leaves its bounds).

**Not determined** (flag, never reported as precise), when any of:

- ``half-width`` of the 95 % interval ``> 50 %`` of the reference size: the value for ``log``
  parameters; ``max(|value|, 10 % of the range)`` for bounded (``logit``) ones (so a severity of
  0.02 is not flagged for a ±0.03 interval, but is for ±0.06);
- the parameter loads (|component| > 0.3) on a singular direction of the column-scaled
  Jacobian whose singular value is below ``1e-3`` of the largest (a near-null direction: a
  combination such as a product of two parameters that the data cannot see).

**Lack of fit** (:func:`expected_noise_rss`). Under the measurement noise alone the residual
of a point whose measured line stands ``S/F`` above its noise floor has a known mean square
(the log of a Rice amplitude, by Gauss–Hermite quadrature), so the loss a right model would
leave is ``E = Σ w² E[r²]`` over the data points. The ratio ``R = ‖r‖² / E`` is the lack of
fit: ≈ 1 when the twin explains the record up to noise, well above 1 when a model-form error
stands above it. ``s²`` already grows with ``R``, but a model-form residual is not noise: it is
coherent over whole bands, so the sandwich, which counts neighbours only to lag 4, understates
how far it moves the estimate. The stated rule: when ``R > LACK_OF_FIT_LIMIT`` (2) the covariance is
multiplied by ``R`` (every interval widened by ``k = √R``), the widening is reported
(``Uncertainty.widened``) and the fit's table says "widened ×k for lack of fit" instead of "ok";
identifiability flags are judged on the widened intervals. Above ``MODEL_FORM_LIMIT`` (10: the
residual's rms more than three times the noise's) no interval stands for the error: every
parameter is NOT DETERMINED, "the model does not fit this record (loss R× the noise)", and its
value is indicative only.

**Whiteness** (:func:`residual_whiteness`). A model that explains the record up to noise
leaves residuals whose correlation ends where the window's leakage ends: a Hann window spreads
a bin's noise over its two neighbours each side, and points farther apart share none of it
(``reach``: two DFT bins, in points of the fit's grid, :func:`dtwin.identify.residuals.window_reach`).
A misfit spread over more bins than that — lines the record shows smeared by a speed that
drifts, or shifted by a wrong speed, a response that bends across a band — correlates residuals
beyond the reach, whether or not the loss stands above the noise. A line the model lacks or
misses in height is a residual within the reach and is not seen here: the lack-of-fit rule
and the band jackknife see it. The test is the
portmanteau statistic of Ljung & Box (1978) over the ``L = 6`` lags past the reach,
``Q = Σ n_ℓ ρ̂(ℓ)² / b`` with ``ρ̂(ℓ)`` the correlation of pairs of one band at lag ``ℓ``,
``n_ℓ`` their number and ``b = 1 + 2 Σ_{k ≤ reach} ρ̂(k)²`` Bartlett's (1946) variance factor for
lags beyond a correlation of finite reach; under white noise past the reach ``Q ~ χ²_L``.
Below ``p = WHITENESS_P`` (0.001; under the null the test is uniform, ``tests/test_whiteness.py``)
the residuals are called not white, and the
fit's status says so instead of "ok" (``Uncertainty.whiteness_p``); the intervals are not
widened by it (the lack-of-fit rule and the band jackknife size them).

**Band jackknife** (:func:`band_jackknife`). The lack-of-fit rule widens only when the loss
stands above the noise; a model-form error can also hide at the noise level and still move an
estimate (a wrong fault shape shifts every sideband of one band together, and each band by a
different amount). The bands are then the independent blocks: each is left out in turn, the
optimum moved by one Gauss–Newton step, and the spread of those estimates gives a jackknife
variance and a Student-t interval with ``B − 1`` degrees of freedom (Quenouille 1956; Tukey
1958). Under noise alone it estimates the sampling variance; when the bands disagree beyond
their noise it grows with the disagreement, and it keeps its coverage where intervals that
count independent points lose it (Monte Carlo in ``tests/test_severity_rules.py``).
:mod:`dtwin.identify.severity` uses it on request (``jackknife=True``) and takes the hull with
the sandwich interval.

**Profile likelihood** for severities (``*_fault``) within ``2σ`` of 0 or 1: the severity is
stepped over a grid across its range, the other parameters follow by one Gauss–Newton step from
the optimum (with ``J`` at the optimum), and the interval is where
``(‖r‖² - ‖r*‖²)/(s² κ_i) ≤ 3.84`` (χ²₁, 95 %); ``κ_i`` is the sandwich's inflation of that
parameter's variance. A second grid of the same size lies between the values that bracket each
edge, and the edge is interpolated where the profile crosses 3.84 between its nearest values
inside and outside (a single grid would leave an edge anywhere within one grid step). A
profile point whose loss lies below the optimum's by more than the χ² level shows that the
optimum is a local one: it is reported (``Uncertainty.better``), and
:func:`dtwin.identify.fit.fit` goes on from it.

**Scan** of a ``log`` parameter (``scan`` of :func:`analyse`; :func:`dtwin.identify.fit.fit`
scans the free stiffnesses, masses and inertias). A stiffness moves the twin's modes, and a
record measures it through products with other quantities and through a mode's passage near
the record's lines, so its loss can have more than one minimum; the Jacobian at one of them
says nothing of the others. The loss is evaluated at the fitted value times ``10^u`` for ``u``
= ±0.25, ±0.5, ±0.75, ±1 (the other parameters following by one Gauss–Newton step, a point
kept before the step where the step raises its loss): a scan point of lower loss by more than
the χ²₁ level is reported as above (``better``); the interval becomes the hull of the
Gaussian one and the range over which the scan stays within the level (edges interpolated in
log value); and a scan point within the level that a point outside it separates from the
optimum is a second minimum the record does not rule out: the parameter is flagged NOT
DETERMINED with the range. Only parameters the rules above find determined are scanned: a
value that looks determined is what a second minimum would make wrong, while a flagged one is
already reported as not known.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from scipy.stats import chi2
from scipy.stats import t as student_t

__all__ = ["LACK_OF_FIT_LIMIT", "WHITENESS_P", "Uncertainty", "analyse", "band_jackknife",
           "expected_noise_rss", "noise_mse", "residual_correlation", "residual_whiteness"]

Z95 = 1.959963984540054
CHI2_95 = 3.841458820694124
MAX_LAG = 4
NULL_RATIO = 1e-3
HALF_WIDTH_LIMIT = 0.5
#: Lack-of-fit ratio (loss over the loss the noise alone would leave) above which the
#: intervals are widened by its square root (module docstring).
LACK_OF_FIT_LIMIT = 2.0
#: Lack of fit above which no interval is trusted (module docstring, "Lack of fit"): the loss
#: is more than ten times what the noise alone leaves (the residual's rms over three times the
#: noise's), a model-form error larger than anything a widened interval can stand for. Every
#: parameter is then NOT DETERMINED ("the model does not fit this record") and its value is
#: indicative only.
MODEL_FORM_LIMIT = 10.0
#: The start of the reason given for a parameter of a fit above :data:`MODEL_FORM_LIMIT`.
MODEL_FORM_REASON = "the model does not fit this record"
#: p-value of the whiteness test below which a fit's residuals are called not white (module
#: docstring, "Whiteness").
WHITENESS_P = 1e-3
#: Lags past the window's reach the whiteness test sums over.
WHITENESS_LAGS = 6


def half_width_scale(value: float, transform: str, lower: float, upper: float) -> float:
    """What a parameter's 95 % half-width is judged against (``HALF_WIDTH_LIMIT`` of it, or
    the parameter is not determined): ``|value|``, and for a ``logit`` parameter at least 10 %
    of its range (a severity near 0 is still determined by a narrow interval)."""
    if transform == "logit":
        return max(abs(float(value)), 0.1 * (float(upper) - float(lower)))
    return abs(float(value))


@dataclasses.dataclass(frozen=True)
class Uncertainty:
    """Result of :func:`analyse` (SI values; names in `names` order).

    - `std`: standard deviations (SI); `interval`: 95 % (lower, upper) per parameter;
    - `cov_theta`, `cov`: covariance in θ and in SI; `correlation`: correlation matrix;
    - `singular_values`: of the column-scaled Jacobian (descending), `null_directions`: right
      singular vectors with ratio below ``1e-3`` (rows);
    - `not_determined`: name → reason; `s2`, `kappa` (neighbour correlation factor), `m`,
      `m_eff`, `dof`; `profiled`: names whose interval is a profile-likelihood interval;
    - `lack_of_fit`: ``‖r‖²`` over the loss expected from the noise alone (nan when unknown);
      `widened`: the factor every interval was widened by for lack of fit (1: none);
    - `better`: ``(name, θ, ‖r‖²)`` when a severity's profile or a scan passed a point whose
      loss lies below the optimum's by more than the χ²₁ 95 % level (the optimum is a local
      one), else None;
    - `scanned`: names whose loss was scanned over a decade each side (``scan`` of
      :func:`analyse`);
    - `whiteness`, `whiteness_p`: the whiteness test's statistic and p-value
      (:func:`residual_whiteness`; nan when not made).
    """

    names: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    interval: np.ndarray
    cov_theta: np.ndarray
    cov: np.ndarray
    correlation: np.ndarray
    singular_values: np.ndarray
    null_directions: np.ndarray
    not_determined: dict[str, str]
    s2: float
    kappa: float
    m: int
    m_eff: float
    dof: int
    profiled: tuple[str, ...] = ()
    lack_of_fit: float = float("nan")
    widened: float = 1.0
    better: tuple[str, np.ndarray, float] | None = None
    scanned: tuple[str, ...] = ()
    whiteness: float = float("nan")
    whiteness_p: float = float("nan")

    @property
    def white(self) -> bool:
        """False when the whiteness test rejects (p below :data:`WHITENESS_P`); True when it
        passes or was not made."""
        return not (np.isfinite(self.whiteness_p) and self.whiteness_p < WHITENESS_P)

    def to_dict(self) -> dict:
        return {
            "names": list(self.names),
            "values": self.values.tolist(),
            "std": self.std.tolist(),
            "interval_95": self.interval.tolist(),
            "correlation": self.correlation.tolist(),
            "singular_values": self.singular_values.tolist(),
            "not_determined": dict(self.not_determined),
            "s2": self.s2, "kappa": self.kappa, "m": self.m, "m_eff": self.m_eff, "dof": self.dof,
            "profiled": list(self.profiled), "scanned": list(self.scanned),
            "lack_of_fit": self.lack_of_fit, "widened": self.widened,
            "whiteness": self.whiteness, "whiteness_p": self.whiteness_p,
        }


def residual_correlation(r: np.ndarray, groups: np.ndarray, max_lag: int = MAX_LAG) -> np.ndarray:
    """``ρ(0..max_lag)`` of residuals between points of the same group, truncated at the first
    non-positive lag (module docstring)."""
    r = np.asarray(r, dtype=float)
    groups = np.asarray(groups)
    r0 = float(np.sum(r * r))
    rho = [1.0]
    for lag in range(1, max_lag + 1):
        if r.size <= lag or r0 == 0:
            break
        same = groups[lag:] == groups[:-lag]
        if not np.any(same):
            break
        # normalise by the energy of the points that have a partner at this lag
        num = np.sum(r[lag:][same] * r[:-lag][same])
        den = np.sqrt(np.sum(r[lag:][same] ** 2) * np.sum(r[:-lag][same] ** 2))
        c = float(num / den) if den > 0 else 0.0
        if c <= 0:
            break
        rho.append(c)
    return np.asarray(rho)


def residual_whiteness(r: np.ndarray, groups: np.ndarray, reach: int = 2,
                       n_lags: int = WHITENESS_LAGS) -> tuple[float, float]:
    """Ljung–Box statistic ``Q`` of the residuals' correlation between points of one group at
    lags ``reach + 1 … reach + n_lags`` and its p-value under white noise past `reach` (χ² with
    the number of lags that have pairs), with Bartlett's variance factor from the correlation
    within `reach` (module docstring, "Whiteness"). (nan, nan) without pairs."""
    r = np.asarray(r, dtype=float)
    groups = np.asarray(groups)
    ms = float(np.mean(r * r)) if r.size else 0.0
    if ms == 0.0:
        return float("nan"), float("nan")

    def rho(lag):
        if r.size <= lag:
            return 0.0, 0
        same = groups[lag:] == groups[:-lag]
        n = int(np.count_nonzero(same))
        return (float(np.mean(r[lag:][same] * r[:-lag][same]) / ms) if n else 0.0), n

    b = 1.0 + 2.0 * sum(rho(k)[0] ** 2 for k in range(1, reach + 1))
    q, dof = 0.0, 0
    for lag in range(reach + 1, reach + 1 + n_lags):
        c, n = rho(lag)
        if n:
            q += n * c * c / b
            dof += 1
    if not dof:
        return float("nan"), float("nan")
    return float(q), float(chi2.sf(q, dof))


def _banded(groups: np.ndarray, rho: np.ndarray):
    """Function v ↦ C v for the banded correlation matrix (no dense m × m matrix)."""

    def apply(v):
        out = v.copy()
        for lag in range(1, rho.size):
            same = groups[lag:] == groups[:-lag]
            out[lag:] += rho[lag] * np.where(same, v[:-lag], 0.0)
            out[:-lag] += rho[lag] * np.where(same, v[lag:], 0.0)
        return out

    return apply


_GH_NODES = 64


def _rice_log_mse(snr: np.ndarray) -> np.ndarray:
    """``E[(log(sqrt(S² + F²) + F) - log(A + F))²]`` for ``A = |S + N|``, ``N`` complex Gaussian
    noise whose amplitude has median ``F`` (``E|N|² = F²/ln 2``), at ``S/F = snr``; Gauss–Hermite
    quadrature over the two noise components (``F = 1``)."""
    x, w = np.polynomial.hermite_e.hermegauss(_GH_NODES)
    w = w / w.sum()
    sigma = 1.0 / np.sqrt(2.0 * np.log(2.0))  # per component: median |N| = 1
    S = np.asarray(snr, dtype=float)[..., None, None]
    a = np.hypot(S + sigma * x[:, None], sigma * x[None, :])
    model = np.log(np.sqrt(S * S + 1.0) + 1.0)
    return np.sum(w[:, None] * w[None, :] * (model - np.log(a + 1.0)) ** 2, axis=(-2, -1))


_SNR_TABLE = np.concatenate([[0.0], np.logspace(-2, 3, 121)])
_MSE_TABLE: np.ndarray | None = None


def noise_mse(level: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """Mean square residual (log units) the measurement noise alone leaves at spectral points of
    measured amplitude `level` over a noise floor (Rayleigh median) `floor`: the line under the
    noise is taken as ``S = sqrt(max(A² - F²/ln 2, 0))`` and :func:`_rice_log_mse` interpolated
    in ``log S/F``."""
    global _MSE_TABLE
    if _MSE_TABLE is None:
        _MSE_TABLE = _rice_log_mse(_SNR_TABLE)
    level = np.asarray(level, dtype=float)
    floor = np.maximum(np.asarray(floor, dtype=float), 1e-300)
    snr = np.sqrt(np.maximum((level / floor) ** 2 - 1.0 / np.log(2.0), 0.0))
    return np.interp(np.log(np.maximum(snr, 1e-6)), np.log(np.maximum(_SNR_TABLE, 1e-6)),
                     _MSE_TABLE)


def expected_noise_rss(observations) -> float:
    """Loss ``Σ r²`` that the measurement noise alone would leave on these observations'
    residual points if the twin were right (module docstring, "Lack of fit"): per point
    :func:`noise_mse` of the measured level over its floor, times the record's weight² (and the
    envelope weight² for envelope points)."""
    total = 0.0
    for o in observations:
        floor = np.asarray(o.floor, dtype=float)
        level = np.exp(np.asarray(o.meas, dtype=float)) - floor
        total += float(o.weight) ** 2 * float(np.sum(noise_mse(level, floor)))
        if o.env_weight:
            ef = np.asarray(o.env_floor, dtype=float)
            el = np.exp(np.asarray(o.env_meas, dtype=float)) - ef
            total += (float(o.weight) * float(o.env_weight)) ** 2 * float(
                np.sum(noise_mse(el, ef)))
    return total


def analyse(
    pset, theta, r, J, groups, *, n_profiled_gains: int = 0, profile_fn=None,
    expected_rss: float | None = None, scan: Sequence[str] = (), reach: int | None = None,
) -> Uncertainty:
    """Covariance, intervals and identifiability flags (module docstring).

    **Arguments:** `pset` (:class:`dtwin.identify.params.ParameterSet`); `theta` (optimum); `r`
    (residuals, ``(m,)``); `J` (``(m, p)`` at the optimum); `groups` (point groups); the number
    of profiled gains; `profile_fn(thetas) -> residuals` (batched, ``(k, p) → (k, m)``) for the
    profile likelihood of severities (optional); `expected_rss`: the loss the noise alone
    would leave (:func:`expected_noise_rss`; None: no lack-of-fit test); `scan`: free
    ``log`` parameters whose loss is scanned over a decade each side of the optimum (module
    docstring, "Scan"; needs `profile_fn`); `reach`: the window's reach in points
    (:func:`dtwin.identify.residuals.window_reach`; None: no whiteness test).
    """
    theta = np.asarray(theta, dtype=float)
    r = np.asarray(r, dtype=float)
    J = np.asarray(J, dtype=float)
    m, p = J.shape
    names = pset.free
    n_prior = len(pset.priors)
    m_data = m - n_prior
    dof = max(m_data - p - n_profiled_gains, 1)
    s2 = float(np.sum(r[:m_data] ** 2) / dof)
    groups = np.concatenate([np.asarray(groups), -1 - np.arange(n_prior)])
    rho = residual_correlation(r[:m_data], groups[:m_data])
    white_q, white_p = (residual_whiteness(r[:m_data], groups[:m_data], reach)
                        if reach is not None else (float("nan"), float("nan")))
    kappa = float(1.0 + 2.0 * np.sum(rho[1:]))
    # scaled Jacobian and its SVD (columns scaled to unit norm: conditioning, null directions)
    col = np.linalg.norm(J, axis=0)
    col_safe = np.where(col > 0, col, 1.0)
    Js = J / col_safe
    U, sv, Vt = np.linalg.svd(Js, full_matrices=False)
    ratio = sv / sv[0] if sv[0] > 0 else np.zeros_like(sv)
    null = Vt[ratio < NULL_RATIO]
    # sandwich covariance; the pseudo-inverse of the column-scaled normal matrix (parameters of
    # very different θ scales, e.g. a transmission error in metres next to a log stiffness,
    # keep their information)
    JtJ_inv = np.linalg.pinv(Js.T @ Js, rcond=1e-14) / np.outer(col_safe, col_safe)
    CJ = np.column_stack([_banded(groups, rho)(J[:, i]) for i in range(p)])
    cov_t = s2 * JtJ_inv @ (J.T @ CJ) @ JtJ_inv
    cov_t = 0.5 * (cov_t + cov_t.T)
    rss = float(np.sum(r[:m_data] ** 2))
    lack = rss / expected_rss if expected_rss else float("nan")
    widen = float(lack) if np.isfinite(lack) and lack > LACK_OF_FIT_LIMIT else 1.0
    cov_t = cov_t * widen
    plain = widen * s2 * np.diag(JtJ_inv)
    inflation = np.where(plain > 0, np.diag(cov_t) / np.where(plain > 0, plain, 1.0), 1.0)
    std_t = np.sqrt(np.clip(np.diag(cov_t), 0.0, None))
    std_t = np.where(col > 0, std_t, np.inf)
    d = np.asarray(pset.dvalues_dtheta(theta))
    values = np.asarray(pset.values(theta))
    cov = cov_t * np.outer(d, d)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov_t / np.outer(std_t, std_t)
    corr = np.where(np.isfinite(corr), corr, 0.0)
    lo_t = np.where(np.isfinite(std_t), theta - Z95 * std_t, -50.0)
    hi_t = np.where(np.isfinite(std_t), theta + Z95 * std_t, 50.0)
    lo = np.asarray(pset.values(np.clip(lo_t, -50, 50)))
    hi = np.asarray(pset.values(np.clip(hi_t, -50, 50)))
    interval = np.stack([np.minimum(lo, hi), np.maximum(lo, hi)], axis=1)
    profiled, better = [], None
    if profile_fn is not None:
        better = _profile_severities(pset, theta, r, J, values, d, std_t, widen * s2, inflation,
                                     profile_fn, m_data, rss, interval, profiled)
    std = np.abs(d) * std_t

    def flag(i, n):
        return _flag(i, interval, values, pset, null, sv, ratio, names, p)

    flags: dict[str, str] = {n: f for i, n in enumerate(names) if (f := flag(i, n))}
    scanned = []
    if profile_fn is not None:
        better = _scan_determined(pset, theta, r, J, std_t, widen * s2, inflation, profile_fn,
                                  m_data, rss, interval, flags, scan, scanned, better, flag)
    if np.isfinite(lack) and lack > MODEL_FORM_LIMIT:  # a model-form failure, not a precise answer
        why = f"{MODEL_FORM_REASON} (loss {lack:.3g}× the noise)"
        flags = {n: why + (f"; {flags[n]}" if n in flags else "") for n in names}
    return Uncertainty(
        names=tuple(names), values=values, std=std, interval=interval, cov_theta=cov_t, cov=cov,
        correlation=corr, singular_values=sv, null_directions=null, not_determined=flags,
        s2=s2, kappa=kappa, m=m_data, m_eff=m_data / kappa, dof=dof, profiled=tuple(profiled),
        lack_of_fit=float(lack), widened=float(np.sqrt(widen)), better=better,
        scanned=tuple(scanned), whiteness=white_q, whiteness_p=white_p,
    )


def _profile_severities(pset, theta, r, J, values, d, std_t, w_s2, inflation, profile_fn,
                        m_data, rss, interval, profiled):
    """The profile likelihood of each free severity (``logit``, ``*_fault``) whose interval
    reaches within two standard errors of a bound: its interval (in `interval`, in place) and
    its name (appended to `profiled`). **Returns:** ``better``, ``(name, θ, rss)`` of a profile
    point whose loss lies below the optimum's by more than the χ²₁ level, or None."""
    better = None
    for i, n in enumerate(pset.free):
        if not n.endswith("_fault") or pset.transforms[i] != "logit":
            continue
        near = (values[i] - pset.lower[i] < 2 * abs(d[i]) * std_t[i]
                or pset.upper[i] - values[i] < 2 * abs(d[i]) * std_t[i])
        if not near or not np.isfinite(std_t[i]):
            continue
        out = _profile_interval(pset, theta, r, J, i, w_s2 * inflation[i], profile_fn, m_data)
        if out is None:
            continue
        interval[i], (th_best, rss_best) = out
        profiled.append(n)
        # a profile point whose loss lies below the optimum's by more than the χ²₁ level:
        # the optimum is a local one (fit refits from it, dtwin.identify.fit)
        if (rss - rss_best) / (w_s2 * inflation[i]) > CHI2_95 and (
                better is None or rss_best < better[2]):
            better = (n, np.asarray(th_best), rss_best)
    return better


def _flag(i, interval, values, pset, null, sv, ratio, names, p) -> str | None:
    """Why parameter `i` is not determined (its 95 % half-width against its scale, a
    near-null singular direction it takes part in), or None."""
    half = 0.5 * (interval[i, 1] - interval[i, 0])
    ref = half_width_scale(values[i], pset.transforms[i], pset.lower[i], pset.upper[i])
    out = None
    if not np.isfinite(half) or half > HALF_WIDTH_LIMIT * ref:
        out = (f"95 % half-width {half:.3g} exceeds {100 * HALF_WIDTH_LIMIT:.0f} % of "
               f"{ref:.3g}")
    for v, s in zip(null, sv[ratio < NULL_RATIO], strict=True):
        if abs(v[i]) > 0.3:
            others = [names[j] for j in range(p) if j != i and abs(v[j]) > 0.3]
            out = (f"near-null singular direction (σ/σmax = {s / sv[0]:.1e})"
                   + (f" shared with {', '.join(others)}" if others else ""))
    return out


def _scan_determined(pset, theta, r, J, std_t, w_s2, inflation, profile_fn, m_data, rss,
                     interval, flags, scan, scanned, better, flag):
    """The scan (module docstring, "Scan") of the parameters in `scan` the Gaussian analysis
    finds determined (a value that looks determined is what a second minimum would make
    wrong): `interval`, `flags` and `scanned` updated in place. **Returns:** `better`, or a
    scanned point of lower loss (as :func:`_profile_severities`)."""
    for i, n in enumerate(pset.free):
        if (n not in scan or n in flags or pset.transforms[i] != "log"
                or not np.isfinite(std_t[i])):
            continue
        s2_i = w_s2 * inflation[i]
        span, far, (th_best, rss_best) = _profile_scan(pset, theta, r, J, i, s2_i,
                                                       profile_fn, m_data)
        scanned.append(n)
        if span is not None:
            interval[i] = [min(interval[i, 0], span[0]), max(interval[i, 1], span[1])]
        if far is not None:
            flags[n] = (f"the loss along it comes back within the 95 % level at "
                        f"{far:.4g} (a second minimum the record does not rule out); "
                        f"95 % range [{interval[i, 0]:.4g}, {interval[i, 1]:.4g}]")
        elif (f := flag(i, n)):
            flags[n] = f
        if (rss - rss_best) / s2_i > CHI2_95 and (better is None or rss_best < better[2]):
            better = (n, np.asarray(th_best), rss_best)
    return better


def _profile_rss(pset, theta, J, i, xs, profile_fn, m_data):
    """Residual sum of squares of the data along the profile of parameter `i`: at each value
    ``xs`` (SI) of it, the other parameters moved by one Gauss–Newton step from the optimum
    (`J` the Jacobian there)."""
    thetas = np.repeat(theta[None, :], len(xs), axis=0)
    v = np.asarray(pset.values(theta)).copy()
    for g, x in enumerate(xs):
        v[i] = x
        thetas[g, i] = pset.theta(v)[i]
    return _follow(thetas, J, i, profile_fn, m_data)


def _follow(thetas, J, i, profile_fn, m_data):
    """``(‖r‖², θ)`` at each row of `thetas` after the parameters other than `i` follow by one
    Gauss–Newton step (`J` the Jacobian at the optimum); a row where the step raises the loss
    keeps its point before the step (each loss then bounds the profile from above)."""
    thetas = np.array(thetas, dtype=float)
    rr = np.asarray(profile_fn(thetas))
    rss = np.sum(rr[:, :m_data] ** 2, axis=1)
    others = [j for j in range(thetas.shape[1]) if j != i]
    if not others:
        return rss, thetas
    moved = thetas.copy()
    moved[:, others] += -np.linalg.lstsq(J[:, others], rr.T, rcond=None)[0].T
    rr2 = np.asarray(profile_fn(moved))
    rss2 = np.sum(rr2[:, :m_data] ** 2, axis=1)
    take = np.isfinite(rss2) & ~(rss2 > rss)
    return np.where(take, rss2, rss), np.where(take[:, None], moved, thetas)


#: Decades (log10 of the factor on the fitted value) at which :func:`_profile_scan` evaluates
#: the loss: a decade each side in quarter-decade steps.
SCAN_DECADES = np.array([-1.0, -0.75, -0.5, -0.25, 0.25, 0.5, 0.75, 1.0])


def _profile_scan(pset, theta, r, J, i, s2_i, profile_fn, m_data):
    """Loss along ``log`` parameter `i` over a decade each side of the optimum (module
    docstring, "Scan").

    **Returns:** ``(span, far, (θ, ‖r‖²))``: the range (SI) over which the loss stays within
    the χ²₁ 95 % level (edges interpolated in log value where it crosses; None when no scan
    point lies inside), the value of the farthest scan point inside that level which a point
    outside it separates from the optimum (None when the inside points are contiguous), and
    the scan point of lowest loss."""
    ln = np.log(10.0) * SCAN_DECADES
    thetas = np.repeat(np.asarray(theta, dtype=float)[None, :], ln.size, axis=0)
    thetas[:, i] += ln
    rss, thetas = _follow(thetas, J, i, profile_fn, m_data)
    rss = np.where(np.isfinite(rss), rss, np.inf)
    rss_opt = float(np.sum(np.asarray(r)[:m_data] ** 2))
    # the optimum itself at 0 decades, in order
    u = np.concatenate([ln[ln < 0], [0.0], ln[ln > 0]])
    loss = np.concatenate([rss[ln < 0], [rss_opt], rss[ln > 0]])
    q = (loss - min(rss_opt, float(rss.min()))) / s2_i
    inside = q <= CHI2_95
    x0 = float(pset.values(theta)[i])
    best = int(np.argmin(rss))
    if not inside.any():
        return None, None, (thetas[best], float(rss[best]))
    a, b = np.flatnonzero(inside)[[0, -1]]
    lo = u[a] if a == 0 else _crossing(u[a], u[a - 1], q[a], q[a - 1])
    hi = u[b] if b == u.size - 1 else _crossing(u[b], u[b + 1], q[b], q[b + 1])
    centre = int(np.flatnonzero(u == 0.0)[0])
    far = None
    gaps = [k for k in range(a, b + 1) if not inside[k]]
    if gaps:
        # inside points beyond an outside one: the farthest of them from the optimum
        cands = [k for k in (a, b) if any((g - centre) * (k - g) > 0 for g in gaps)]
        if cands:
            k = max(cands, key=lambda k: abs(u[k]))
            far = x0 * float(np.exp(u[k]))
    return x0 * np.exp(np.array([lo, hi])), far, (thetas[best], float(rss[best]))


def _crossing(x0, x1, q0, q1):
    """Where ``q`` reaches the χ² level between ``(x0, q0)`` and ``(x1, q1)``, one inside and
    one outside (linear interpolation; the midpoint when ``q`` does not change there)."""
    if q1 == q0:
        return 0.5 * (x0 + x1)
    u = min(max((CHI2_95 - q0) / (q1 - q0), 0.0), 1.0)
    return x0 + u * (x1 - x0)


def _profile_interval(pset, theta, r, J, i, s2_i, profile_fn, m_data, n_grid: int = 13):
    """Profile-likelihood 95 % interval of parameter `i` (a bounded severity) and the profile
    point of lowest loss, ``(interval, (θ, ‖r‖²))``.

    The profile is evaluated on `n_grid` values across the parameter's range, then on
    `n_grid` more between the grid values that bracket each edge of the interval (a batch of
    the same size, so no new compilation), and each edge is interpolated where the profile
    crosses the χ² level between its two nearest values, inside and outside."""
    lo, hi = pset.lower[i], pset.upper[i]
    xs = np.linspace(lo + 1e-3 * (hi - lo), hi - 1e-3 * (hi - lo), n_grid)
    rss, thetas = _profile_rss(pset, theta, J, i, xs, profile_fn, m_data)
    rss0 = min(float(np.sum(r[:m_data] ** 2)), float(rss.min()))
    inside = (rss - rss0) / s2_i <= CHI2_95
    if not inside.any():
        return None
    a, b = np.flatnonzero(inside)[[0, -1]]
    brackets = ([(xs[a - 1], xs[a])] if a > 0 else []) + \
               ([(xs[b], xs[b + 1])] if b < n_grid - 1 else [])
    if brackets:
        k = n_grid // len(brackets)
        fine = np.concatenate([np.linspace(x0, x1, k + 2)[1:-1] for x0, x1 in brackets])
        fine = np.concatenate([fine, np.full(n_grid - fine.size, fine[-1])])
        rss_fine, thetas_fine = _profile_rss(pset, theta, J, i, fine, profile_fn, m_data)
        order = np.argsort(np.concatenate([xs, fine]), kind="stable")
        xs = np.concatenate([xs, fine])[order]
        rss = np.concatenate([rss, rss_fine])[order]
        thetas = np.concatenate([thetas, thetas_fine])[order]
        rss0 = min(rss0, float(rss_fine.min()))
    q = (rss - rss0) / s2_i
    a, b = np.flatnonzero(q <= CHI2_95)[[0, -1]]
    lo_v = lo if a == 0 else _crossing(xs[a], xs[a - 1], q[a], q[a - 1])
    hi_v = hi if b == xs.size - 1 else _crossing(xs[b], xs[b + 1], q[b], q[b + 1])
    best = int(np.argmin(rss))
    return np.array([lo_v, hi_v]), (thetas[best], float(rss[best]))


def band_jackknife(theta, r, J, groups, *, level: float = 0.95):
    """Delete-one-band jackknife of a fit (module docstring, "Band jackknife").

    A model-form error is coherent over a whole band (a wrong loss shape moves every sideband
    of one mesh harmonic together), so the bands, not the points, are the independent
    blocks (the delete-a-group jackknife; blocks as in Künsch, Ann. Statist. 17 (1989)
    1217–1241). Each band ``b`` is left out in turn and the optimum moved by one Gauss–Newton step,
    ``θ_(−b) = θ* − (J_{−b}ᵀ J_{−b})⁻¹ J_{−b}ᵀ r_{−b}`` (``J``, ``r`` at the optimum; prior
    rows, ``groups < 0``, are kept); the jackknife variance is
    ``V = (B − 1)/B Σ_b (θ_(−b) − θ̄)²`` and the interval ``θ* ± t_{B−1} √V`` (Student's t
    with ``B − 1`` degrees of freedom: few blocks). Under noise alone ``V`` estimates the
    sampling variance; when the bands disagree beyond it (a model-form error that each band
    sees differently) it grows with their disagreement.

    **Arguments:** `theta` ``(p,)``; `r` ``(m,)``; `J` ``(m, p)``; `groups` ``(m,)`` (band per
    row, negative for priors); `level`. **Returns:** ``(half_width (p,), leave-one-out θ
    (B, p))`` in θ; half-width nan with fewer than 3 bands.
    """
    theta = np.asarray(theta, dtype=float)
    r, J = np.asarray(r, dtype=float), np.asarray(J, dtype=float)
    groups = np.asarray(groups)
    bands = [g for g in np.unique(groups) if g >= 0]
    B = len(bands)
    if B < 3:
        return np.full(theta.shape, np.nan), np.zeros((0, theta.size))
    loo = []
    for g in bands:
        keep = groups != g
        Jk, rk = J[keep], r[keep]
        step = np.linalg.lstsq(Jk, rk, rcond=None)[0]
        loo.append(theta - step)
    loo = np.asarray(loo)
    var = (B - 1) / B * np.sum((loo - loo.mean(axis=0)) ** 2, axis=0)
    q = float(student_t.ppf(0.5 + 0.5 * level, B - 1))
    return q * np.sqrt(var), loo

