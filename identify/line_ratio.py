"""A tooth fault's depth from the power of its sidebands over the healthy mesh lines, per band.

A local tooth fault modulates one mesh once per pass of the faulty tooth and so adds lines
beside every mesh harmonic. Within one band around a mesh harmonic, ``(m ± 1/2) f_m``, the
power the fault adds on its lines over the power of the gearbox's own (healthy) lines is a
ratio in which the sensor's gain and its transfer path cancel (both kinds of line pass the
same path at nearly the same frequency), and the window of the passing planets to the extent
that the twin's healthy lines already stand where the record's do. What is left is the fault's
own dynamics — how much sideband power a given loss of mesh stiffness makes — over the healthy
mesh excitation: the fault's sidebands are the stiffness it removes times the static mesh
deflection, the healthy lines the mesh's excitation (the stiffness waveform's under the load,
and any transmission error). That excitation does **not** cancel, and a healthy record at one
load cannot split it from the transfer path: on the independent records of the paper's
gearbox the same sun fault read 0.19 with the calibrated transmission error and 0.33 with the
stiffness waveform's excitation alone, truth 0.09 (:mod:`dtwin.identify.severity` reads both
and reports the hull). :func:`line_ratio` reads the
record's ratio in each mesh band, simulates the twin (a :class:`~dtwin.identify.problem.Problem`
with the fault's severity free, as ``dtwin severity`` builds it) at a grid of severities, and
reads the severity at which the twin's ratio meets the record's; the first mesh band's reading
is refined on the twin itself: simulated at the reading, the bracket about the record's ratio
narrowed by the secant in log severity until the twin's ratio stands within
:data:`REFINE_DB` of the record's. Every simulation is a batch through one compiled function
of θ and the fault's loss shape (:func:`twin_powers`): ``dtwin severity`` simulates the healthy
twin and the grid of every loss shape it reads in one batch.

Why not the level of every point of the spectrum (:mod:`dtwin.identify.residuals`)? A
least-squares fit of log levels weighs every sideband alone, and the twin's sidebands are
spread over the lines differently from a record's (load sharing, the window, the transfer
path): on records from independent simulators such a fit read some sun and planet faults
7–50× small where this ratio read every one 0.97–2.1× (docs/identification.md, "The depth of a
tooth fault: the sideband ratio").

**The lines** (DFT bins of a Hann-windowed spectrum of the whole record). The fault's lines are
the bins where the twin with the fault (at :data:`REFERENCE_SEVERITY`) stands
:data:`FAULT_LINE_DB` over the healthy twin, away from the healthy twin's own lines (below
:data:`HEALTHY_LINE_DB` under the band's strongest healthy bin), and where the record stands
:data:`SIGNIFICANT_DB` over its noise floor (a 31-bin running median): the lines the twin
predicts and the record shows; at least :data:`MIN_FAULT_LINES` of them make a reading. The
healthy lines are the other bins where the record stands :data:`SIGNIFICANT_DB` over its
floor. The fault's power is then summed over every bin its twin **reaches** — where the twin's
fault adds power within :data:`REACH_DB` of its strongest bin, away from the healthy lines —
not over the fault's lines alone: how a fault's power is shared among its sidebands rests on
what a healthy record cannot fix (for a planet fault, the harmonics of the passing planet's
window that cancel over the planets of a healthy gearbox), and on records from independent
simulators the twin put about half its planet-fault power on bins where the record showed no
line, and ``dtwin severity`` read those faults 1.09–1.10× from the sum over the reach where it
read them 1.3× from the lines alone (docs/identification.md, "The depth of a tooth fault").
The record's excess in a bin is its power less the noise's mean power there (the floor's
median over ``ln 2``: a bin of Gaussian noise has an exponentially distributed power; not held
at 0, so that noise adds as much below as above) or, with a healthy record of the same machine
at the same speed (`healthy`), less that record's power in the same bin — then lines the
healthy gearbox already makes there (which the twin may lack) are not counted as the fault's,
and the fault's lines must also stand :data:`HEALTHY_EXCESS_DB` over the healthy record's. The
twin's excess is its power with the fault less its power without.

**The interval** of a band's reading holds two terms, added in quadrature in dB and carried
through the twin's slope (its ratio against the log severity): the noise's (the variance of a
bin's power with a line of power ``L`` in noise of mean power ``μ`` is ``2 L μ + μ²``, summed
over the bins of each set, with the error of the noise's mean subtracted (:func:`_floor_var`),
and carried through the ratio's logarithm) and the delete-one-group
jackknife of the record's ratio less the twin's over :data:`SLICES` slices either side of the
harmonic (how far the reading rests on one part of the band: a path or a dynamics the twin
lacks shows as slices that disagree). A reading past the grid's upper end is held there and
flagged; one below its lower end is extrapolated along the twin's own slope there (the
fault's sidebands grow with the square of a small loss). Where no band holds
:data:`MIN_FAULT_LINES` fault lines over the noise, the reading is 0 with an interval up to the
detection limit: the smallest severity whose lines, the twin scaled to the record by the
healthy lines, would stand :data:`SIGNIFICANT_DB` over the record's floor.

Frequencies in Hz, power in the record's units squared (a ratio: the unit cancels).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from dtwin.errors import RecordError
from dtwin.signal.spectrum import noise_floor

from .operating_point import gear_orders
from .residuals import _amplitude

__all__ = ["BandReading", "LineRatio", "SEVERITY_GRID", "line_ratio", "mesh_bands",
           "twin_powers", "with_shape"]

#: Severities (the fault type's own measure, 1) the twin is simulated at.
SEVERITY_GRID = (0.02, 0.06, 0.18, 0.45, 0.9)
#: Severity of the twin's fault that marks its lines (a mid-range depth of the grid).
REFERENCE_SEVERITY = 0.18
#: A fault line: the faulty twin stands this many dB over the healthy twin in the bin.
FAULT_LINE_DB = 10.0
#: ... and the healthy twin stands this many dB below its band's strongest bin there.
HEALTHY_LINE_DB = 40.0
#: A line of the record: it stands this many dB over the record's noise floor (false
#: alarms: a bin of noise passes 12 dB over its median with probability ``2^(-15.8)``).
SIGNIFICANT_DB = 12.0
#: With a healthy record: a fault line also stands this many dB over the healthy record's bin
#: (the power ratio of two noise bins passes 6 dB one time in five).
HEALTHY_EXCESS_DB = 6.0
#: Fewest distinct fault lines (runs of bins more than a Hann main lobe apart) a band must
#: show for a reading: a tooth fault adds a family of sidebands, and a line or two where the
#: twin predicts them may be a line of the healthy gearbox that the twin lacks.
MIN_FAULT_LINES = 3
#: Bins of the running median of the noise floor.
FLOOR_BINS = 31
#: The bins the twin's fault reaches: its excess at :data:`REFERENCE_SEVERITY` stands within
#: this many dB of its strongest bin in the band (they hold all but about 0.5 % of its power).
REACH_DB = 30.0
#: The refinement stops when the twin's ratio stands this close to the record's (dB; 0.6 % in
#: severity where the sidebands grow with its square) ...
REFINE_DB = 0.05
#: ... or after this many simulations.
REFINE_STEPS = 3


def power_spectrum(x) -> np.ndarray:
    """Hann-windowed power spectrum of one signal, its mean removed (numpy, one-sided bins):
    the square of the fit's amplitude spectrum (:mod:`dtwin.identify.residuals`)."""
    x = np.asarray(x, dtype=np.float64)
    return _amplitude(x, x.size) ** 2


