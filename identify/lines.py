"""Residual line analysis: which spectral lines the measurement has and the model lacks (and the
reverse), each described by the kinematic combinations that explain it.

**Kinematic basis** (:class:`dtwin.model.kinematics.Kinematics`, Hz, speed taken from the data first with
:func:`dtwin.identify.operating_point.resolve_speed`): ``fm`` (mesh), ``fc`` (carrier), ``fsr`` (absolute sun rotation),
``fs/N`` (sun-fault repetition over the number of planets, = fsr − fc), ``fp`` (planet fault,
fm/Zp), ``fr`` (ring fault, fm N/Zr = N fc), ``fe`` (the motor's electrical frequency, pole pairs
× sun speed).

**Search space and order bound** (:class:`dtwin.model.kinematics.OrderBounds`, here ``LineBounds``)::

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

**Families** (:func:`find_combs`, :func:`find_modulation`): a fault's impulse comb
``k g + n fc`` (k up to what the band holds) and a modulation at a located frequency
(``f_x``, ``L ± j f_x``) are scored as wholes, with the chance that as many of the residual
lines fall on them at random (binomial tail, Bonferroni over the families tried): twenty lines
on one comb are strong evidence, not twenty chance matches. Members are labelled
"14fs/3 − fc (comb)"; mesh harmonics are searched up to Nyquist (:func:`band_bounds`) and
lines near Nyquist may be described as aliases ("alias of 5fm").
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np

from dtwin.model.kinematics import Kinematics, OrderBounds, combination_text
from dtwin.signal.spectrum import noise_floor

from .gap import ALIAS_ZONE

__all__ = [
    "Comb", "Description", "Kinematics", "LineBounds", "Modulation", "ResidualLine",
    "band_bounds", "chance_match_probability", "comb_label", "comb_lines", "describe",
    "find_combs", "find_modulation", "interpolated_peak", "label_combs",
    "modulation_lines", "refined_modulation_frequency", "residual_lines",
]


#: The order bounds of the descriptions (module docstring): :class:`dtwin.model.kinematics.OrderBounds`.
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


def _alias(f: float, kin: Kinematics, tolerance: float, f_nyquist: float
           ) -> tuple[Description, ...]:
    """Descriptions "alias of 5fm" of a line in the top fifth of the band (:data:`ALIAS_ZONE` of
    Nyquist; the gap leaves these frequencies unscored, :mod:`dtwin.identify.gap`) that is the mirror
    ``2 f_nyquist − f`` of a carrier-grid line above Nyquist (``m fm + n fc``, m ≥ 1): what a
    DAQ's anti-alias filter lets through in its transition band (the independent records show
    5 fm = 2501.5 Hz at 2498.5 Hz)."""
    if f < ALIAS_ZONE * f_nyquist:
        return ()
    fa = 2.0 * f_nyquist - f
    b = dataclasses.replace(LineBounds(), mesh=int(2 * f_nyquist // kin.f_mesh) + 1, fault=0,
                            motor=0)
    return tuple(dataclasses.replace(d, text=f"alias of {d.text}")
                 for d in describe(fa, kin, tolerance, b)
                 if d.coefficient("fm") > 0 and d.families <= 2 and d.frequency > f_nyquist)


def band_bounds(kin: Kinematics, f_max: float, bounds: LineBounds = LineBounds()) -> LineBounds:
    """`bounds` with the mesh harmonics raised to every harmonic below `f_max` (Hz): a line at
    5 fm below Nyquist is "5fm", not "no kinematic match"."""
    return dataclasses.replace(bounds, mesh=max(bounds.mesh, int(f_max // kin.f_mesh)))


def _union_measure(freq: np.ndarray, tolerance: float, f_max: float) -> float:
    """Measure (Hz) of the union of the intervals ``freq ± tolerance`` within (0, `f_max`)."""
    freq = np.sort(np.asarray(freq)[np.asarray(freq) < f_max + tolerance])
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
    return float(total)


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
    #: the label of the line as a member of a comb found in the record (:func:`find_combs`,
    #: "14fs/3 − fc"), "" when it belongs to none; used when no bounded combination matches
    comb: str = ""

    @property
    def text(self) -> str:
        if self.descriptions:
            return " | ".join(d.text for d in self.descriptions)
        return f"{self.comb} (comb)" if self.comb else "no kinematic match"

    @property
    def power_excess(self) -> float:
        """Excess as a power ratio minus one (weight for coverage)."""
        return 10.0 ** (self.excess_db / 10.0) - 1.0

    def to_dict(self) -> dict:
        return dict(side=self.side, frequency=self.frequency, excess_db=self.excess_db,
                    above_floor_db=self.above_floor_db, description=self.text,
                    chance_match_probability=self.chance, comb=self.comb)


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
    floored at the noise floor, by `excess_db`. Sorted by excess, largest first. Mesh
    harmonics are searched up to `f_max` (:func:`band_bounds`); combs are labelled by
    :func:`find_combs` (the loop of :mod:`dtwin.identify.discover` does it).

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
    bounds = band_bounds(kin, f_max, bounds)
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
            desc = tuple(describe(f, kin, tol, bounds)) or _alias(f, kin, tol, float(freqs[-1]))
            out.append(ResidualLine(side, f, int(k), float(ex),
                                    float(20 * np.log10(a[k] / floor[k])), desc, chance))
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




#: Carrier sidebands ``|n|`` around each tooth of a fault comb.
COMB_CARRIER = 2
#: A comb is reported when this many residual lines lie on it and the chance of as many
#: matches among the residual lines (binomial, Bonferroni over the combs tried) is below
#: :data:`COMB_CHANCE`.
COMB_MIN_MEMBERS = 3
COMB_CHANCE = 1e-3


@dataclasses.dataclass(frozen=True)
class Comb:
    """A family of lines ``k g + n fc`` (k = 1 … what the band holds, |n| ≤ `carrier`) found
    in the residual lines and scored as a whole (:func:`find_combs`).

    - `symbol` ("fs/3", "fp", "fsr", "fe", or a located frequency's name), `spacing` g (Hz),
      `carrier` (|n| bound);
    - `teeth`: comb lines in the band off the carrier grid; `tried`: residual lines off the
      carrier grid it was tested against; `members`: (frequency, k, n, label) of the lines on it;
    - `chance`: probability that a set of `tried` lines at uniformly random frequencies puts
      at least ``len(members)`` on the comb (binomial tail, times the number of combs tried).
    """

    symbol: str
    spacing: float
    carrier: int
    teeth: int
    tried: int
    members: tuple[tuple[float, int, int, str], ...]
    chance: float

    @property
    def text(self) -> str:
        return (f"comb k·{self.symbol} ± n fc (|n| ≤ {self.carrier}): {len(self.members)} of "
                f"{self.tried} residual lines on its {self.teeth} teeth, chance "
                f"{self.chance:.1e}")

    def to_dict(self) -> dict:
        return dict(symbol=self.symbol, spacing_hz=self.spacing, carrier=self.carrier,
                    teeth=self.teeth, tried=self.tried, chance_match_probability=self.chance,
                    members=[dict(frequency=f, k=k, n=n, label=lab)
                             for f, k, n, lab in self.members])


def comb_label(kin: Kinematics, symbol: str, g: float, k: int, n: int) -> str:
    """Label of the comb line ``k g + n fc``; when fm is a whole multiple Q of g (fm = Zs fs/N,
    fm = Zp fp) written around the nearest mesh harmonic, ``m fm + (k − m Q) g + n fc``."""
    q = kin.f_mesh / g
    if abs(q - round(q)) < 1e-6 * q and round(q) > 0:
        qi = int(round(q))
        m = int(np.floor(k / qi + 0.5))
        return combination_text((("fm", m), (symbol, k - m * qi), ("fc", n)))
    return combination_text(((symbol, k), ("fc", n)))


def comb_lines(kin: Kinematics, symbol: str, g: float, f_max: float,
               carrier: int = COMB_CARRIER) -> list[tuple[float, int, int, str]]:
    """The comb ``k g + n fc`` (k ≥ 1, |n| ≤ `carrier`) below `f_max`: (Hz, k, n, label)."""
    out = []
    for k in range(1, int((f_max + carrier * kin.f_carrier) // g) + 1):
        for n in range(-carrier, carrier + 1):
            f = k * g + n * kin.f_carrier
            if 0 < f < f_max:
                out.append((f, k, n, comb_label(kin, symbol, g, k, n)))
    return out


def _binomial_tail(m: int, n: int, p: float) -> float:
    """P(X ≥ m), X ~ Binomial(n, p)."""
    import scipy.stats

    return float(scipy.stats.binom.sf(m - 1, n, min(max(p, 0.0), 1.0)))


def find_combs(lines: list[ResidualLine], kin: Kinematics, tolerance: float, f_max: float,
               extra: dict[str, float] | None = None, carrier: int = COMB_CARRIER,
               max_chance: float = COMB_CHANCE, min_members: int = COMB_MIN_MEMBERS
               ) -> list[Comb]:
    """Combs in the measured residual lines, scored jointly rather than line by line.

    For each spacing g of the basis (``fs/N``, ``fp``, ``fsr``, ``fe``, ``fr = N fc``; `extra`:
    located frequencies, e.g. ``{"fx": 2.1}``) the comb ``k g + n fc`` up to `f_max` is
    compared with the residual lines that lie off the carrier grid ``m fm + n fc`` (|n| ≤ 8,
    every mesh harmonic of the band: those lines are described already, and every comb whose
    spacing divides fm would collect them). With ``p`` the share of the band within
    `tolerance` of a tooth and L the lines tried, M members have chance
    ``K · P(Binomial(L, p) ≥ M)`` (K combs tried, Bonferroni). The comb of smallest chance is
    taken first and its members leave the pool (greedy), so one family is not counted twice.

    **Returns:** the combs with at least `min_members` members and chance ≤ `max_chance`.
    """
    fm, fc = kin.f_mesh, kin.f_carrier
    grid = np.array([m * fm + n * fc for m in range(int(f_max // fm) + 2)
                     for n in range(-8, 9) if m * fm + n * fc > 0])
    meas = [r for r in lines if r.side == "measured"
            and np.min(np.abs(grid - r.frequency)) > tolerance]
    basis = {s: g for s, g in kin.basis().items()}
    basis[f"{kin.n_planets}fc"] = kin.n_planets * fc
    basis.update(extra or {})
    combs: dict[str, tuple] = {}
    for sym, g in basis.items():
        if g is None or not g > 2 * tolerance:
            continue
        c = 0 if sym in ("fe",) else carrier
        teeth = [t for t in comb_lines(kin, sym, g, f_max, c)
                 if np.min(np.abs(grid - t[0])) > tolerance]
        if teeth:
            combs[sym] = (g, c, teeth, np.array([t[0] for t in teeth]))
    n_tried = max(len(combs), 1)
    found: list[Comb] = []
    pool = list(meas)
    while pool and combs:
        best = None
        for sym, (g, c, teeth, tf) in combs.items():
            p = _union_measure(tf, tolerance, f_max) / f_max
            mem = []
            for r in pool:
                i = int(np.argmin(np.abs(tf - r.frequency)))
                if abs(tf[i] - r.frequency) <= tolerance:
                    mem.append((r, teeth[i]))
            if len(mem) < min_members:
                continue
            ch = min(1.0, n_tried * _binomial_tail(len(mem), len(pool), p))
            if best is None or ch < best[0]:
                best = (ch, sym, g, c, teeth, mem)
        if best is None or best[0] > max_chance:
            break
        ch, sym, g, c, teeth, mem = best
        found.append(Comb(sym, g, c, len(teeth), len(pool),
                          tuple((r.frequency, t[1], t[2], t[3]) for r, t in mem), ch))
        used = {id(r) for r, _ in mem}
        pool = [r for r in pool if id(r) not in used]
        del combs[sym]
    return found


def label_combs(lines: list[ResidualLine], combs: list[Comb]) -> list[ResidualLine]:
    """`lines` with each comb member's `comb` label (and the comb's chance as its `chance`)."""
    lab = {}
    for cb in combs:
        for f, _, _, text in cb.members:
            lab[f] = (text, cb.chance)
    out = []
    for r in lines:
        if r.side == "measured" and r.frequency in lab:
            text, ch = lab[r.frequency]
            r = dataclasses.replace(r, comb=text, chance=r.chance if r.descriptions else ch)
        out.append(r)
    return out


@dataclasses.dataclass(frozen=True)
class Modulation:
    """A modulation at a located frequency `f_x` (Hz) that is no gearbox frequency: the line
    `f_x` and sidebands ``L ± j f_x`` (j = 1, 2) of the lines an ideal gearbox has (L =
    ``m fm + n fc`` allowed by the sideband rule, |n| ≤ 8). `members`: (frequency, label) of
    the residual lines on the family; `chance` as for :class:`Comb` (Bonferroni over the
    frequencies tried); `off`: the gearbox combinations that described the f_x line and that
    the family's frequency rules out (:func:`find_modulation`), empty when none did."""

    f_x: float
    teeth: int
    tried: int
    members: tuple[tuple[float, str], ...]
    chance: float
    off: tuple[str, ...] = ()

    @property
    def text(self) -> str:
        off = f"; off {', '.join(self.off)} by its family's frequency" if self.off else ""
        return (f"modulation at {self.f_x:.2f} Hz: {len(self.members)} of {self.tried} residual "
                f"lines on its {self.teeth} lines, chance {self.chance:.1e}{off}")

    def to_dict(self) -> dict:
        return dict(f_x_hz=self.f_x, teeth=self.teeth, tried=self.tried,
                    chance_match_probability=self.chance, off_combinations=list(self.off),
                    members=[dict(frequency=f, label=lab) for f, lab in self.members])


