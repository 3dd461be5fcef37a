"""The identification API for users and scripts (re-exports; the CLI calls the same functions).

    from dtwin.identify.api import fit, estimate_severity, severity_series, ParameterSet, Features

    res = fit(records, "bench.toml", ["k_sun_planet", "k_ring_planet", "zeta_mesh", "sun_fault"],
              starts=9, refine=3)   # or fit(records, spec, free, FitSettings(starts=9, refine=3))
    seg = segment_for_fit(long_record, "bench.toml")   # a steady window of a long record
    res = fit(seg.record, "bench.toml", ["sun_fault"]); print(seg.describe())
    print(res.table())           # values, 95 % intervals, "NOT DETERMINED" flags
    res.to_dict()                # JSON-ready (values, intervals, correlations, loss history)

See docs/identification.md.
"""

from __future__ import annotations

import numpy as np

from dtwin.model.kinematics import Kinematics
from dtwin.signal.spectrum import label_frequency

from .fit import fit as fit
from .fit_batch import fit_batch as fit_batch
from .fit_batch import stack_problems as stack_problems
from .fit_result import FitResult as FitResult
from .fit_settings import FitSettings as FitSettings
from .operating_point import OperatingPoint as OperatingPoint
from .operating_point import SpeedProfileEstimate as SpeedProfileEstimate
from .operating_point import estimate_speed as estimate_speed
from .operating_point import estimate_speed_profile as estimate_speed_profile
from .params import ParameterSet as ParameterSet
from .problem import Problem as Problem
from .problem import make_problem as make_problem
from .residuals import Features as Features
from .residuals import Observation as Observation
from .residuals import drive_at as drive_at
from .residuals import observe as observe
from .segment import FitWindow as FitWindow
from .segment import Segment as Segment
from .segment import segment_for_fit as segment_for_fit
from .severity import SeverityEstimate as SeverityEstimate
from .severity import SeveritySeries as SeveritySeries
from .severity import estimate_severity as estimate_severity
from .severity import severity_series as severity_series
from .stopping import SOLVERS as SOLVERS
from .uncertainty import Uncertainty as Uncertainty
from .uncertainty import analyse as analyse

__all__ = [
    "SOLVERS", "Features", "FitResult", "FitSettings", "FitWindow", "Observation", "OperatingPoint",
    "ParameterSet", "Problem", "Segment", "SeverityEstimate", "SeveritySeries", "SpeedProfileEstimate", "Uncertainty",
    "analyse", "drive_at", "estimate_severity", "estimate_speed", "estimate_speed_profile",
    "fit", "fit_batch", "make_problem", "stack_problems", "observe", "plot_fit", "plot_severity_series", "segment_for_fit", "severity_series",
]


def plot_fit(result: FitResult, record_index: int = 0, *, label_peaks: bool = True,
             unit: str | None = "m/s^2"):
    """Figure of measured vs fitted levels of one record of `result`, peaks labelled with their
    gear-frequency combinations (:func:`dtwin.signal.spectrum.label_frequency`); levels in dB re the
    reference of the record's `unit` (None: a unit the record does not state)."""
    from .plotting.fit import plot_fit_spectrum  # at call time: matplotlib only for figures

    freqs, meas, model = result.spectra()[record_index]
    labels = []
    if label_peaks:
        try:
            labels = _labels(result, record_index, freqs, meas)
        except Exception as e:  # noqa: BLE001 — labels are decoration; say why they are missing
            labels = [(float(freqs[int(np.argmax(meas))]), f"(labels unavailable: {e})")]
    return plot_fit_spectrum(freqs, meas, model, labels=labels, unit=unit)


def _labels(result: FitResult, i: int, freqs, meas, n: int = 8):
    p = result.problem
    obs = p.observations[i]
    basis = Kinematics.from_gear_set(p.twin.lp, float(obs.speed[0]))
    m = np.asarray(meas)
    # the n highest local maxima, one per line (neighbouring bins of a peak are not new lines)
    peak = np.flatnonzero((m[1:-1] >= m[:-2]) & (m[1:-1] >= m[2:])) + 1
    idx = []
    for k in peak[np.argsort(m[peak])[::-1]]:
        if all(abs(int(k) - j) > 3 for j in idx):
            idx.append(int(k))
        if len(idx) == n:
            break
    res = 1.0 / obs.duration
    out = []
    for k in sorted(idx, key=lambda j: freqs[j]):
        lab = label_frequency(float(freqs[k]), basis, res)
        text = lab[0].text if lab else "no kinematic match"
        out.append((float(freqs[k]), text))
    return out


def plot_severity_series(series: SeveritySeries, truth=None):
    """Figure of the trajectories of a :class:`SeveritySeries` (one panel per parameter)."""
    from .plotting.fit import plot_trajectories  # at call time: matplotlib only for figures

    vals = {n: series.trajectory(n)[0] for n in series.names}
    lo = {n: series.trajectory(n)[1] for n in series.names}
    hi = {n: series.trajectory(n)[2] for n in series.names}
    return plot_trajectories(series.labels, vals, lo, hi, truth=truth)
