"""Fault severity from records: one estimate with its interval, and a series (degradation).

:func:`estimate_severity` fits the severity of the fault at a named location
(``<location>_fault``, a registry name), optionally with further free parameters (mesh
stiffness, damping), and returns it with its 95 % interval — a profile-likelihood interval when
the estimate lies near 0 or 1 (:mod:`dtwin.identify.uncertainty`).

:func:`severity_series` runs the same fit over a series of records (e.g. one per day of a
machine's life): all records of one length and rate share one compiled fit (the observations
differ only in their arrays), so after the first record each fit costs only its iterations.
The trajectories of the severity and of the other free parameters, with their intervals, come
back as :class:`SeveritySeries`; :func:`dtwin.identify.api.plot_severity_series` draws them (the
paper's degradation-model idea).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from .fit import FitResult, fit

__all__ = ["SeverityEstimate", "SeveritySeries", "estimate_severity", "severity_series"]

_LOCATIONS = ("sun", "planet", "ring")


def _name(location: str) -> str:
    if location not in _LOCATIONS:
        from dtwin.errors import ParameterError

        raise ParameterError(f"fault location must be one of {_LOCATIONS}, got {location!r}")
    return f"{location}_fault"


@dataclasses.dataclass(frozen=True)
class SeverityEstimate:
    """Severity (1) at `location` with its 95 % `interval`, whether it is `determined`, the
    method of the interval (``gaussian`` in the logit coordinate or ``profile``), and the fit."""

    location: str
    severity: float
    interval: tuple[float, float]
    determined: bool
    method: str
    fit: FitResult = dataclasses.field(repr=False)

    def to_dict(self) -> dict[str, Any]:
        return {"location": self.location, "severity": self.severity,
                "interval_95": list(self.interval), "determined": self.determined,
                "interval_method": self.method, "fit": self.fit.to_dict()}


def estimate_severity(
    record, spec_or_twin, location: str = "sun", *, free: Sequence[str] = (),
    initial_severity: float = 0.3, **fit_kwargs: Any,
) -> SeverityEstimate:
    """Severity of the fault at `location` from one record (module docstring).

    **Arguments:** `record`; `spec_or_twin`; `location` (``sun``, ``planet``, ``ring``); `free`:
    further registry names fitted together; `initial_severity`; keyword arguments of
    :func:`dtwin.identify.fit.fit` (``f_sun``, ``features``, ``starts``, ``progress`` …).
    """
    name = _name(location)
    names = [name] + [n for n in free if n != name]
    initial = dict(fit_kwargs.pop("initial", {}) or {})
    initial.setdefault(name, initial_severity)
    res = fit(record, spec_or_twin, names, initial=initial, **fit_kwargs)
    i = res.names.index(name)
    unc = res.uncertainty
    iv = tuple(map(float, unc.interval[i])) if unc is not None else (np.nan, np.nan)
    method = "profile" if unc is not None and name in unc.profiled else "gaussian"
    det = unc is not None and name not in unc.not_determined
    return SeverityEstimate(location, res.values[name], iv, det, method, res)


@dataclasses.dataclass(frozen=True)
class SeveritySeries:
    """Trajectories over a series of records: `labels` (one per record), `names` (free
    parameters), `values` ``(records, params)`` (SI), `lower`/`upper` (95 %),
    `not_determined` (per record, names flagged), and the fits."""

    labels: tuple[str, ...]
    names: tuple[str, ...]
    values: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    not_determined: tuple[tuple[str, ...], ...]
    fits: tuple[FitResult, ...] = dataclasses.field(repr=False)

    def trajectory(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        i = self.names.index(name)
        return self.values[:, i], self.lower[:, i], self.upper[:, i]

    def to_dict(self) -> dict[str, Any]:
        return {"labels": list(self.labels), "names": list(self.names),
                "values": self.values.tolist(), "lower_95": self.lower.tolist(),
                "upper_95": self.upper.tolist(),
                "not_determined": [list(x) for x in self.not_determined]}


def severity_series(
    records: Sequence, spec_or_twin, location: str = "sun", *, free: Sequence[str] = (),
    labels: Sequence[str] | None = None, initial_severity: float = 0.3, warm_start: bool = False,
    **fit_kwargs: Any,
) -> SeveritySeries:
    """Fit every record of a series (module docstring).

    **Arguments:** `records` (in time order); `spec_or_twin`; `location`; `free` (further
    parameters); `labels` (default ``record0`` …); `initial_severity`; `warm_start`: start each
    fit from the previous record's values (a slowly evolving machine); keyword arguments of
    :func:`dtwin.identify.fit.fit`.
    """
    name = _name(location)
    names = [name] + [n for n in free if n != name]
    labels = tuple(labels) if labels is not None else tuple(f"record{i}" for i in range(len(records)))
    if len(labels) != len(records):
        raise ValueError("labels need one entry per record")
    init = dict(fit_kwargs.pop("initial", {}) or {})
    init.setdefault(name, initial_severity)
    fits = []
    for rec in records:
        res = fit(rec, spec_or_twin, names, initial=init, **fit_kwargs)
        fits.append(res)
        if warm_start:
            init = dict(res.values)
    p = len(names)
    vals = np.array([[f.values[n] for n in names] for f in fits]).reshape(len(fits), p)
    lo = np.array([[f.interval(n)[0] if f.uncertainty else np.nan for n in names] for f in fits])
    hi = np.array([[f.interval(n)[1] if f.uncertainty else np.nan for n in names] for f in fits])
    nd = tuple(tuple(f.not_determined) for f in fits)
    return SeveritySeries(labels, tuple(names), vals, lo.reshape(vals.shape), hi.reshape(vals.shape),
                          nd, tuple(fits))
