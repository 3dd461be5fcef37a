"""Order map and order cuts of a run-up against a synthetic run-up whose orders and amplitudes are
known, with the angle from a tachometer."""

import numpy as np
import pytest

from dtwin.signal.order import order_cuts, order_map, tacho_angle


@pytest.fixture(scope="module")
def runup():
    # input shaft 10 -> 20 Hz linearly over 4 s; order 7.3 of amplitude 2, order 12 of 0.5
    fs, dur = 8000.0, 4.0
    t = np.arange(int(fs * dur)) / fs
    speed = 10.0 + 2.5 * t
    theta = 2 * np.pi * (10.0 * t + 1.25 * t**2)
    x = 2.0 * np.cos(7.3 * theta) + 0.5 * np.cos(12.0 * theta)
    tacho = (np.mod(theta, 2 * np.pi) < 0.5).astype(float)  # one pulse per revolution
    return fs, t, speed, theta, x, tacho


def test_order_map_speeds_and_lines(runup):
    fs, t, speed, theta, x, tacho = runup
    ang = tacho_angle(tacho, fs, 1)
    om = order_map(x, fs, ang, max_order=20.0, revs_per_segment=4)
    assert np.all(np.diff(om.speed) >= 0)
    assert om.speed[0] == pytest.approx(10.0, abs=0.6) and om.speed[-1] == pytest.approx(20.0, abs=0.6)
    np.testing.assert_allclose(om.rpm, 60 * om.speed)
    # each stretch's speed is the true speed at its centre time (linear run-up: the mean)
    np.testing.assert_allclose(om.speed, np.interp(om.times, t, speed), rtol=0.01)
    # order 12 is on a bin (resolution 1/4): it reads 0.5 there
    k = int(np.argmin(np.abs(om.orders - 12.0)))
    np.testing.assert_allclose(om.amplitude[k], 0.5, rtol=0.02)
    assert om.orders[1] - om.orders[0] == pytest.approx(0.25)


def test_order_cuts_read_amplitude_between_bins(runup):
    fs, t, speed, theta, x, tacho = runup
    om = order_map(x, fs, theta - theta[0], max_order=20.0, revs_per_segment=4)
    cuts = order_cuts(om, {"7.3": 7.3, "12": 12.0, "far": 50.0})
    # 7.3 falls between bins (7.25, 7.5): the Parseval sum over the main lobe gives 2 anyway
    np.testing.assert_allclose(cuts["7.3"], 2.0, rtol=0.02)
    np.testing.assert_allclose(cuts["12"], 0.5, rtol=0.02)
    assert np.all(np.isnan(cuts["far"]))
