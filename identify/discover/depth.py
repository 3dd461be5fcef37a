"""The depth of a tooth fault that discovery named: the problem ``dtwin severity`` fits.

Discovery's search fits each candidate's amplitude about the current twin, linearised, in the
spec's own twin kind, on the bins of its signature (:mod:`dtwin.identify.discover.statistics`):
that is what decides whether an effect is there and which one it is, not how deep a fault is.
A fault's depth is fitted once, one way, for every command (issue "One fault depth"):
:func:`dtwin.identify.severity.estimate_severity` on the same record and spec — the same twin,
the same ends of a calibration's excitation/response split, the same bands, and so the same
number ``dtwin severity REC --spec S --location L`` reports.

:func:`fault_depths` fits it for each step of a :class:`~dtwin.identify.discover.DiscoveryResult`
that added a local tooth fault and keeps it on the step (:attr:`Step.depth`); ``dtwin discover``
does so by default (``--no-depth`` skips it).
"""

from __future__ import annotations

from typing import Any

from dtwin.io.record import Record

from ..segment import segment_for_fit
from ..severity import SeverityEstimate, estimate_severity
from .results import DiscoveryResult

__all__ = ["fault_depths", "tooth_fault_location"]

#: discovery's local tooth-fault effects (:class:`dtwin.identify.discover.effects.LocalFaultEffect`
#: names, ``<location>_local_fault`` and a planet's ``planet_local_fault_<flank>``)
_SUFFIX = "_local_fault"


def tooth_fault_location(effect: str) -> str | None:
    """The location (``sun``, ``planet``, ``ring``) of a discovery effect that is a local tooth
    fault, from its name; None for any other effect."""
    head, sep, _ = effect.partition(_SUFFIX)
    return head if sep and head in ("sun", "planet", "ring") else None


def fault_depths(result: DiscoveryResult, record, spec, *, f_sun: float | None = None,
                 kind: str | None = None, channel: int | str = 0,
                 **severity_kwargs: Any) -> list[SeverityEstimate]:
    """Fit the depth of every local tooth fault `result` added, as ``dtwin severity`` does, and
    keep each on its step (``step.depth``, the estimate's dictionary without the fit).

    **Arguments:** `result` (of :func:`~dtwin.identify.discover.discover` on `record`);
    `record` (a :class:`dtwin.io.Record`, cut to the stretch and rate ``dtwin severity`` fits:
    :func:`dtwin.identify.segment.segment_for_fit`, ``auto``); `spec` (the spec discovery was
    given: path,
    mapping, `Spec`, or a twin); `f_sun` (Hz) and `kind` as the user gave them to discovery
    (None: as ``dtwin severity`` resolves them); `channel`; further keyword arguments of
    :func:`~dtwin.identify.severity.estimate_severity`.

    **Returns:** the estimates, one per tooth-fault step, in step order.
    """
    if not isinstance(record, Record):
        raise TypeError("fault_depths needs the Record discovery was run on, got "
                        f"{type(record).__name__}")
    out = []
    segment = None
    for step in result.steps:
        location = tooth_fault_location(step.effect)
        if location is None:
            continue
        if segment is None:  # the stretch and rate `dtwin severity` fits (its default window)
            segment = segment_for_fit(record, spec, f_sun, "auto", channel=channel).record
        est = estimate_severity(segment, spec, location, f_sun=f_sun, kind=kind,
                                channel=channel, **severity_kwargs)
        step.depth = est.to_dict(with_fit=False)
        step.depth["summary"] = est.summary()
        out.append(est)
    return out
