"""identify: fitting, uncertainty, severity, discrepancy discovery and fleet runs for dtwin.

identify never edits the twin's equations: it chooses parameter values and adds parts.
"""

import dtwin as _dtwin  # noqa: F401  (float64 + compilation cache)

from .api import Features as Features
from .api import FitResult as FitResult
from .api import FitSettings as FitSettings
from .api import Observation as Observation
from .api import OperatingPoint as OperatingPoint
from .api import ParameterSet as ParameterSet
from .api import Problem as Problem
from .api import SeverityEstimate as SeverityEstimate
from .api import SeveritySeries as SeveritySeries
from .api import SpeedProfileEstimate as SpeedProfileEstimate
from .api import Uncertainty as Uncertainty
from .api import analyse as analyse
from .api import drive_at as drive_at
from .api import estimate_severity as estimate_severity
from .api import estimate_speed as estimate_speed
from .api import estimate_speed_profile as estimate_speed_profile
from .api import fit as fit
from .api import fit_batch as fit_batch
from .api import make_problem as make_problem
from .api import observe as observe
from .api import plot_fit as plot_fit
from .api import plot_severity_series as plot_severity_series
from .api import severity_series as severity_series
from .api import stack_problems as stack_problems
from .discover import DiscoverySettings as DiscoverySettings
from .discover import discover as discover

__all__ = [
    "analyse",
    "discover",
    "DiscoverySettings",
    "drive_at",
    "estimate_severity",
    "estimate_speed",
    "estimate_speed_profile",
    "Features",
    "fit",
    "fit_batch",
    "FitResult",
    "FitSettings",
    "make_problem",
    "Observation",
    "observe",
    "OperatingPoint",
    "ParameterSet",
    "plot_fit",
    "plot_severity_series",
    "Problem",
    "severity_series",
    "SeverityEstimate",
    "SeveritySeries",
    "SpeedProfileEstimate",
    "stack_problems",
    "Uncertainty",
]
