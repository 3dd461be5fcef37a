"""Figures of identification results (fits, discovery, fleet trends). They live with
:mod:`dtwin.identify` (the twin's own figures are in :mod:`dtwin.plotting`); each function takes
data and returns a matplotlib Figure, and the CLI and notebooks call the same functions."""