def mesh_bands(f_mesh: float, sample_rate: float, passband: float = 0.45
               ) -> list[tuple[str, float, float]]:
    """The bands ``(m − 1/2, m + 1/2) f_mesh`` that lie below ``passband × sample_rate``:
    ``[("mesh1", lo, hi), …]`` (Hz)."""
    out, m = [], 1
    while (m + 0.5) * f_mesh <= passband * sample_rate:
        out.append((f"mesh{m}", (m - 0.5) * f_mesh, (m + 0.5) * f_mesh))
        m += 1
    return out


@dataclasses.dataclass(frozen=True)
class BandReading:
    """One band's reading: `name`, `lo_hz`, `hi_hz`; `fault_bins` (the fault's bins where the
    record stands over its noise), `healthy_bins`, `reach_bins` (every bin the twin's fault
    reaches: the sums run over these) (counts);
    `record_db` (the record's ratio, dB; nan where a set is empty) and `record_se_db` (its
    noise standard error); `twin_db` (the twin's ratio at each severity of the grid);
    `severity` (where the twin's ratio meets the record's; nan when it cannot be read; 0 below
    detection) and its 95 % `interval` (noise and jackknife; ``(0, detection limit)`` below
    detection); `edge`: ``"above the grid"`` (held at the grid's top), ``"below the grid"``
    (extrapolated), ``"below detection"`` (no fault line stands over the noise) or empty;
    `jackknife_db`: the delete-one-slice jackknife's standard error of the record's ratio less
    the twin's (dB; nan with fewer than three slices holding fault lines)."""

    name: str
    lo_hz: float
    hi_hz: float
    fault_bins: int
    healthy_bins: int
    record_db: float
    record_se_db: float
    twin_db: tuple[float, ...]
    severity: float = float("nan")
    interval: tuple[float, float] = (float("nan"), float("nan"))
    edge: str = ""
    jackknife_db: float = float("nan")
    reach_bins: int = 0

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class LineRatio:
    """:func:`line_ratio`'s result: `grid` (severities simulated), `bands` (one
    :class:`BandReading` each), `severity` and its 95 % noise `interval` from the first mesh
    band (refined on the twin where `refined`), `healthy_reference`: whether a healthy record
    was subtracted."""

    grid: tuple[float, ...]
    bands: tuple[BandReading, ...]
    severity: float
    interval: tuple[float, float]
    refined: bool = False
    healthy_reference: bool = False

    def to_dict(self) -> dict:
        return {"grid": list(self.grid), "bands": [b.to_dict() for b in self.bands],
                "severity": self.severity, "interval_95": list(self.interval),
                "refined": self.refined, "healthy_reference": self.healthy_reference}


