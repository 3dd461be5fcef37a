"""A stiffness loss of one depth makes every band's sidebands in the twin's proportions, so
the sideband ratio's bands agree on it (identify/severity.py, "The sideband ratio"): bands
whose 95 % intervals exclude each other leave the depth NOT DETERMINED. Hand-made band
readings (no simulation), the shapes measured on the family's records (benchmarks/README.md,
2026-12-01 third session): a transmission-error simulator's ring profile fault read 0.595
[0.505, 0.700] in its first band, above the grid's top in its third and 0.006 in its ninth."""

from __future__ import annotations

import math

from dtwin.identify.line_ratio import BandReading
from dtwin.identify.severity import bands_disagree


def _band(name, sev, lo, hi, edge="", fault_bins=6):
    return BandReading(name, 0.0, 1.0, fault_bins, 6, -20.0, 0.5, (), sev, (lo, hi), edge)


def test_bands_whose_intervals_overlap_agree():
    assert bands_disagree([_band("mesh1", 0.30, 0.25, 0.36), _band("mesh2", 0.40, 0.33, 0.50)]) \
        is None
    # one band alone, or bands without fault lines over the noise, cannot disagree
    assert bands_disagree([_band("mesh1", 0.30, 0.25, 0.36)]) is None
    assert bands_disagree([_band("mesh1", 0.30, 0.25, 0.36),
                           _band("mesh2", 0.0, 0.0, 0.05, "below detection", 0),
                           _band("mesh3", math.nan, math.nan, math.nan)]) is None
    # a band held at the grid's top reads at least its lower end: it agrees with one above it
    assert bands_disagree([_band("mesh1", 0.80, 0.70, 0.88),
                           _band("mesh3", 0.90, 0.66, 0.90, "above the grid")]) is None


def test_bands_whose_intervals_exclude_each_other_disagree():
    m1 = _band("mesh1", 0.595, 0.505, 0.700)
    m3 = _band("mesh3", 0.90, 0.758, 0.90, "above the grid")
    m9 = _band("mesh9", 0.006, 0.005, 0.009, "below the grid", 13)
    high, low = bands_disagree([m1, m3, m9])
    assert (high.name, low.name) == ("mesh3", "mesh9")
    high, low = bands_disagree([m1, m3])  # the third band reads above the first's interval
    assert (high.name, low.name) == ("mesh3", "mesh1")
