"""Calibration shortfall (:mod:`dtwin.identify.shortfall`): lines the calibrated twin leaves
unexplained on the healthy record, and a discovery candidate whose evidence lies on them."""

from __future__ import annotations

import numpy as np

from dtwin.identify.lines import Kinematics
from dtwin.identify.shortfall import SHORTFALL_SHARE, shortfall_lines, shortfall_share


class _Line:
    def __init__(self, f, ex):
        self.frequency, self.excess_db = f, ex


def _spectrum(fs=5000.0, n=20000, lines=()):
    rng = np.random.default_rng(0)
    t = np.arange(n) / fs
    x = 1e-3 * rng.standard_normal(n)
    for f, a in lines:
        x = x + a * np.sin(2 * np.pi * f * t)
    w = np.hanning(n)
    return np.fft.rfftfreq(n, 1 / fs), 2 * np.abs(np.fft.rfft(x * w)) / w.sum()


def test_a_misfitted_mesh_harmonic_is_a_shortfall_line_as_an_order():
    """The record holds fm and 2fm; the 'twin' makes fm right and 2fm 20 dB too weak: one
    shortfall line, at 2 × the mesh order of the input speed, with an excess near 20 dB."""
    kin = Kinematics.from_gears(21, 30, 81, 3, 30.0)
    fm = kin.f_mesh
    f, meas = _spectrum(lines=[(fm, 0.1), (2 * fm, 0.05)])
    _, model = _spectrum(lines=[(fm, 0.1), (2 * fm, 0.005)])
    orders, excess = shortfall_lines(f, meas, model, kin, 2250.0)
    assert len(orders) == 1
    assert abs(orders[0] * 30.0 - 2 * fm) < 0.5
    assert 15.0 < excess[0] < 25.0


def test_share_of_a_candidates_evidence_on_shortfall_lines():
    """Powers 10^(excess/10): two lines of 20 dB on shortfall lines and one of 20 dB elsewhere
    give 2/3; none on them gives 0; the speed maps orders to Hz."""
    orders = [33.0, 66.0]  # 2fm-like orders of f_sun = 30 Hz: 990 and 1980 Hz
    matched = [_Line(990.1, 20.0), _Line(1980.0, 20.0), _Line(1234.0, 20.0)]
    share, on = shortfall_share(matched, orders, 30.0, 0.25)
    assert abs(share - 2 / 3) < 1e-12 and on == [990.1, 1980.0]
    assert share >= SHORTFALL_SHARE
    share, on = shortfall_share(matched, orders, 31.0, 0.25)  # another speed: no longer on them
    assert share == 0.0 and on == []
    assert shortfall_share(matched, [], 30.0, 0.25) == (0.0, [])