def with_shape(problem, part: int, ramp, spread):
    """`problem` with the loss shape of its twin's fault ``parts[part]`` set to `ramp` and
    `spread` (mesh cycles; floats or traced scalars, stored as float64 arrays)."""
    return eqx.tree_at(lambda q: (q.twin.parts[part].fault.ramp,
                                  q.twin.parts[part].fault.spread), problem,
                       (jnp.asarray(ramp, jnp.float64), jnp.asarray(spread, jnp.float64)))


@eqx.filter_jit
def _signals(thetas, ramps, spreads, problem, part):
    """The twin's first-record sensor signals at each θ (rows of `thetas`), the loss shape of
    the fault of ``problem.twin.parts[part]`` set to each `ramps`, `spreads` (mesh cycles; no
    shape is set where `part` is None), one after the other (``jax.lax.map``). The shape is data
    of the compiled function: every shape of one batch size shares one compilation, and what
    does not change with θ is computed once per call rather than once per simulation (a batch
    of four simulates in about two thirds the time per member of single calls on a CPU)."""
    def one(args):
        theta, ramp, spread = args
        p = problem if part is None else with_shape(problem, part, ramp, spread)
        sigs, _ = p.signals(theta)
        return sigs[0]
    return jax.lax.map(one, (thetas, ramps, spreads))


def twin_powers(problem, index: int, severities: Sequence[float],
                shapes: Sequence[tuple[float, float]] | None = None,
                part: int | None = None) -> np.ndarray:
    """The twin's power spectra (:func:`power_spectrum`, one row per severity) with the free
    parameter `index` of `problem` at each of `severities`, the others at their starting values,
    simulated in one batch; with `shapes` (one ``(ramp, spread)`` per severity, mesh cycles) and
    `part` (the index of the fault's part in ``problem.twin.parts``) each with its own loss
    shape."""
    thetas = _thetas(problem, index, severities)
    n = thetas.shape[0]
    if shapes is None or part is None:
        shapes, part = [(0.0, 0.0)] * n, None
    ramps = jnp.asarray([float(r) for r, _ in shapes], jnp.float64)
    spreads = jnp.asarray([float(v) for _, v in shapes], jnp.float64)
    sigs = np.asarray(_signals(thetas, ramps, spreads, problem, part))
    return np.stack([power_spectrum(x) for x in sigs])


def _thetas(problem, index: int, severities: Sequence[float]) -> jnp.ndarray:
    """θ of `problem` at each severity of its free parameter `index`, the others at their
    starting values."""
    x0 = [float(v) for v in np.asarray(problem.pset.x0)]
    rows = []
    for s in severities:
        v = list(x0)
        v[index] = float(s)
        rows.append(problem.pset.theta(v))
    return jnp.asarray(np.stack(rows))


