"""Per-machine trends of a fleet: severity and mesh-parameter trajectories over time, with
intervals, and a flag when a trend crosses a threshold.

From the per-record results of :mod:`dtwin.identify.fleet` (:func:`dtwin.identify.fleet.load_results`),
:func:`machine_trends` collects, per machine, every fitted parameter against time (the records'
timestamps; records without one are placed one day apart in record order and say so).

**Trend.** A straight line ``x(t) = a + b t`` (t in days since the machine's first record) by
weighted least squares, weights ``1/σ_i²`` with ``σ_i`` = half the 95 % interval / 1.96
(equal weights when no interval is known); the slope's standard error ``se_b`` is scaled by
``max(1, sqrt(χ²/(n − 2)))`` so scatter beyond the intervals widens it.

**Flag** (:class:`TrendFlag`) of a parameter with a threshold ``(value, "above"|"below")``:

- ``crossed``: a record's value is beyond the threshold, whatever the trend and however few the
  records. When the last record is beyond it (the machine is past it now), the time reported
  is when the trend line crossed, when there is a trend beyond the threshold too, else the
  first record of the last run of records beyond it; when only earlier records are (the last
  back within: a repair, or a misfit of those records), the first record beyond it;
- ``approaching``: not crossed, the slope points toward the threshold and differs from zero by
  more than 2 se_b, and the line reaches the threshold within `horizon_days` of the last record
  (the predicted date is reported);
- ``too_few``: not crossed, and fewer than 3 records (or all at one time): no trend can be
  judged, which is not the same as "ok";
- ``ok`` otherwise.

Default thresholds (:data:`DEFAULT_THRESHOLDS`): fault severities ``0.4`` above (the paper's
missing-tooth scale: 1 = a whole tooth's stiffness lost); mesh stiffnesses 20 % below the
machine's first value (``("-20%", "below")`` is relative to the first record).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from dtwin.errors import SettingsError

__all__ = ["DEFAULT_THRESHOLDS", "MIN_TREND_RECORDS", "MachineTrend", "ParameterTrend", "TrendFlag", "fit_trend",
           "flag_trend", "machine_trends", "parse_threshold"]

_Z95 = 1.959963984540054
#: Records a trend needs (a line through two points has no scatter to judge it by).
MIN_TREND_RECORDS = 3
#: Parameter → (threshold, direction). A string ``"-20%"`` is relative to the first record.
DEFAULT_THRESHOLDS: dict[str, tuple[float | str, str]] = {
    "sun_fault": (0.4, "above"),
    "planet_fault": (0.4, "above"),
    "ring_fault": (0.4, "above"),
    "k_sun_planet": ("-20%", "below"),
    "k_ring_planet": ("-20%", "below"),
}


def parse_threshold(text: str) -> tuple[str, tuple[float | str, str]]:
    """``name=0.4`` (above), ``name<1e8`` (below), ``name>0.4`` (above), ``name<-20%``
    (relative to the first record) → ``(name, (value, direction))``."""
    for sep, direction in ((">", "above"), ("<", "below"), ("=", "above")):
        if sep in text:
            name, value = text.split(sep, 1)
            name, value = name.strip(), value.strip()
            if not name or not value:
                break
            if value.endswith("%"):
                float(value[:-1])
                return name, (value, direction)
            return name, (float(value), direction)
    raise SettingsError(f"threshold {text!r}: write name>value, name<value or name<-20%")


@dataclasses.dataclass(frozen=True)
class TrendFlag:
    """State of a trajectory against its threshold (module docstring): `state` (``ok``,
    ``too_few``, ``approaching``, ``crossed``), `threshold` (SI), `direction`, `crossing_time`
    (ISO UTC: for ``crossed`` the line's crossing, or the first record of the last run beyond
    the threshold when there is no trend beyond it, or the first record beyond it when the last
    record is back within it; predicted for ``approaching``; else None),
    `reason` (one sentence)."""

    state: str
    threshold: float
    direction: str
    crossing_time: str | None
    reason: str

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class ParameterTrend:
    """One parameter of one machine: `values`, `lower`, `upper` (95 %) per record, the line's
    `intercept` and `slope` (per day) with `slope_se`, and the `flag` (None: no threshold)."""

    name: str
    values: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    intercept: float
    slope: float
    slope_se: float
    flag: TrendFlag | None

    def line(self, days: np.ndarray) -> np.ndarray:
        return self.intercept + self.slope * np.asarray(days)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "values": self.values.tolist(), "lower_95": self.lower.tolist(),
                "upper_95": self.upper.tolist(), "intercept": self.intercept,
                "slope_per_day": self.slope, "slope_se": self.slope_se,
                "flag": None if self.flag is None else self.flag.to_dict()}


@dataclasses.dataclass(frozen=True)
class MachineTrend:
    """The trajectories of one machine: `records`, `times` (ISO UTC, or None), `days` (since
    the first record), `timed` (False when the records had no timestamps), `parameters`."""

    machine: str
    records: tuple[str, ...]
    times: tuple[str | None, ...]
    days: np.ndarray
    timed: bool
    parameters: dict[str, ParameterTrend]

    @property
    def flagged(self) -> list[str]:
        """Names whose flag is not ``ok``."""
        return [n for n, p in self.parameters.items() if p.flag and p.flag.state != "ok"]

    @property
    def state(self) -> str:
        """The most urgent flag: ``crossed``, ``approaching``, ``too_few``, else ``ok``."""
        states = [p.flag.state for p in self.parameters.values() if p.flag]
        for s in ("crossed", "approaching", "too_few"):
            if s in states:
                return s
        return "ok"

    def to_dict(self) -> dict[str, Any]:
        return {"machine": self.machine, "records": list(self.records), "times": list(self.times),
                "days": self.days.tolist(), "timed": self.timed, "state": self.state,
                "flagged": self.flagged,
                "parameters": {n: p.to_dict() for n, p in self.parameters.items()}}


def fit_trend(days, values, lower=None, upper=None) -> tuple[float, float, float]:
    """Weighted straight line through `values` over `days` (module docstring).

    **Returns:** ``(intercept, slope per day, slope standard error)``; with fewer than two
    points the slope is 0 and its error infinite."""
    t = np.asarray(days, float)
    x = np.asarray(values, float)
    ok = np.isfinite(t) & np.isfinite(x)
    sig = np.ones_like(x)
    if lower is not None and upper is not None:
        s = (np.asarray(upper, float) - np.asarray(lower, float)) / (2 * _Z95)
        good = np.isfinite(s) & (s > 0)
        if np.any(good & ok):
            sig = np.where(good, s, np.nanmedian(np.where(good, s, np.nan)))
    t, x, sig = t[ok], x[ok], sig[ok]
    if t.size < 2 or np.ptp(t) == 0:
        return (float(np.mean(x)) if x.size else float("nan")), 0.0, float("inf")
    w = 1.0 / sig**2
    A = np.stack([np.ones_like(t), t], axis=1)
    AtW = A.T * w
    cov = np.linalg.inv(AtW @ A)
    a, b = cov @ (AtW @ x)
    r = x - (a + b * t)
    dof = t.size - 2
    scale = max(1.0, math.sqrt(float(np.sum(w * r * r)) / dof)) if dof > 0 else 1.0
    return float(a), float(b), float(math.sqrt(cov[1, 1]) * scale)


def flag_trend(days, values, intercept: float, slope: float, slope_se: float,
               threshold: float, direction: str, t0: _dt.datetime | None,
               horizon_days: float = 90.0) -> TrendFlag:
    """The flag of one trajectory (module docstring)."""
    if direction not in ("above", "below"):
        raise SettingsError(f"direction must be above or below, got {direction!r}")
    sgn = 1.0 if direction == "above" else -1.0
    t = np.asarray(days, float)
    x = np.asarray(values, float)

    def when(d: float | None) -> str | None:
        if d is None or t0 is None or not math.isfinite(d):
            return None
        return (t0 + _dt.timedelta(days=float(d))).isoformat()

    if t.size == 0:
        return TrendFlag("too_few", threshold, direction, None,
                         f"no record with a value: too few for a trend ({MIN_TREND_RECORDS} "
                         "needed)")
    trend = t.size >= MIN_TREND_RECORDS and math.isfinite(slope_se)
    t_last = float(t[-1])
    line_last = intercept + slope * t_last
    cross = (threshold - intercept) / slope if slope != 0 else None
    if sgn * (x[-1] - threshold) > 0:
        beyond = sgn * (x - threshold) > 0
        first = len(x) - int(np.argmin(beyond[::-1])) if not beyond.all() else 0
        if trend and sgn * (line_last - threshold) > 0:
            return TrendFlag("crossed", threshold, direction, when(cross),
                             f"trend {line_last:.4g} and last value {x[-1]:.4g} are {direction} "
                             f"{threshold:.4g}")
        why = ("the trend line is not" if trend else
               f"{t.size} record(s): too few for a trend")
        return TrendFlag("crossed", threshold, direction, when(float(t[first])),
                         f"last value {x[-1]:.4g} is {direction} {threshold:.4g} ({why})")
    beyond = sgn * (x - threshold) > 0
    if beyond.any():  # an earlier record beyond it, the last back within: still a crossing
        k = int(np.argmax(beyond))
        return TrendFlag("crossed", threshold, direction, when(float(t[k])),
                         f"record {k + 1} of {t.size} at {x[k]:.4g} is {direction} "
                         f"{threshold:.4g}; the last value {x[-1]:.4g} is back within it (a "
                         "repair, or a misfit of that record: check it)")
    if not trend:
        return TrendFlag("too_few", threshold, direction, None,
                         f"{t.size} record(s): too few for a trend ({MIN_TREND_RECORDS} at "
                         f"distinct times needed); last value {x[-1]:.4g}, threshold "
                         f"{threshold:.4g} {direction}")
    if sgn * slope > 2.0 * slope_se and cross is not None and t_last < cross <= t_last + \
            horizon_days:
        return TrendFlag("approaching", threshold, direction, when(cross),
                         f"slope {slope:.3g}/day (±{slope_se:.2g}) reaches {threshold:.4g} in "
                         f"{cross - t_last:.1f} days")
    return TrendFlag("ok", threshold, direction, None,
                     f"trend {line_last:.4g}, slope {slope:.3g}/day (±{slope_se:.2g})")


def _resolve(threshold: float | str, first: float) -> float:
    if isinstance(threshold, str) and threshold.endswith("%"):
        return first * (1.0 + float(threshold[:-1]) / 100.0)
    return float(threshold)


def machine_trends(
    results: Sequence[Mapping[str, Any]],
    thresholds: Mapping[str, tuple[float | str, str]] | None = None,
    *,
    horizon_days: float = 90.0,
) -> dict[str, MachineTrend]:
    """Trends per machine from fleet results (``status == "ok"`` entries of
    :func:`dtwin.identify.fleet.load_results`).

    **Arguments:** `results`; `thresholds`: parameter → ``(value, "above"|"below")`` (value
    SI, or ``"-20%"`` relative to the first record), merged over :data:`DEFAULT_THRESHOLDS`;
    `horizon_days`: how far ahead an ``approaching`` crossing is predicted.

    **Returns:** ``{machine: MachineTrend}``, machines sorted by name, records by time."""
    th = dict(DEFAULT_THRESHOLDS)
    th.update(thresholds or {})
    by_machine: dict[str, list[Mapping[str, Any]]] = {}
    for r in results:
        if r.get("status") == "ok":
            by_machine.setdefault(str(r.get("machine")), []).append(r)
    out: dict[str, MachineTrend] = {}
    for machine in sorted(by_machine):
        rs = by_machine[machine]
        timed = all(r.get("timestamp") for r in rs)
        if timed:
            rs = sorted(rs, key=lambda r: (r["timestamp"], r["record"]))
            ts = [_dt.datetime.fromisoformat(r["timestamp"]) for r in rs]
            t0 = ts[0]
            days = np.array([(t - t0).total_seconds() / 86400.0 for t in ts])
        else:
            rs = sorted(rs, key=lambda r: str(r["record"]))
            t0 = None
            days = np.arange(len(rs), dtype=float)
        names: list[str] = []
        for r in rs:
            names += [n for n in r.get("names", []) if n not in names]
        params = {}
        for n in names:
            v = np.array([_f((r.get("values") or {}).get(n)) for r in rs])
            iv = [(r.get("intervals_95") or {}).get(n, (None, None)) for r in rs]
            lo = np.array([_f(a) for a, _ in iv])
            hi = np.array([_f(b) for _, b in iv])
            a, b, se = fit_trend(days, v, lo, hi)
            flag = None
            if n in th:
                value, direction = th[n]
                finite = v[np.isfinite(v)]
                thr = _resolve(value, float(finite[0]) if finite.size else float("nan"))
                keep = np.isfinite(v)
                flag = flag_trend(days[keep], v[keep], a, b, se, thr, direction, t0, horizon_days)
            params[n] = ParameterTrend(n, v, lo, hi, a, b, se, flag)
        out[machine] = MachineTrend(machine, tuple(str(r["record"]) for r in rs),
                                    tuple(r.get("timestamp") for r in rs), days, timed, params)
    return out


def _f(v: Any) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")
