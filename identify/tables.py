"""Identification results as rows (lists of dicts) and pandas DataFrames: what the HTML report
shows and what a script analyses.

    from dtwin.identify.tables import fit_dataframe, trends_dataframe

    df = fit_dataframe(result)            # one row per parameter: initial, fitted, 95 %, unit
    trends_dataframe(trends)              # one row per machine, record and parameter

Units come from the parameter registry (``"1"`` for dimensionless). DataFrames need pandas
(``pip install 'dtwin[fleet]'``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from dtwin.model.registry import REGISTRY

__all__ = ["discovery_candidate_rows", "discovery_rows", "fit_dataframe", "fit_rows", "trend_rows", "trends_dataframe"]


def _unit(name: str) -> str:
    info = REGISTRY.get(name)
    return "?" if info is None else info.unit


def fit_rows(result: Any) -> list[dict[str, Any]]:
    """One row per fitted parameter of a :class:`dtwin.identify.fit.FitResult`: ``parameter``,
    ``unit``, ``initial``, ``fitted``, ``lower_95``, ``upper_95``, ``status`` (ok,
    unconverged, NOT DETERMINED, widened ×k for lack of fit, residuals not white:
    ``FitResult.status``)."""
    rows = []
    nd = result.not_determined
    for n in result.names:
        lo = hi = None
        if result.has_interval(n) if hasattr(result, "has_interval") else \
                result.uncertainty is not None:
            lo, hi = result.interval(n)
        status = (result.status(n) if hasattr(result, "status") else
                  "NOT DETERMINED" if n in nd else "ok" if result.converged else "unconverged")
        rows.append({"parameter": n, "unit": _unit(n), "initial": float(result.initial[n]),
                     "fitted": float(result.values[n]), "lower_95": lo, "upper_95": hi,
                     "status": status})
    return rows


def _frame(rows: list[dict[str, Any]]):
    try:
        import pandas as pd
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("DataFrames need pandas: pip install 'dtwin[fleet]'") from e
    return pd.DataFrame(rows)


def fit_dataframe(result: Any):
    """:func:`fit_rows` as a pandas DataFrame."""
    return _frame(fit_rows(result))


def _total(g: Any) -> float:
    """A gap's total (dB); NaN where there is none."""
    return float("nan") if g is None else float(g.total)


def discovery_rows(result: Any) -> list[dict[str, Any]]:
    """One row per step of a discovery (:class:`dtwin.identify.discover.DiscoveryResult`):
    effect named, main parameter with its 99 % interval and unit, held-out gap before and
    after (dB; as reported, the twin with the effect simulated in full), the search's gaps
    (bins `threshold_db` over the floor; after: linearised), p-value; for a local tooth fault,
    its peak stiffness loss with its 95 % interval and status as ``dtwin severity`` fits it
    (:attr:`~dtwin.identify.discover.Step.depth`; NaN otherwise)."""
    rows = []
    for s in result.steps:
        unit = s.main.get("unit", "")
        rows.append({"step": s.number, "effect": s.named, "parameter": s.main["name"],
                     "value": float(s.main["value"]),
                     "lower_99": float(s.main["interval"][0]),
                     "upper_99": float(s.main["interval"][1]),
                     "unit": "dimensionless" if unit == "1" else unit,
                     "gap_before_db": _total(s.heldout_before),
                     "gap_after_db": _total(s.heldout_after),
                     "search_gap_before_db": float(s.gap_before.total),
                     "search_gap_after_db": float(s.gap_after.total),
                     "p_value": float(s.p_value)})
        # a tooth fault's depth, as `dtwin severity` fits it (NaN: not a tooth fault, or
        # not fitted)
        d = s.depth or {}
        lo, hi = d.get("peak_stiffness_loss_interval_95", (float("nan"), float("nan")))
        rows[-1].update(peak_stiffness_loss=float(d.get("peak_stiffness_loss", float("nan"))),
                        peak_stiffness_loss_lower_95=float(lo),
                        peak_stiffness_loss_upper_95=float(hi),
                        depth_status=d.get("status", ""))
    return rows


def discovery_candidate_rows(result: Any) -> list[dict[str, Any]]:
    """One row per candidate judged in each step of a discovery
    (:class:`dtwin.identify.discover.DiscoveryResult`), the last (unaccepted) step included:
    step, candidate and its group, coverage, screening score (degrees of freedom, rank), the
    search's gap before the step and with the candidate (dB, linearised), p-value against the
    step's family-wise level, whether its amplitude was identified, its fitted main value with
    unit and interval, an out-of-range refit, and whether it was accepted or set aside and why
    (screened out, not significant, amplitude not identified, a failed or out-of-range refit,
    not confirmed simulated in full). These are
    :meth:`dtwin.identify.discover.DiscoveryResult.candidate_table`'s rows: the terminal, the
    JSON and both reports print the same verdicts."""
    return result.candidate_table()


def trend_rows(trends: Mapping[str, Any]) -> list[dict[str, Any]]:
    """One row per machine, record and parameter of :func:`dtwin.identify.trends.machine_trends`:
    value with its 95 % interval, days since the first record, the machine's flag state."""
    rows = []
    for m, t in trends.items():
        for n, p in t.parameters.items():
            for k, rec in enumerate(t.records):
                rows.append({"machine": m, "record": rec, "time": t.times[k],
                             "days": float(t.days[k]), "parameter": n, "unit": _unit(n),
                             "value": float(p.values[k]), "lower_95": float(p.lower[k]),
                             "upper_95": float(p.upper[k]),
                             "state": p.flag.state if p.flag is not None else "no threshold"})
    return rows


def trends_dataframe(trends: Mapping[str, Any]):
    """:func:`trend_rows` as a pandas DataFrame."""
    return _frame(trend_rows(trends))