#: Slices of a band either side of its mesh harmonic (the jackknife's groups; paired across
#: the harmonic with ``paired=True``).
SLICES = 5


def _groups(freqs, centre: float, width: float, fault, paired: bool
            ) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """The fault lines of a band in slices of ``width / (2 SLICES)`` either side of `centre`:
    ``(mask, None)`` per slice holding fault lines or, `paired`, ``(lower, upper)`` per pair
    of mirrored slices both holding fault lines."""
    d = freqs - centre
    w = 0.5 * width / SLICES
    out = []
    for k in range(SLICES):
        lo_m = fault & (d < -k * w) & (d >= -(k + 1) * w)
        hi_m = fault & (d >= k * w) & (d < (k + 1) * w)
        if paired:
            if lo_m.any() and hi_m.any():
                out.append((lo_m, hi_m))
        else:
            out.extend((m, None) for m in (lo_m, hi_m) if m.any())
    return out


def _group_excess(e: np.ndarray, groups) -> np.ndarray:
    """The fault's power per group (:func:`_groups`): the sum of `e` over a slice, or over a
    pair the geometric mean of the two sides' sums (each held at 0 or above), twice (a
    transfer path's slope across the band, in dB, cancels)."""
    return np.array([float(e[a].sum()) if b is None
                     else 2.0 * math.sqrt(max(float(e[a].sum()), 0.0)
                                          * max(float(e[b].sum()), 0.0))
                     for a, b in groups])


def _lines(mask: np.ndarray) -> int:
    """Distinct lines among the bins of `mask`: runs whose bins lie more than two bins (a Hann
    main lobe's half-width) apart."""
    idx = np.flatnonzero(mask)
    return 0 if idx.size == 0 else 1 + int(np.sum(np.diff(idx) > 2))


def _noise_var(line: np.ndarray, mu: np.ndarray) -> float:
    """Variance of a sum of bin powers, each a line of power `line` in noise of mean `mu`."""
    return float(np.sum(2.0 * np.clip(line, 0.0, None) * mu + mu * mu))


def _floor_var(mu: np.ndarray) -> float:
    """Variance of the sum of the noise's mean power `mu` over a set of bins, each estimated
    from the running median of :data:`FLOOR_BINS` bins: the median of ``n`` exponential powers
    has a standard deviation of about ``μ/√n``, so ``μ̂ = median/ln 2`` one of ``μ/(ln 2 √n)``,
    and it is shared by the ``n`` bins of one window; summed over the set, about
    ``Σ μ² / ln² 2`` (an upper bound where the set is sparser than the window)."""
    return float(np.sum(mu * mu)) / math.log(2.0) ** 2


def _read(record_db: float, twin_db: np.ndarray, grid: np.ndarray) -> tuple[float, str]:
    """The severity at which the twin's ratios `twin_db` (on `grid`) meet `record_db`:
    interpolation in log severity on the monotone part, held at the top, extrapolated along the
    lowest segment's slope below."""
    lg = np.log(grid)
    if not (np.isfinite(record_db) and np.all(np.isfinite(twin_db))):
        return float("nan"), ""
    if record_db >= twin_db[-1]:
        return float(grid[-1]), "above the grid"
    if record_db < twin_db[0]:
        slope = (twin_db[1] - twin_db[0]) / (lg[1] - lg[0])
        if slope <= 0:
            return float("nan"), ""
        return float(np.exp(lg[0] + (record_db - twin_db[0]) / slope)), "below the grid"
    mono = np.maximum.accumulate(twin_db)  # the ratio rises with the depth; flats held
    j = int(np.searchsorted(mono, record_db, side="right"))
    j = min(max(j, 1), grid.size - 1)
    d = mono[j] - mono[j - 1]
    u = 0.5 if d <= 0 else (record_db - mono[j - 1]) / d
    return float(np.exp(lg[j - 1] + u * (lg[j] - lg[j - 1]))), ""


def _slope_at(sev: float, twin_db: np.ndarray, grid: np.ndarray) -> float:
    """d(ratio, dB)/d(log severity) of the twin near `sev` (its grid segment; > 0)."""
    lg = np.log(grid)
    j = int(np.clip(np.searchsorted(lg, math.log(max(sev, 1e-12))), 1, grid.size - 1))
    return float(max((twin_db[j] - twin_db[j - 1]) / (lg[j] - lg[j - 1]), 1e-6))


