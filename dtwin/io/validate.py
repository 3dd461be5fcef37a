"""Checks that a vibration record can support a gearbox diagnosis.

:func:`check_record` lists every :class:`Problem` found; :func:`validate_record` raises one
:class:`~dtwin.errors.RecordError` listing them all. Each message says what to change.

The checks and their thresholds:

- **non-finite samples** (NaN/inf): the first bad sample index and the count;
- **absurd values**: samples beyond :data:`ABSURD_LIMIT` (1e20) in any unit, or more than
  :data:`ABSURD_DYNAMIC_RANGE` (1e12, 240 dB) times the channel's median absolute value (a
  corrupt file, a wrong data type or unit: no recorder spans that range);
- **empty** (no samples) or **constant** channels (peak-to-peak exactly 0: a dead sensor or
  a disconnected cable);
- **clipping**: runs of at least `clip_run` consecutive samples sitting exactly at the
  channel's maximum or minimum, covering at least a fraction `clip_fraction` of the record
  (an amplifier or ADC in saturation holds its rail value; a smooth signal does not repeat
  its extreme value);
- **sampling rate too low** for the mesh frequency: ``sample_rate ≥ 2.5 f_mesh``
  (:data:`MIN_RATE_PER_MESH`: Nyquist factor 2 plus the anti-aliasing filter's transition band,
  the usual 2.56 rule of analysers, rounded), and, with `f_carrier` known, the highest
  sideband ``f_mesh + n_sidebands·f_carrier`` below Nyquist, ``sample_rate > 2(f_mesh +
  n_sidebands f_carrier)``;
- **record too short** to resolve the carrier sidebands: ``duration ≥ k / f_carrier`` with
  ``k =`` :data:`MIN_CARRIER_PERIODS` ``= 8``: calibration and discovery score each half of a
  record (:data:`SCORED_PARTS`), and in a half sidebands spaced ``f_carrier`` apart are then
  :data:`MIN_SIDEBAND_BINS` ``= 4`` frequency bins (``2/T``) apart, clear of a Hann window's
  main lobe (4 bins wide);
- **time column** disagreeing with the rate used (relative difference above
  :data:`RATE_TOLERANCE`), or non-uniform (a step deviating more than
  :data:`TIME_JITTER_TOLERANCE` from the mean step);
- **unknown channels** among those an analysis asks for;
- **tachometer** of another length than the signals or holding NaN/inf.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from ..errors import RecordError
from .record import Record

#: Minimum sampling rate per mesh frequency (Nyquist 2 × anti-alias margin 1.25).
MIN_RATE_PER_MESH = 2.5
#: Bins between neighbouring carrier sidebands needed to resolve them: a Hann window's main
#: lobe is 4 bins wide.
MIN_SIDEBAND_BINS = 4
#: Parts of a record scored separately by calibration and discovery (held-out halves).
SCORED_PARTS = 2
#: Minimum record length in carrier periods to resolve the carrier sidebands in each scored
#: part (see module doc): ``SCORED_PARTS × MIN_SIDEBAND_BINS``.
MIN_CARRIER_PERIODS = float(SCORED_PARTS * MIN_SIDEBAND_BINS)
#: Relative disagreement tolerated between a given rate and the file's time column.
RATE_TOLERANCE = 1e-3
#: Relative deviation of one time step from the mean step tolerated in a time column.
TIME_JITTER_TOLERANCE = 1e-2
#: A sample more than this many times the channel's median absolute value is absurd: 240 dB,
#: far beyond the dynamic range of any recorder (24-bit ADCs: about 145 dB).
ABSURD_DYNAMIC_RANGE = 1e12
#: A sample beyond this magnitude is absurd in any unit (no vibration, sound, voltage or force
#: measurement in SI comes near; squares of such values overflow float64 sums at 1e154).
ABSURD_LIMIT = 1e20


@dataclasses.dataclass(frozen=True)
class Problem:
    """One defect of a record.

    **Fields:** `kind` (``nan``, ``absurd``, ``empty``, ``constant``, ``clipping``, ``sample_rate``,
    ``too_short``, ``time_column``, ``unknown_channel``, ``tacho``; ``speed``: `dtwin record
    info`'s speed the record's gear lines contradict); `message` (what is wrong
    and what to change); `channel` (name, or None for the whole record); `sample` (first
    sample index concerned, or None); `value` (a number characterising it: count, fraction,
    needed rate in Hz or needed duration in s).
    """

    kind: str
    message: str
    channel: str | None = None
    sample: int | None = None
    value: float | None = None

    def __str__(self) -> str:
        return self.message


def _absurd_samples(x: np.ndarray) -> tuple[int, int, float, str] | None:
    """Samples no measurement can hold (module docstring, "absurd values"): beyond
    :data:`ABSURD_LIMIT` in any unit, or more than :data:`ABSURD_DYNAMIC_RANGE` times the
    channel's median absolute value. **Returns:** ``(count, first index, bound, which bound)``
    or None."""
    a = np.abs(x)
    med = float(np.median(a))
    bound, why = ABSURD_LIMIT, f"{ABSURD_LIMIT:.0e} in any unit"
    if med > 0 and ABSURD_DYNAMIC_RANGE * med < bound:
        bound = ABSURD_DYNAMIC_RANGE * med
        why = (f"{ABSURD_DYNAMIC_RANGE:.0e} × the channel's median absolute value "
               f"{med:.3g}")
    bad = a > bound
    if not np.any(bad):
        return None
    return int(bad.sum()), int(np.flatnonzero(bad)[0]), bound, why


def _clip_runs(x: np.ndarray, level: float, min_run: int) -> tuple[int, int | None]:
    """Samples in runs of ≥ `min_run` consecutive samples equal to `level`, and the first index."""
    at = np.concatenate(([False], x == level, [False]))
    edges = np.flatnonzero(np.diff(at.astype(np.int8)))
    starts, ends = edges[::2], edges[1::2]
    lengths = ends - starts
    long = lengths >= min_run
    if not np.any(long):
        return 0, None
    return int(lengths[long].sum()), int(starts[long][0])


def check_record(
    record: Record,
    *,
    f_mesh: float | None = None,
    f_carrier: float | None = None,
    n_sidebands: int = 5,
    channels: Sequence[str | int] | None = None,
    min_carrier_periods: float = MIN_CARRIER_PERIODS,
    clip_run: int = 3,
    clip_fraction: float = 1e-4,
) -> list[Problem]:
    """List the problems of a record (empty list: fit for analysis).

    **Arguments:**

    - `record`: the record.
    - `f_mesh`: gear mesh frequency (Hz), for the sampling-rate check.
    - `f_carrier`: carrier rotation frequency (Hz), for the duration and sideband checks.
    - `n_sidebands`: sideband orders ``f_mesh ± n f_carrier`` the analysis uses (the highest
      must lie below Nyquist).
    - `channels`: channels an analysis will use (names/indices); unknown ones are problems.
    - `min_carrier_periods`: ``k`` of ``duration ≥ k / f_carrier``.
    - `clip_run`: samples at the rail in a row that count as clipping.
    - `clip_fraction`: fraction of samples in such runs above which a channel is clipped.

    **Returns:** a list of :class:`Problem`.
    """
    problems: list[Problem] = []
    fs = float(record.sample_rate)
    n = record.n_samples
    if channels is not None:
        for c in channels:
            ok = (isinstance(c, (int, np.integer)) and -len(record.channels) <= int(c) <
                  len(record.channels)) or (isinstance(c, str) and (c in record.channels or c in
                                                                    record.groups))
            if not ok:
                problems.append(Problem(
                    "unknown_channel",
                    f"unknown channel {c!r}; the record has {list(record.channels)}"
                    + (f" and groups {sorted(record.groups)}" if record.groups else "")
                    + ": pick one of these",
                    channel=str(c)))
    if len(record.channels) == 0:
        problems.append(Problem("empty", "the record has no signal channels; select at least "
                                "one channel (the tacho alone cannot be analysed)"))
    if n == 0:
        problems.append(Problem("empty", "the record holds no samples: the file is empty or "
                                "was cut; record again or pick another file", value=0.0))
    for i, name in enumerate(record.channels if n > 0 else ()):
        x = record.data[i]
        bad = ~np.isfinite(x)
        if np.any(bad):
            first = int(np.flatnonzero(bad)[0])
            problems.append(Problem(
                "nan",
                f"channel {name!r} has {int(bad.sum())} NaN/inf sample(s), the first at sample "
                f"{first} (t = {first / fs:.6g} s); cut the record before it or repair the "
                "channel (interpolating over a few samples is acceptable, over many is not)",
                channel=name, sample=first, value=float(bad.sum())))
            continue
        absurd = _absurd_samples(x)
        if absurd is not None:
            count, first, bound, why = absurd
            problems.append(Problem(
                "absurd",
                f"channel {name!r} holds {count} absurd sample(s), the first "
                f"{f'{x[first]:.4g} {record.units[i]}'.strip()} at sample {first} (t = {first / fs:.6g} s): beyond {why} "
                f"({bound:.3g}); no sensor measures that: a corrupt file, a wrong data type or "
                "a wrong unit/sensitivity; repair the file or cut the record before it",
                channel=name, sample=first, value=float(x[first])))
            continue
        span = float(np.ptp(x))
        if n > 1 and span == 0.0:
            problems.append(Problem(
                "constant",
                f"channel {name!r} is constant ({x[0]:g} {record.units[i]}) over all {n} "
                "samples: a dead sensor, a disconnected cable or a wrong channel; check the "
                "wiring or drop the channel", channel=name, value=float(x[0])))
            continue
        hi_n, hi_at = _clip_runs(x, float(x.max()), clip_run)
        lo_n, lo_at = _clip_runs(x, float(x.min()), clip_run)
        frac = (hi_n + lo_n) / n
        if hi_n + lo_n > 0 and frac >= clip_fraction:
            first = min(a for a in (hi_at, lo_at) if a is not None)
            problems.append(Problem(
                "clipping",
                f"channel {name!r} is clipped: {hi_n + lo_n} samples ({100 * frac:.3g} %) sit "
                f"at its limits {x.min():g} / {x.max():g} {record.units[i]} in runs of "
                f"≥ {clip_run}, the first at sample {first}; lower the amplifier gain or raise "
                "the input range and record again", channel=name, sample=first, value=frac))
    if f_mesh is not None:
        need = MIN_RATE_PER_MESH * float(f_mesh)
        why = f"{MIN_RATE_PER_MESH} × f_mesh = {need:g} Hz"
        if f_carrier is not None and n_sidebands > 0:
            top = float(f_mesh) + n_sidebands * float(f_carrier)
            if 2.0 * top > need:
                need = 2.0 * top
                why = (f"2 × (f_mesh + {n_sidebands} f_carrier) = {need:g} Hz, to keep the "
                       f"{n_sidebands}th sideband at {top:g} Hz below Nyquist")
        if fs < need:
            problems.append(Problem(
                "sample_rate",
                f"sampling rate {fs:g} Hz is too low for the mesh frequency {float(f_mesh):g} Hz:"
                f" need at least {why}; record at ≥ {math.ceil(need):d} Hz",
                value=need))
    if f_carrier is not None and n > 0:
        need_t = float(min_carrier_periods) / float(f_carrier)
        if record.duration < need_t:
            problems.append(Problem(
                "too_short",
                f"the record lasts {record.duration:.4g} s, too short to resolve the carrier "
                f"sidebands ({float(f_carrier):g} Hz apart): need {min_carrier_periods:g} carrier "
                f"periods = {need_t:.4g} s; record at least {need_t:.4g} s "
                f"({math.ceil(need_t * fs):d} samples at {fs:g} Hz)",
                value=need_t))
    tinfo = record.metadata.get("time_column")
    if isinstance(tinfo, dict) and "rate" in tinfo:
        t_rate = float(tinfo["rate"])
        if abs(t_rate - fs) > RATE_TOLERANCE * fs:
            problems.append(Problem(
                "time_column",
                f"the time column {tinfo.get('name', '')!r} implies {t_rate:.6g} Hz but the "
                f"sampling rate used is {fs:.6g} Hz; drop sample_rate= to use the time column, "
                "or fix the rate you gave", value=t_rate))
        jitter = float(tinfo.get("nonuniformity", 0.0))
        if jitter > TIME_JITTER_TOLERANCE:
            problems.append(Problem(
                "time_column",
                f"the time column {tinfo.get('name', '')!r} is not uniformly sampled (a step "
                f"deviates by {100 * jitter:.3g} % from the mean step); resample the record to "
                "a constant rate before analysis", value=jitter))
    if record.tacho is not None:
        tacho = np.asarray(record.tacho)
        if tacho.shape[-1] != n:
            problems.append(Problem(
                "tacho", f"the tacho has {tacho.shape[-1]} samples, the signals {n}; record "
                "them together at one rate", value=float(tacho.shape[-1])))
        elif not np.all(np.isfinite(tacho)):
            first = int(np.flatnonzero(~np.isfinite(tacho))[0])
            problems.append(Problem(
                "tacho", f"the tacho holds NaN/inf from sample {first}; repair or drop it",
                sample=first))
    return problems


def validate_record(record: Record, **kwargs) -> Record:
    """Raise :class:`~dtwin.errors.RecordError` listing every problem of :func:`check_record`
    (same keyword arguments); return the record unchanged when it has none.

    The error carries the list as ``problems``.
    """
    problems = check_record(record, **kwargs)
    if problems:
        src = record.metadata.get("source")
        head = f"record {src} is not usable" if src else "record is not usable"
        err = RecordError(head + ":\n  " + "\n  ".join(p.message for p in problems))
        err.problems = problems  # type: ignore[attr-defined]
        raise err
    return record


#: Problems no analysis can use: the record is refused whatever the command.
UNUSABLE = ("empty", "nan", "absurd", "constant", "time_column", "unknown_channel", "truncated")


def usable_record(
    record: Record,
    *,
    channels: Sequence[str | int] | None = None,
    f_mesh: float | None = None,
    f_carrier: float | None = None,
    fit: bool = False,
    fit_min_carrier_periods: float = 2.0,
) -> list[Problem]:
    """The one check of a record before an analysis (every command that reads one calls it).

    Refuses (:class:`~dtwin.errors.RecordError` listing them) what no analysis can use:
    :data:`UNUSABLE` problems of the channels used (`channels`, default all) or of the whole
    record. Returns the problems where the analysis degrades (clipping, a rate too low for the
    mesh, a record shorter than :data:`MIN_CARRIER_PERIODS` carrier periods, a bad tacho), for
    the caller to show as warnings; with `fit` (parameter fits), those are refused too, except
    a record shorter than :data:`MIN_CARRIER_PERIODS` carrier periods that still holds
    `fit_min_carrier_periods` (2: the carrier sidebands two Hann bins apart, resolved; the fits'
    own limit, ``dtwin.identify.residuals.MIN_SIDEBAND_BINS``): warned about, not refused.
    """
    problems = check_record(record, f_mesh=f_mesh, f_carrier=f_carrier, channels=channels)
    used = None
    if channels is not None:
        used = set()
        for c in channels:
            try:
                used.add(record.channels[record.index(c)])
            except Exception:
                pass
    mine = [p for p in problems if p.channel is None or used is None or p.channel in used
            or p.kind == "unknown_channel"]

    def fit_can_use(p: Problem) -> bool:
        return (p.kind == "too_short" and f_carrier is not None
                and record.duration >= fit_min_carrier_periods / float(f_carrier))

    refuse = [p for p in mine if p.kind in UNUSABLE or (fit and not fit_can_use(p))]

    if refuse:
        src = record.metadata.get("source")
        head = f"record {src} cannot be used" if src else "the record cannot be used"
        if fit and not any(p.kind in UNUSABLE for p in refuse):
            head += " for a fit"
        # one problem: one line (the CLI's `error:` line); several: one line each
        sep = ": " if len(refuse) == 1 else ":\n  "
        err = RecordError(head + sep + "\n  ".join(p.message for p in refuse))
        err.problems = refuse  # type: ignore[attr-defined]
        raise err
    return [p for p in mine if p not in refuse]

