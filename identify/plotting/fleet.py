"""Figures of a fleet: one machine's parameter trends with intervals, thresholds and flags, and
an overview of every machine's latest severity.

The functions take :class:`dtwin.identify.trends.MachineTrend` objects (duck-typed: plain attributes)
and return a matplotlib Figure; ``dtwin fleet trends`` and scripts call the same functions.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from dtwin.model.registry import REGISTRY

__all__ = ["plot_fleet_overview", "plot_machine_trend"]

_STATE_COLOURS = {"ok": "tab:green", "too_few": "tab:gray", "approaching": "tab:orange",
                  "crossed": "tab:red"}


def plot_machine_trend(trend: Any, names: Sequence[str] | None = None) -> Figure:
    """One panel per parameter of one machine: estimates with 95 % intervals over time, the
    weighted trend line, the threshold (dashed) and the flag state in the panel title."""
    names = list(names or trend.parameters)
    fig = Figure(figsize=(7.5, 2.3 * max(len(names), 1) + 0.8))
    days = np.asarray(trend.days, float)
    grid = np.linspace(days.min(), days.max(), 50) if days.size else days
    for k, n in enumerate(names):
        p = trend.parameters[n]
        ax = fig.add_subplot(len(names), 1, k + 1)
        v, lo, hi = (np.asarray(p.values), np.asarray(p.lower), np.asarray(p.upper))
        err = np.vstack([np.where(np.isfinite(lo), v - lo, 0.0),
                         np.where(np.isfinite(hi), hi - v, 0.0)])
        ax.errorbar(days, v, yerr=np.maximum(err, 0.0), fmt="o", capsize=3, label="fit, 95 %")
        if np.isfinite(p.slope_se):
            ax.plot(grid, p.line(grid), "-", color="0.3", lw=1, label="trend")
        state = "no threshold"
        if p.flag is not None:
            ax.axhline(p.flag.threshold, ls="--", color=_STATE_COLOURS[p.flag.state], lw=1,
                       label=f"threshold ({p.flag.direction})")
            state = p.flag.state
        ax.set_ylabel(f"{n} ({_unit(n)})")
        ax.grid(alpha=0.3)
        ax.set_title(f"{n}: {state}", fontsize=9, loc="left",
                     color=_STATE_COLOURS.get(state, "black"))
        if k == 0:
            ax.legend(loc="best", fontsize=7)
    xlabel = "days since the first record" if trend.timed else "record (no timestamps)"
    fig.axes[-1].set_xlabel(xlabel) if fig.axes else None
    fig.suptitle(f"Machine {trend.machine}: {len(trend.records)} records, {trend.state}")
    fig.tight_layout()
    return fig


def plot_fleet_overview(trends: Mapping[str, Any], parameter: str | None = None) -> Figure:
    """Every machine in one figure: left, the latest value of `parameter` (default: the first
    fault severity fitted, else the first parameter) with its 95 % interval, coloured by the
    machine's flag state; right, all machines' trajectories of that parameter over time."""
    machines = sorted(trends)
    if parameter is None:
        names: list[str] = []
        for m in machines:
            names += [n for n in trends[m].parameters if n not in names]
        faults = [n for n in names if n.endswith("_fault")]
        parameter = faults[0] if faults else (names[0] if names else "")
    fig = Figure(figsize=(11, 0.45 * max(len(machines), 4) + 1.8))
    ax, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    thr = None
    for i, m in enumerate(machines):
        tr = trends[m]
        p = tr.parameters.get(parameter)
        if p is None or not len(p.values):
            continue
        v, lo, hi = float(p.values[-1]), float(p.lower[-1]), float(p.upper[-1])
        state = p.flag.state if p.flag is not None else tr.state
        col = _STATE_COLOURS.get(state, "tab:blue")
        xerr = [[max(v - lo, 0.0) if np.isfinite(lo) else 0.0],
                [max(hi - v, 0.0) if np.isfinite(hi) else 0.0]]
        ax.errorbar([v], [i], xerr=xerr, fmt="o", color=col, capsize=3)
        ax2.plot(tr.days, p.values, "o-", color=col, ms=3, lw=1, label=m)
        if p.flag is not None:
            thr = p.flag.threshold
    if thr is not None:
        ax.axvline(thr, ls="--", color="0.4", lw=1)
        ax2.axhline(thr, ls="--", color="0.4", lw=1)
    ax.set_yticks(range(len(machines)), machines)
    ax.set_xlabel(f"latest {parameter} ({_unit(parameter)}), 95 % interval")
    ax.set_title("Fleet: latest estimate per machine", fontsize=10)
    ax.grid(alpha=0.3)
    ax2.set_xlabel("days since each machine's first record")
    ax2.set_ylabel(f"{parameter} ({_unit(parameter)})")
    ax2.set_title("Trajectories (green ok, orange approaching, red crossed)", fontsize=9)
    ax2.grid(alpha=0.3)
    if len(machines) <= 12:
        ax2.legend(fontsize=7, loc="best")
    fig.tight_layout()
    return fig


def _unit(name: str) -> str:
    """The registry's unit of parameter `name` ("dimensionless" for 1; "?" if unknown)."""

    info = REGISTRY.get(name)
    return "?" if info is None else ("dimensionless" if info.unit == "1" else info.unit)
