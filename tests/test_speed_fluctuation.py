"""A speed fluctuation of the drive (dtwin.model.motor.speed_fluctuation) against closed forms: far
below the torsional modes the sun follows the rotor's speed and the carrier the kinematic
ratio, and the mesh line is frequency-modulated with the Bessel sidebands of its phase
deviation (J1(β)/J0(β) at m f_m ± f, β = m z_ring Δθ_c)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.special

from dtwin.model.motor.speed_fluctuation import SpeedFluctuation
from dtwin.simulation.simulate import DAQ, simulate
from dtwin.spec import preset
from dtwin.spec.build import build_twin

F_SUN = 30.0
F_X = 2.0      # Hz
A = 0.1        # rad/s at the rotor
DURATION = 2.0
FS = 5000.0


@pytest.fixture(scope="module")
def runs():
    spec = preset("paper-sim")
    out = {}
    for name, part in (("base", None), ("zero", SpeedFluctuation(0.0, 0.0, F_X)),
                       ("fluct", SpeedFluctuation(A, 0.0, F_X))):
        tw = build_twin(spec, kind="torsional", f_sun=F_SUN,
                        extra_parts=() if part is None else (part,))
        out[name] = simulate(tw, duration=DURATION, f_sun=F_SUN, daq=DAQ(sample_rate=FS),
                             discard=0.5, start="steady")
    g = spec["gears"]
    return out, g["z_sun"], g["z_ring"]


def _tone(x, t, f):
    """Complex amplitude of `x` at `f` (Hz) over whole periods (least squares)."""
    basis = np.stack([np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t), np.ones_like(t)], 1)
    c, *_ = np.linalg.lstsq(basis, x, rcond=None)
    return c[0] - 1j * c[1]


def test_zero_amplitude_is_the_base_twin(runs):
    out, _, _ = runs
    np.testing.assert_array_equal(np.asarray(out["zero"].signal), np.asarray(out["base"].signal))


def test_sun_and_carrier_follow_the_rotor(runs):
    out, zs, zr = runs
    res = out["fluct"]
    t = np.arange(len(res.signal)) / FS
    ws = np.asarray(res.outputs["omega_sun"])
    wc = np.asarray(res.outputs["omega_carrier"])
    c_sun = _tone(ws, t, F_X)
    assert abs(c_sun) == pytest.approx(A, rel=0.02)
    # in phase with the set cosine (t measured from the record's first sample, 0.5 s after 0:
    # 0.5 s is one whole period of 2 Hz)
    assert abs(np.angle(c_sun)) < 0.05
    assert abs(_tone(wc, t, F_X)) == pytest.approx(A * zs / (zs + zr), rel=0.02)


def test_mesh_line_is_frequency_modulated(runs):
    out, zs, zr = runs
    x = np.asarray(out["fluct"].signal)
    n = len(x)
    w = np.hanning(n + 1)[:-1]
    a = np.abs(np.fft.rfft(x * w))
    f = np.fft.rfftfreq(n, 1 / FS)
    fc = F_SUN * zs / (zs + zr)
    fm = zr * fc
    d_theta_c = A / (2 * math.pi * F_X) * zs / (zs + zr)

    def level(freq):
        k = int(round(freq / (f[1] - f[0])))
        return a[k - 1: k + 2].max()

    for m in (1, 2):
        beta = m * zr * d_theta_c
        want = scipy.special.jv(1, beta) / scipy.special.jv(0, beta)
        got = 0.5 * (level(m * fm - F_X) + level(m * fm + F_X)) / level(m * fm)
        assert got == pytest.approx(want, rel=0.15), (m, got, want)
