"""Signal-processing views on records made by the twin (issue 5's twin-record tests).

The shaft angles come from the simulation (`SimResult.outputs`), as a tachometer would give
them. TSA averages asynchronous noise down by sqrt(n) (Braun 1975). In a planetary gearbox a
plain TSA over the sun's relative turn also averages the fault away (each impact is seen
through the passing planet's window, at a carrier position that changes from turn to turn): the
sun-gear form of McFadden's windowed averaging (`sun_separation`) adds each planet's passage at
the sun tooth in mesh with it, and planet separation isolates each planet (McFadden 1994).
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from dtwin.model.faults import parse_fault
from dtwin.signal.tsa import (
    planet_separation,
    sun_relative_angle,
    sun_separation,
    time_synchronous_average,
)
from dtwin.simulation.simulate import simulate
from dtwin.spec import preset
from dtwin.spec.build import build_twin

FS = 5000.0


@functools.cache
def record(faults: tuple[str, ...], duration: float):
    spec = preset("paper-sim")
    tw = build_twin(spec, kind="torsional", faults=tuple(parse_fault(f) for f in faults))
    res = simulate(tw, duration=duration, f_sun=30.0, discard=0.1)
    return (np.asarray(res.signal), np.asarray(res.outputs["theta_sun"]),
            np.asarray(res.outputs["theta_carrier"]))


def test_tsa_averages_asynchronous_noise_down_by_sqrt_n():
    spec = preset("paper-sim")
    _, _, tc = record(("sun:missing_tooth:0.5",), 2.0)
    rel = sun_relative_angle(tc, spec["gears"]["z_sun"], spec["gears"]["z_ring"])
    noise = np.random.default_rng(0).standard_normal(tc.shape)
    tsa = time_synchronous_average(noise, rel, 1024, sample_rate=FS)
    assert tsa.n_averages >= 10
    assert abs(np.std(tsa.average) * np.sqrt(tsa.n_averages) - 1.0) < 0.25


def _sun_residual(x, tc, spt=16):
    """Sun-gear windowed average minus its tooth-periodic part (what every tooth shares)."""
    s = sun_separation(x, tc, 21, 81, 3, sample_rate=FS, samples_per_tooth=spt)
    a = s.average.reshape(21, spt)
    return (a - a.mean(axis=0)).ravel()


@pytest.mark.parametrize("snr_db", [None, 10.0])
def test_windowed_sun_average_raises_the_sun_fault_signature(snr_db):
    """The sun fault (tooth 0) stands out of the sun-gear average; healthy teeth all look alike."""
    x_h, _, tc = record((), 2.0)
    x_f, _, _ = record(("sun:missing_tooth:0.5",), 2.0)
    rng = np.random.default_rng(1)
    if snr_db is not None:
        s = np.std(x_f) / 10 ** (snr_db / 20)
        x_f = x_f + s * rng.standard_normal(x_f.shape)
        x_h = x_h + s * rng.standard_normal(x_h.shape)
    r_f, r_h = _sun_residual(x_f, tc), _sun_residual(x_h, tc)
    assert np.std(r_f) > 5.0 * np.std(r_h)
    kurt = np.mean(r_f**4) / np.mean(r_f**2) ** 2
    assert kurt > 5.0
    # the largest deviation sits at the faulty tooth (tooth 0, in contact for eps ~ 1.6 cycles)
    tooth = np.argmax(np.abs(r_f)) / 16
    assert tooth < 2.0 or tooth > 20.0


@pytest.mark.parametrize("planet", [0, 1, 2])
def test_planet_separation_points_at_the_faulty_planet(planet):
    spec = preset("paper-sim")
    g = spec["gears"]
    x, _, tc = record((f"planet:missing_tooth:0.7:0:{planet}",), 4.0)
    pa = planet_separation(x, tc, g["z_ring"], g["z_planet"], g["n_planets"], sample_rate=FS)
    # fault indicator per planet: kurtosis-like peakiness of the separated average
    peak = []
    for avg in pa.averages:
        a = avg[np.isfinite(avg)]
        a = a - a.mean()
        peak.append(np.mean(a**4) / np.mean(a**2) ** 2)
    assert int(np.argmax(peak)) == planet, peak