def _band(name, lo, hi, freqs, p_rec, floor, mu, sig_rec, p_ref, p0, p_grid, p_mark, grid,
          paired):
    """One band's :class:`BandReading` and its bin sets (module docstring)."""
    s = (freqs >= lo) & (freqs < hi)
    quiet0 = p0 < 10 ** (-HEALTHY_LINE_DB / 10) * (p0[s].max() if s.any() else 0.0)
    candidate = s & quiet0 & (p_mark > 10 ** (FAULT_LINE_DB / 10) * p0)
    fault = candidate & sig_rec
    if p_ref is not None:
        fault &= p_rec > 10 ** (HEALTHY_EXCESS_DB / 10) * p_ref
    if _lines(fault) < MIN_FAULT_LINES:  # a line or two is no fault's family
        fault = np.zeros_like(fault)
    healthy_l = s & sig_rec & ~fault
    # the sums run over every bin the twin's fault reaches, where the record shows its lines
    ex_mark = np.where(candidate, np.clip(p_mark - p0, 0.0, None), 0.0)
    reach = candidate & (ex_mark >= 10 ** (-REACH_DB / 10) * ex_mark.max()) if fault.any() \
        else fault
    groups = _groups(freqs, 0.5 * (lo + hi), hi - lo, reach, paired)
    base = mu if p_ref is None else p_ref
    e_rec = p_rec - base  # unbiased: a bin of noise alone adds as much below as above
    r_k = _group_excess(e_rec, groups)
    num, den = float(r_k.sum()), float(p_rec[healthy_l].sum())
    ex_tw = np.clip(p_grid - p0, 0.0, None)
    t_k = np.stack([_group_excess(e, groups) for e in ex_tw]) if groups else \
        np.zeros((len(grid), 0))
    t_den = np.array([float(p[healthy_l].sum()) for p in p_grid])
    with np.errstate(divide="ignore", invalid="ignore"):
        t_db = 10 * np.log10(t_k.sum(axis=1) / t_den)
    t_db = np.where(np.isfinite(t_db), t_db, np.nan)
    if not (num > 0 and den > 0):
        # no fault line stands over the noise: below detection (module docstring)
        limit = _detection_limit(candidate, healthy_l, p_rec, floor, p0, p_grid, grid)
        return (BandReading(name, float(lo), float(hi), 0, int(healthy_l.sum()), float("nan"),
                            float("nan"), tuple(float(v) for v in t_db), 0.0, (0.0, limit),
                            "below detection"), fault, healthy_l, groups)
    rec_db = 10 * math.log10(num / den)
    var_base = mu if p_ref is None else 2 * mu  # the healthy record's noise too
    # the noise in the bins summed, and the error of the floor subtracted from them
    var_num = _noise_var(e_rec[reach], var_base[reach])
    if p_ref is None:
        var_num += _floor_var(mu[reach])
    rel2 = var_num / num**2 + _noise_var(p_rec[healthy_l], mu[healthy_l]) / den**2
    se_db = 10 / math.log(10) * math.sqrt(rel2)
    sev, edge = _read(rec_db, t_db, grid)
    iv = (float("nan"), float("nan"))
    jk_db = float("nan")
    if np.isfinite(sev):
        jk_db = _jackknife_db(r_k, den, t_k, t_den, grid, sev)
        se = math.hypot(se_db, jk_db) if np.isfinite(jk_db) else se_db
        half = 1.96 * se / _slope_at(sev, t_db, grid)
        iv = (sev * math.exp(-half), float(grid[-1]) if edge == "above the grid"
              else min(sev * math.exp(half), 1.0))
    return (BandReading(name, float(lo), float(hi), int(fault.sum()), int(healthy_l.sum()),
                        rec_db, se_db, tuple(float(v) for v in t_db), sev, iv, edge, jk_db,
                        int(reach.sum())),
            reach, healthy_l, groups)


