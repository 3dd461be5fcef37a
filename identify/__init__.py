"""identify: fitting, uncertainty, severity, discrepancy discovery and fleet runs for dtwin.

identify never edits the twin's equations: it chooses parameter values and adds parts.
"""

import dtwin as _dtwin  # noqa: F401  (float64 + compilation cache)