def _modulation_family(kin: Kinematics, f_x: float, f_max: float, orders: int = 2,
                       carrier: int = 8) -> list[tuple[float, float, int, str]]:
    """The lines of :func:`modulation_lines` as (Hz, the line L they stand beside (0 for the
    harmonics of f_x), j, label)."""
    out = [(j * f_x, 0.0, j, combination_text((("fx", j),))) for j in range(1, orders + 1)
           if j * f_x < f_max]
    for m in range(int(f_max // kin.f_mesh) + 1):
        for n in range(-carrier, carrier + 1):
            base = m * kin.f_mesh + n * kin.f_carrier
            if base <= 0 or (kin.z_ring is not None and not kin.allowed_by_sideband_rule(m, n)):
                continue
            for j in range(-orders, orders + 1):
                f = base + j * f_x
                if j and 0 < f < f_max:
                    out.append((f, base, j, combination_text((("fm", m), ("fc", n), ("fx", j)))))
    return out


def modulation_lines(kin: Kinematics, f_x: float, f_max: float, orders: int = 2,
                     carrier: int = 8) -> list[tuple[float, str]]:
    """Lines of a modulation at `f_x`: ``j f_x`` and ``m fm + n fc ± j f_x`` (lines allowed by
    the sideband rule, every mesh harmonic of the band, |n| ≤ `carrier`, 1 ≤ j ≤ `orders`):
    (Hz, label)."""
    return [(f, lab) for f, _, _, lab in _modulation_family(kin, f_x, f_max, orders, carrier)]


#: A located frequency departs from a gearbox combination that describes its line when the
#: family's refined frequency lies off it by more than this many standard errors
#: (:func:`refined_modulation_frequency`) ...
OFF_COMBINATION_SE = 5.0
#: ... and by more than this share of the line-matching tolerance (0.05 bin at the default
#: quarter-bin tolerance): the interpolated peaks of a family's members agree to a few
#: hundredths of a bin (median over the members).
OFF_COMBINATION_TOL = 0.2


def _on_family(fam, lines: list[ResidualLine], tolerance: float):
    """The measured lines of `lines` within `tolerance` of a line of the family `fam`
    (:func:`_modulation_family`), each with the family line nearest it: ``[(line, entry)]``."""
    ff = np.array([f for f, *_ in fam])
    out = []
    for r in lines:
        i = int(np.argmin(np.abs(ff - r.frequency)))
        if r.side == "measured" and abs(ff[i] - r.frequency) <= tolerance:
            out.append((r, fam[i]))
    return out


def _readings(f_x: float, on_family) -> tuple[float, float, int]:
    """Median, its standard error and count of the readings ``(f − L) / j`` of the lines on a
    family (:func:`_on_family`); `f_x` with an infinite error when there is none."""
    if not on_family:
        return float(f_x), float("inf"), 0
    e = np.asarray([(r.frequency - base) / j for r, (_, base, j, _) in on_family])
    med = float(np.median(e))
    se = 1.4826 * float(np.median(np.abs(e - med))) / math.sqrt(e.size)
    return med, se, int(e.size)


#: At most this many gatherings of a family about its own reading
#: (:func:`refined_modulation_frequency`); each one that changes the members moves the reading
#: toward the members' centre, and a family settles in two or three.
READING_PASSES = 10


def refined_modulation_frequency(kin: Kinematics, f_x: float, lines: list[ResidualLine],
                                 tolerance: float, f_max: float) -> tuple[float, float, int]:
    """The modulation frequency read from the whole family of a trial at `f_x` (Hz): each
    measured line within `tolerance` of a line ``L + j f_x`` of the family
    (:func:`modulation_lines`; L = 0 for the harmonics ``j f_x``) reads ``(f − L) / j``; the
    median of the readings and its standard error (1.4826 × their median absolute deviation
    / √n) (:func:`_readings`).

    The family is gathered again about that reading until its members no longer change (at
    most :data:`READING_PASSES` gatherings): the reading is the family's own, not the trial's.
    Each line's interpolated frequency scatters by its noise (about 0.1 bin for a line 12 to
    20 dB over the floor), so a window of ± `tolerance` put about a first guess that one line
    read a quarter bin off keeps the lines whose scatter lies toward that guess and drops those
    on the other side: the median of what is kept is pulled toward the guess by a good part of
    the scatter, and their spread, and so the standard error, is understated. A family gathered
    about its own median keeps its lines on both sides.

    **Returns:** ``(f_x, standard error, readings)`` in Hz, Hz and a count; `f_x` with an
    infinite error when no line lies on its family."""
    f, se, n = _readings(f_x, [])
    seen: set[frozenset[int]] = set()
    for _ in range(READING_PASSES):
        on = _on_family(_modulation_family(kin, f, f_max), lines, tolerance)
        members = frozenset(id(r) for r, _ in on)
        if not on or members in seen:
            break
        seen.add(members)
        f, se, n = _readings(f, on)
    return f, se, n


def _combination_frequencies(r: ResidualLine, kin: Kinematics, combs) -> list[float]:
    """The frequencies (Hz) of the gearbox combinations that describe line `r`: its bounded
    descriptions and the tooth of the comb that holds it."""
    out = [d.frequency for d in r.descriptions]
    for cb in combs or ():
        for f, k, n, _ in cb.members:
            if f == r.frequency:
                out.append(k * cb.spacing + n * kin.f_carrier)
    return out


def find_modulation(lines: list[ResidualLine], kin: Kinematics, tolerance: float, f_max: float,
                    max_chance: float = COMB_CHANCE, min_members: int = COMB_MIN_MEMBERS,
                    combs: list[Comb] | None = None) -> Modulation | None:
    """Locate a modulation frequency from the record: each measured residual line below
    ``fm / 2`` that no bounded combination describes and no comb holds is a trial `f_x`; its
    family (:func:`modulation_lines`) is scored against the residual lines as a comb is
    (:func:`find_combs`; the trial line itself is not counted). The most significant family
    with at least `min_members` lines besides the trial line and chance ≤ `max_chance` and the
    most members wins, the lowest frequency on a tie (a sideband ``3fc − f_x`` of the family
    of f_x has f_x in its own family as ``3fc − (3fc − f_x)``: the modulation is the slower).

    A line that a combination describes, or that a comb of `combs` holds, is a trial too when
    its family says it lies off that combination: the family's refined frequency
    (:func:`refined_modulation_frequency`) departs from every describing combination by more
    than :data:`OFF_COMBINATION_SE` standard errors and :data:`OFF_COMBINATION_TOL` of
    `tolerance` (0.05 bin at the default quarter-bin tolerance). A bounded combination of
    several gearbox frequencies falls within a quarter bin of many a frequency (a load
    fluctuation at 3.30 Hz on a box whose ``fp − 2fc`` is 3.33 Hz, read from 4 s), while twenty
    sidebands read its frequency to a few thousandths of a bin. Such a modulation says so
    (:attr:`Modulation.off`).

    When no line below ``fm / 2`` locates a modulation, its sidebands may
    (:func:`_from_sidebands`): a record need not hold the line ``f_x`` itself.

    A trial line at an order of ``fc`` or of a basis frequency, of any order
    (:func:`_at_gearbox_order`), is none: the gearbox makes lines there. A line that a
    combination describes lies off that order as it lies off the combination
    (:func:`_at_named`).

    **Returns:** the :class:`Modulation`, or ``None``."""
    meas = [r for r in lines if r.side == "measured"]
    trials = []  # (line, its family, the combinations it lies off)
    for r in meas:
        if not 2 * tolerance < r.frequency < 0.5 * kin.f_mesh:
            continue
        if not r.descriptions and not r.comb:
            if not _at_gearbox_order(r.frequency, kin, tolerance):
                trials.append((r, _modulation_family(kin, r.frequency, f_max), ()))
            continue
        named = _combination_frequencies(r, kin, combs)
        if not named or (r.comb and combs is None):
            continue
        fam = _modulation_family(kin, r.frequency, f_max)
        f_ref, se, n_est = refined_modulation_frequency(kin, r.frequency, meas, tolerance, f_max)
        named += [f for f in [_at_gearbox_order(f_ref, kin, float("inf"))] if f]
        if n_est > min_members and not _at_named(f_ref, se, named, kin, meas, tolerance, f_max):
            trials.append((r, fam, tuple(sorted({d.text for d in r.descriptions} | (
                {r.comb} if r.comb else set())))))
    trials.sort(key=lambda x: x[0].frequency)
    best = None
    for t, fam, off in trials:
        scored = _scored_family(t, fam, meas, tolerance, f_max, min_members, len(trials))
        if scored is None:
            continue
        pool, mem, ch = scored
        if ch <= max_chance and (best is None or len(mem) + 1 > len(best.members)):
            best = Modulation(t.frequency, len(fam), len(pool),
                              ((t.frequency, "fx"),) + tuple(mem), ch, off)
    if best is None:
        best = _from_sidebands(meas, kin, tolerance, f_max, max_chance, min_members,
                               len(trials))
    return best


def _scored_family(t: ResidualLine, fam, meas: list[ResidualLine], tolerance: float,
                   f_max: float, min_members: int, n_tried: int):
    """A trial's family scored against the measured lines other than its own line `t`:
    ``(pool, members, chance)`` with the chance Bonferroni over `n_tried` frequencies, or None
    when fewer than `min_members` lines lie on it (:func:`find_modulation`)."""
    pool = [r for r in meas if r is not t]
    mem = [(r.frequency, entry[3]) for r, entry in _on_family(fam, pool, tolerance)]
    if len(mem) < min_members:
        return None
    p = _union_measure(np.array([f for f, *_ in fam]), tolerance, f_max) / f_max
    return pool, mem, min(1.0, n_tried * _binomial_tail(len(mem), len(pool), p))


def _at_gearbox_order(f: float, kin: Kinematics, tolerance: float) -> float | None:
    """The order of ``fc`` or of a basis frequency (``fsr``, ``fs/N``, ``fp``, ``fe``), of any
    order, nearest `f` (Hz) when it lies within `tolerance` of it, else None: a line there is
    the gearbox's own (a ring fault's ``15 fc`` on a 17/26/70 box lies beyond the bounded
    combinations), no frequency of a modulation."""
    best = None
    for g in (kin.f_carrier, *kin.basis().values()):
        k = round(f / g) if g else 0
        if k >= 1 and abs(f - k * g) <= tolerance and (
                best is None or abs(f - k * g) < abs(f - best)):
            best = k * g
    return best


def _at_named(f_x: float, se: float, named: list[float], kin: Kinematics,
              lines: list[ResidualLine], tolerance: float, f_max: float) -> bool:
    """Whether a family read at `f_x` (Hz) with standard error `se` (Hz)
    (:func:`refined_modulation_frequency`) is the family of one of the gearbox frequencies
    `named` (Hz: combinations, orders of ``fc`` or of a basis frequency): `f_x` lies within
    :data:`OFF_COMBINATION_SE` × `se` or :data:`OFF_COMBINATION_TOL` × `tolerance` of one, or
    the family gathered once about that gearbox frequency itself reads it, within as many of
    its own standard errors or the same share of `tolerance`.

    The second reading tests the gearbox frequency where the lines are gathered about it, not
    about a reading off it. Where the family's lines coincide (``f_x = 3 fc`` on a box whose
    lines lie 3 fc apart: ``L + f_x`` is ``L' − f_x``), each measured line takes the family
    line whose reading lies nearer the frequency it is gathered about, and a family gathered
    about a reading δ off the gearbox frequency reads near δ again, however far its lines
    scatter (its noise, about 0.1 bin at 12 to 20 dB over the floor); gathered about the
    gearbox frequency, the same lines read it. A modulation off a gearbox frequency holds its
    reading either way: its lines read ``(f − L) / j`` wherever they are gathered from."""
    thr = max(OFF_COMBINATION_SE * se, OFF_COMBINATION_TOL * tolerance)
    for g in named:
        if abs(f_x - g) <= thr:
            return True
        f_g, se_g, n_g = _readings(g, _on_family(_modulation_family(kin, g, f_max), lines,
                                                 tolerance))
        if n_g and abs(f_g - g) <= max(OFF_COMBINATION_SE * se_g,
                                       OFF_COMBINATION_TOL * tolerance):
            return True
    return False


def _sideband_trials(meas: list[ResidualLine], kin: Kinematics, tolerance: float,
                     f_max: float, carrier: int = 8) -> list[tuple[ResidualLine, float]]:
    """Trial modulation frequencies read from sidebands (:func:`_from_sidebands`): each
    measured line above ``fm / 2`` that no combination describes and no comb holds, and its
    distance to the gearbox lines ``L = m fm + n fc`` on either side of it (sideband rule,
    |n| ≤ `carrier`); distances within `tolerance` of one tried already are not tried again.
    **Returns:** ``[(line, f_x)]`` in order of frequency."""
    fm, fc = kin.f_mesh, kin.f_carrier
    bases = np.array(sorted(
        m * fm + n * fc for m in range(1, int(f_max // fm) + 2)
        for n in range(-carrier, carrier + 1)
        if m * fm + n * fc > 0 and (kin.z_ring is None or kin.allowed_by_sideband_rule(m, n))))
    out: list[tuple[ResidualLine, float]] = []
    for r in sorted(meas, key=lambda r: r.frequency):
        if r.descriptions or r.comb or r.frequency < 0.5 * fm or bases.size == 0:
            continue
        i = int(np.searchsorted(bases, r.frequency))
        for b in bases[max(i - 1, 0): i + 1]:
            f_x = abs(r.frequency - float(b))
            if (2 * tolerance < f_x < 0.5 * fm
                    and all(abs(f_x - g) > tolerance for _, g in out)):
                out.append((r, f_x))
    return out


def _from_sidebands(meas: list[ResidualLine], kin: Kinematics, tolerance: float, f_max: float,
                    max_chance: float, min_members: int, tried: int) -> Modulation | None:
    """A modulation located from its sidebands alone, when no line below ``fm / 2`` locates
    one (:func:`find_modulation`): a sensor that does not pass the modulation's own frequency
    — an accelerometer's high-pass, a housing whose path carries no low frequencies — still
    shows the sidebands ``L ± j f_x`` of the gearbox lines. Each trial of
    :func:`_sideband_trials` (one line and its distance to a gearbox line) is scored as a trial
    line is: its family's lines among the other measured lines, the chance Bonferroni over
    every frequency tried here and by the caller (`tried`). Each trial's frequency is first
    read from its whole family, gathered about its own reading
    (:func:`refined_modulation_frequency`), not from the one distance it was found by;
    ``f_x`` and ``N fc − f_x`` put their first sidebands on the same lines, and on a tie the
    slower is taken. A trial that a gearbox combination describes, or that lies at an order
    of ``fc`` or of a basis frequency (``fsr``, ``fs/N``, ``fp``, ``fe``) of any order, as
    its family reads it (:func:`_at_named`), is no trial:
    the lines of a tooth fault that breaks the planets' symmetry lie ``k fc`` from the lines
    the sideband rule allows (a ring profile fault on a 17/26/70 box: 15 ``fc``)."""
    trials = _sideband_trials(meas, kin, tolerance, f_max)
    n_tried = tried + len(trials)
    best = None
    refined = []
    bounds = band_bounds(kin, f_max)
    for t, f_x in trials:  # one distance reads f_x to a tolerance; its family, far closer
        f_ref, se, n = refined_modulation_frequency(kin, f_x, meas, tolerance, f_max)
        f_x = f_ref if n >= min_members else f_x
        # a gearbox frequency is no located modulation: the lines its family holds are the
        # gearbox's own (a ring or planet fault's sidebands beyond the bounded combinations)
        named = [d.frequency for d in describe(f_x, kin, tolerance, bounds)] + [
            f for f in [_at_gearbox_order(f_x, kin, float("inf"))] if f]
        if _at_named(f_x, se, named, kin, meas, tolerance, f_max):
            continue
        refined.append((t, f_x))
    for t, f_x in sorted(refined, key=lambda x: x[1]):  # the slowest on a tie
        fam = _modulation_family(kin, f_x, f_max)
        own = _on_family(fam, [t], tolerance)
        if not own:
            continue
        scored = _scored_family(t, fam, meas, tolerance, f_max, min_members, n_tried)
        if scored is None:
            continue
        pool, mem, ch = scored
        if ch <= max_chance and (best is None or len(mem) + 1 > len(best.members)):
            best = Modulation(f_x, len(fam), len(pool), ((t.frequency, own[0][1][3]),)
                              + tuple(mem), ch)
    return best