def _jackknife_db(r_k, den, t_k, t_den, grid, sev) -> float:
    """Delete-one-group jackknife standard error (dB) of the record's ratio less the twin's at
    `sev` (the twin's groups interpolated in log severity): how far the reading rests on one
    part of the band; nan with fewer than three groups."""
    k = r_k.size
    if k < 3:
        return float("nan")
    lg = np.log(grid)
    with np.errstate(divide="ignore"):
        tl = np.log(np.maximum(t_k, 1e-300))
    t_at = np.exp(np.array([np.interp(math.log(sev), lg, tl[:, j]) for j in range(k)]))
    d_at = float(np.exp(np.interp(math.log(sev), lg, np.log(t_den))))
    loo = []
    for j in range(k):
        r, t = r_k.sum() - r_k[j], t_at.sum() - t_at[j]
        if r <= 0 or t <= 0:
            continue
        loo.append(10 * math.log10(r / den) - 10 * math.log10(t / d_at))
    if len(loo) < 3:
        return float("nan")
    loo = np.asarray(loo)
    return float(math.sqrt((loo.size - 1) / loo.size * np.sum((loo - loo.mean()) ** 2)))


def _detection_limit(candidate, healthy_l, p_rec, floor, p0, p_grid, grid) -> float:
    """The smallest severity whose fault lines would stand :data:`SIGNIFICANT_DB` over the
    record's floor in some bin of `candidate`, the twin scaled to the record by their healthy
    lines (interpolated in log severity; the grid's top when none would)."""
    den = float(p_rec[healthy_l].sum())
    if not candidate.any() or den <= 0:
        return float(grid[-1])
    over = []
    for p in p_grid:
        d = float(p[healthy_l].sum())
        e = np.clip(p - p0, 0.0, None)[candidate] * (den / d if d > 0 else 0.0)
        over.append(float(np.max(e / floor[candidate])) if e.size else 0.0)
    over_db = 10 * np.log10(np.maximum(np.asarray(over), 1e-300))
    target = SIGNIFICANT_DB
    if over_db[-1] < target:
        return float(grid[-1])
    if over_db[0] >= target:
        return float(grid[0])
    j = int(np.argmax(over_db >= target))
    u = (target - over_db[j - 1]) / max(over_db[j] - over_db[j - 1], 1e-12)
    lg = np.log(grid)
    return float(np.exp(lg[j - 1] + u * (lg[j] - lg[j - 1])))


