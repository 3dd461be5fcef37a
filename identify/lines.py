"""Residual line analysis: which spectral lines the measurement has and the model lacks (and the
reverse), each described by the kinematic combinations that explain it.

**Kinematic basis** (:class:`dtwin.kinematics.Kinematics`, Hz, speed taken from the data first with
:func:`estimate_speed`): ``fm`` (mesh), ``fc`` (carrier), ``fsr`` (absolute sun rotation),
``fs/N`` (sun-fault repetition over the number of planets, = fsr − fc), ``fp`` (planet fault,
fm/Zp), ``fr`` (ring fault, fm N/Zr = N fc), ``fe`` (the motor's electrical frequency, pole pairs
× sun speed).

**Search space and order bound** (:class:`dtwin.kinematics.OrderBounds`, here ``LineBounds``)::

    f = m fm + n fc                        0 <= m <= 4, |n| <= 8          (carrier family)
    f = m fm + j g + n fc                  g in {fsr, fs/N, fp}, 1 <= |j| <= 3, |n| <= 2
    f = m fm + j fe                        1 <= |j| <= 6                  (motor family)

i.e. at most one secondary family per combination, faults with at most ±2 carrier sidebands.
The ring-fault frequency ``fr = N fc`` lies on the carrier grid and is not a separate family.
Combinations are ranked by parsimony (families used, then total order |m| + |n| + |j|, then
|error|); all combinations of the best rank are reported (ties, e.g. fsr − fc = fs/N).

**Tolerance.** A line's frequency is read by quadratic interpolation of the log amplitude around
its Hann peak (error well under 0.1 bin at 20 dB over the floor); a combination matches within
``tolerance_bins`` (default 0.25) bins. :func:`chance_match_probability` gives the probability
that a tone at a uniformly random frequency in (0, Nyquist) matches *some* combination — the
false-naming rate the report states next to each description.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np

from dtwin.kinematics import Kinematics, OrderBounds, combination_text
from dtwin.spectrum import noise_floor

__all__ = [
    "Description", "Kinematics", "LineBounds", "ResidualLine", "chance_match_probability",
    "describe", "estimate_speed", "interpolated_peak", "residual_lines",
]


#: The order bounds of the descriptions (module docstring): :class:`dtwin.kinematics.OrderBounds`.
LineBounds = OrderBounds


@dataclasses.dataclass(frozen=True)
class Description:
    """One kinematic combination: coefficients by symbol, its `frequency`, `error` (line minus
    combination, Hz), `order` and `families`, and `text` ("fm − 7fc")."""

    coefficients: tuple[tuple[str, int], ...]
    frequency: float
    error: float
    order: int
    families: int
    text: str

    def coefficient(self, symbol: str) -> int:
        return dict(self.coefficients).get(symbol, 0)


def _table(kin: Kinematics, bounds: LineBounds):
    """All combinations: (coefficient tuples, frequencies, orders, families)."""
    rows: list[tuple[tuple[tuple[str, int], ...], float]] = []
    fm, fc = kin.f_mesh, kin.f_carrier
    for m in range(bounds.mesh + 1):
        for n in range(-bounds.carrier, bounds.carrier + 1):
            rows.append(((("fm", m), ("fc", n)), m * fm + n * fc))
    for sym, g in kin.basis().items():
        if sym == "fe":
            for m, j in itertools.product(range(bounds.mesh + 1),
                                          [j for j in range(-bounds.motor, bounds.motor + 1) if j]):
                rows.append(((("fm", m), ("fe", j)), m * fm + j * g))
            continue
        for m, j, n in itertools.product(
            range(bounds.mesh + 1),
            [j for j in range(-bounds.fault, bounds.fault + 1) if j],
            range(-bounds.fault_carrier, bounds.fault_carrier + 1),
        ):
            rows.append(((("fm", m), (sym, j), ("fc", n)), m * fm + j * g + n * fc))
    coefs = [r[0] for r in rows]
    freq = np.array([r[1] for r in rows])
    order = np.array([sum(abs(c) for _, c in r) for r in coefs])
    fam = np.array([sum(c != 0 for _, c in r) for r in coefs])
    keep = (freq > 0) & (order > 0)
    idx = np.flatnonzero(keep)
    return [coefs[i] for i in idx], freq[idx], order[idx], fam[idx]


def describe(f: float, kin: Kinematics, tolerance: float, bounds: LineBounds = LineBounds()
             ) -> list[Description]:
    """Kinematic combinations within `tolerance` (Hz) of `f`, best first; only the best rank
    (families, order) is kept — ties all reported. Empty list: "no kinematic match"."""
    coefs, freq, order, fam = _table(kin, bounds)
    err = f - freq
    hit = np.flatnonzero(np.abs(err) <= tolerance)
    if hit.size == 0:
        return []
    hit = sorted(hit, key=lambda i: (fam[i], order[i], abs(err[i])))
    best = (fam[hit[0]], order[hit[0]])
    out = []
    seen = set()
    for i in hit:
        if (fam[i], order[i]) != best:
            break
        c = tuple((s, v) for s, v in coefs[i] if v != 0)
        if c in seen:
            continue
        seen.add(c)
        out.append(Description(c, float(freq[i]), float(err[i]), int(order[i]), int(fam[i]),
                               combination_text(c)))
    return out


def chance_match_probability(kin: Kinematics, tolerance: float, f_max: float,
                             bounds: LineBounds = LineBounds()) -> float:
    """Probability that a tone uniformly random in (0, `f_max`) Hz lies within `tolerance` Hz of
    some combination (measure of the union of the ±tolerance intervals over `f_max`)."""
    _, freq, _, _ = _table(kin, bounds)
    freq = np.sort(freq[freq < f_max + tolerance])
    lo = np.clip(freq - tolerance, 0.0, f_max)
    hi = np.clip(freq + tolerance, 0.0, f_max)
    total, cur_lo, cur_hi = 0.0, None, None
    for a, b in zip(lo, hi, strict=True):
        if cur_hi is None or a > cur_hi:
            if cur_hi is not None:
                total += cur_hi - cur_lo
            cur_lo, cur_hi = a, b
        else:
            cur_hi = max(cur_hi, b)
    if cur_hi is not None:
        total += cur_hi - cur_lo
    return float(total / f_max)


def interpolated_peak(freqs: np.ndarray, amp: np.ndarray, k: int) -> float:
    """Frequency (Hz) of the peak at bin `k` refined by a parabola through the log amplitudes
    of bins k−1, k, k+1 (Hann: error well below 0.1 bin for an isolated line)."""
    if k <= 0 or k >= len(amp) - 1:
        return float(freqs[k])
    a, b, c = np.log(np.maximum(amp[k - 1: k + 2], 1e-300))
    den = a - 2 * b + c
    d = 0.0 if den == 0 else 0.5 * (a - c) / den
    d = float(np.clip(d, -0.5, 0.5))
    return float(freqs[k] + d * (freqs[1] - freqs[0]))


def estimate_speed(freqs: np.ndarray, amp: np.ndarray, kin: Kinematics,
                   search: float | None = None, bounds: LineBounds = LineBounds()) -> float:
    """Sun speed (Hz) from the measured spectrum: the speed within ±`search` (relative; default
    ``1 / (2 Zr)``, the range in which the carrier grid is unambiguous — a speed ratio of
    ``1 + 1/Zr`` maps fm onto fm + fc — beyond it use a tachometer) of the nominal one whose
    carrier grid ``m fm + n fc`` (0 ≤ m ≤ 4, |n| ≤ 8, below 0.8 × the top
    frequency) collects the most line height over the noise floor (sum of positive dB at the
    grid's bins; step 0.05 bin at the highest line), refined by interpolating the strongest
    grid line around a mesh harmonic. Every gear line lies on this grid whatever the imperfections, so a weak mesh
    line does not mislead it."""
    if search is None:
        search = 0.5 / kin.z_ring
    amp = np.asarray(amp, dtype=np.float64)
    floor = noise_floor(amp, 31)
    height = np.maximum(20 * np.log10(np.maximum(amp, 1e-300) / floor), 0.0)
    df = float(freqs[1] - freqs[0])
    m, n = np.meshgrid(np.arange(bounds.mesh + 1), np.arange(-bounds.carrier, bounds.carrier + 1))
    m, n = m.ravel(), n.ravel()
    order = (m * kin.f_mesh + n * kin.f_carrier) / kin.f_sun  # line / f_sun
    keep = (order > 0) & (order * kin.f_sun * (1 + search) < 0.8 * freqs[-1])
    order = order[keep]
    step = 0.05 * df / (order.max() * kin.f_sun)
    ratios = np.arange(1 - search, 1 + search + step / 2, step)
    f_lines = ratios[:, None] * kin.f_sun * order[None, :]
    k = np.clip(np.rint(f_lines / df).astype(int), 0, len(amp) - 1)
    score = height[k].sum(axis=1)
    best = ratios[int(np.argmax(score))] * kin.f_sun
    # refine on the strongest grid line
    kk = np.clip(np.rint(best * order / df).astype(int), 1, len(amp) - 2)
    j = int(np.argmax(np.where(order * kin.f_sun > 0.5 * kin.f_mesh, amp[kk], -1.0)))
    f_line = interpolated_peak(freqs, amp, int(kk[j]))
    refined = f_line / order[j]
    return float(refined if abs(refined / best - 1) < df / (best * order[j]) else best)


@dataclasses.dataclass(frozen=True)
class ResidualLine:
    """A line present in one spectrum and not in the other.

    - `side`: ``"measured"`` (in the measurement, missing from the model) or ``"model"``;
    - `frequency` (Hz, interpolated), `bin`;
    - `excess_db`: level of the line over the *other* spectrum's level there, both floored at
      the local noise floor (dB);
    - `above_floor_db`: line over the local noise floor (dB);
    - `descriptions`: best kinematic combinations (ties), empty = "no kinematic match";
    - `chance`: probability of a chance match at this resolution and bound.
    """

    side: str
    frequency: float
    bin: int
    excess_db: float
    above_floor_db: float
    descriptions: tuple[Description, ...]
    chance: float

    @property
    def text(self) -> str:
        return " | ".join(d.text for d in self.descriptions) or "no kinematic match"

    @property
    def power_excess(self) -> float:
        """Excess as a power ratio minus one (weight for coverage)."""
        return 10.0 ** (self.excess_db / 10.0) - 1.0

    def to_dict(self) -> dict:
        return dict(side=self.side, frequency=self.frequency, excess_db=self.excess_db,
                    above_floor_db=self.above_floor_db, description=self.text,
                    chance_match_probability=self.chance)


def _peaks(amp, floor, thr_db):
    import scipy.signal

    idx, _ = scipy.signal.find_peaks(amp, height=floor * 10 ** (thr_db / 20.0))
    return idx


def residual_lines(
    freqs: np.ndarray,
    measured: np.ndarray,
    model: np.ndarray,
    kin: Kinematics,
    *,
    threshold_db: float = 12.0,
    excess_db: float = 6.0,
    tolerance_bins: float = 0.25,
    floor_bins: int = 31,
    bounds: LineBounds = LineBounds(),
    f_max: float | None = None,
) -> list[ResidualLine]:
    """Lines of `measured` missing from `model` and the reverse, over 0 … `f_max` (Nyquist).

    A line is a local maximum `threshold_db` above the noise floor (running median of the
    *measured* amplitude) whose level exceeds the other spectrum's (max over ±1 bin), both
    floored at the noise floor, by `excess_db`. Sorted by excess, largest first.

    **Arguments:** `freqs` (Hz), `measured`, `model` (amplitude spectra, same unit; the model
    already scaled by its gain), `kin`, thresholds (dB), `tolerance_bins` for descriptions.
    """
    freqs = np.asarray(freqs)
    measured = np.asarray(measured, dtype=np.float64)
    model = np.asarray(model, dtype=np.float64)
    floor = noise_floor(measured, floor_bins)
    df = float(freqs[1] - freqs[0])
    tol = tolerance_bins * df
    f_max = float(freqs[-1]) if f_max is None else float(f_max)
    chance = chance_match_probability(kin, tol, f_max, bounds)
    out = []
    for side, a, b in (("measured", measured, model), ("model", model, measured)):
        for k in _peaks(a, floor, threshold_db):
            if freqs[k] <= 0 or freqs[k] > f_max:
                continue
            other = float(np.max(b[max(k - 1, 0): k + 2]))
            ex = 20 * np.log10(max(a[k], floor[k]) / max(other, floor[k]))
            if ex < excess_db:
                continue
            f = interpolated_peak(freqs, a, int(k))
            out.append(ResidualLine(side, f, int(k), float(ex),
                                    float(20 * np.log10(a[k] / floor[k])),
                                    tuple(describe(f, kin, tol, bounds)), chance))
    out.sort(key=lambda r: -r.excess_db)
    return out


def sideband_rule_lines(kin: Kinematics, f_max: float, bounds: LineBounds = LineBounds()):
    """Frequencies ``m fm + n fc`` (1 ≤ m, |n| ≤ carrier bound) that the sideband rule forbids
    for an ideal gearbox: where planet-to-planet differences show (Hz)."""
    out = []
    for m in range(1, bounds.mesh + 1):
        for n in range(-bounds.carrier, bounds.carrier + 1):
            f = m * kin.f_mesh + n * kin.f_carrier
            if 0 < f < f_max and not kin.allowed_by_sideband_rule(m, n):
                out.append(f)
    return out