def line_ratio(problem, record, index: int = 0, *, channel: int | str = 0, healthy=None,
               grid: Sequence[float] = SEVERITY_GRID, refine: bool = True,
               passband: float = 0.45, paired: bool = False, twin=None) -> LineRatio:
    """Read a tooth fault's severity from the power of its sidebands over the healthy lines
    (module docstring).

    **Arguments:** `problem` (a :class:`~dtwin.identify.problem.Problem` of one steady record
    whose free parameter `index` is the fault's severity; the other free parameters are held
    at their starting values); `record` (the same record); `channel`; `healthy`: a healthy
    record of the same machine at the same speed and rate, at least as long (a
    :class:`~dtwin.errors.RecordError` otherwise), or None (module docstring, "The lines"); `grid`: severities the twin is simulated at (ascending); `refine`: refine the
    first band's reading on the twin (module docstring); `passband`: the highest band's upper
    edge as a fraction of the sampling rate; `paired`: read mirrored slices of a band together
    (:func:`_group_excess`); `twin`: ``(healthy, at_grid)``, the twin's power spectra
    (:func:`twin_powers`) without the fault and at each severity of `grid` where they are already
    simulated (None: simulated here). **Returns:** :class:`LineRatio`.
    """
    obs = problem.observations[0]
    n, fs = int(obs.n_samples), float(obs.sample_rate)
    grid = np.asarray(sorted(float(g) for g in grid))
    x = np.asarray(record.channel(channel), dtype=np.float64)[:n]
    p_rec = power_spectrum(x)
    floor = noise_floor(np.sqrt(p_rec), FLOOR_BINS) ** 2  # median power of a noise bin
    mu = floor / math.log(2.0)
    p_ref = None
    if healthy is not None:
        h = np.asarray(healthy.channel(channel), dtype=np.float64)
        if h.size < n or float(healthy.sample_rate) != fs:
            raise RecordError(
                f"the healthy record ({h.size} samples at {float(healthy.sample_rate):g} Hz) "
                f"must have the faulty record's rate ({fs:g} Hz) and at least its length "
                f"({n} samples): give a healthy record of the same acquisition, or none")
        p_ref = power_spectrum(h[:n])
    freqs = np.fft.rfftfreq(n, 1.0 / fs)
    f_mesh = float(obs.speed[0]) * gear_orders(problem.twin)["mesh"]

    # the healthy twin, the grid, and the marking depth where the grid does not hold it
    extra = [] if np.any(np.isclose(grid, REFERENCE_SEVERITY)) else [REFERENCE_SEVERITY]
    if twin is None:
        p_tw = twin_powers(problem, index, [0.0, *grid, *extra])
        p0, p_grid = p_tw[0], p_tw[1: 1 + grid.size]
        p_mark = p_tw[-1] if extra else None
    else:
        p0, p_grid = (np.asarray(a, dtype=np.float64) for a in twin)
        if p_grid.shape[0] != grid.size:
            raise ValueError(f"twin holds {p_grid.shape[0]} spectra at the fault for a grid of "
                             f"{grid.size} severities: give one per severity of grid, in order")
        p_mark = twin_powers(problem, index, extra)[0] if extra else None
    if p_mark is None:
        p_mark = p_grid[int(np.argmin(abs(grid - REFERENCE_SEVERITY)))]

    bands, sets = [], []
    sig_rec = p_rec > 10 ** (SIGNIFICANT_DB / 10) * floor
    for name, lo, hi in mesh_bands(f_mesh, fs, passband):
        reading, fault, healthy_l, groups = _band(
            name, lo, hi, freqs, p_rec, floor, mu, sig_rec, p_ref, p0, p_grid, p_mark, grid,
            paired)
        bands.append(reading)
        sets.append((fault, healthy_l, groups))

    if not bands:
        return LineRatio(tuple(grid), (), float("nan"), (float("nan"), float("nan")))
    first = bands[0]
    sev, iv, refined = first.severity, first.interval, False
    if refine and np.isfinite(sev) and sev > 0 and not first.edge:
        sev_r = _refine(problem, index, sev, first.record_db, sets[0], p0, grid,
                        np.asarray(first.twin_db))
        if sev_r is not None:
            f = sev_r / sev
            sev, iv, refined = sev_r, (iv[0] * f, iv[1] * f), True
    return LineRatio(tuple(float(g) for g in grid), tuple(bands), float(sev),
                     (float(iv[0]), float(iv[1])), refined, p_ref is not None)


def _twin_db(p: np.ndarray, p0: np.ndarray, healthy_l: np.ndarray, groups) -> float:
    """The twin's ratio (dB) in a band from its power spectrum `p`, as :func:`_band` reads it:
    the excess over the healthy twin `p0` on the fault's groups over the healthy lines."""
    e = float(_group_excess(np.clip(p - p0, 0.0, None), groups).sum())
    d = float(p[healthy_l].sum())
    return 10 * math.log10(e / d) if e > 0 and d > 0 else float("nan")


def _refine(problem, index: int, sev0: float, target_db: float, sets, p0, grid, twin_db
            ) -> float | None:
    """The severity where the twin's first-band ratio meets `target_db`: the twin simulated at
    the reading `sev0`, then at the secant in log severity across the tightest bracket of the
    record's ratio among the points simulated so far (grid and refinement), until it stands
    within :data:`REFINE_DB` (at most :data:`REFINE_STEPS` simulations). None where no bracket
    holds or the result moves more than a factor e from `sev0`."""
    _, healthy_l, groups = sets
    pts = [(math.log(g), float(d)) for g, d in zip(grid, twin_db, strict=True)
           if np.isfinite(d)]
    s = sev0
    for _ in range(REFINE_STEPS):
        d = _twin_db(twin_powers(problem, index, [s])[0], p0, healthy_l, groups)
        if not np.isfinite(d):
            return None
        if abs(d - target_db) <= REFINE_DB:
            break
        pts.append((math.log(s), d))
        below = [q for q in pts if q[1] < target_db]
        above = [q for q in pts if q[1] > target_db]
        if not below or not above:
            return None
        a, b = max(below), min(above)  # the tightest bracket in log severity
        if b[1] == a[1]:
            return None
        s = math.exp(a[0] + (target_db - a[1]) * (b[0] - a[0]) / (b[1] - a[1]))
    return s if s > 0 and abs(math.log(s / sev0)) < 1.0 else None
