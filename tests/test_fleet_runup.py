"""Fleet records: a run-up is recognised as one (and fitted as one), a steady record is not.

The bundled bench records (``data/samples``) are the reference: ``bench_runup`` was simulated
with the input speed ramped from 20 Hz (its tachometer says so), the others at a steady
29.7 Hz.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dtwin.identify.fleet.tasks import RUNUP_SPEED_CHANGE, runup_range
from dtwin.io.readers import read_record
from dtwin.io.record import Record
from dtwin.spec import preset

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"


@pytest.mark.parametrize("name,runup", [("bench_healthy", False), ("bench_sun_fault", False),
                                        ("bench_combined", False), ("bench_runup", True)])
def test_bundled_records(name, runup):
    rng = runup_range(read_record(SAMPLES / f"{name}.dtwin.h5"), preset("paper-bench"))
    assert (rng is not None) == runup
    if runup:  # the tachometer's speed range, with its 3 % margin, starts near 20 Hz
        assert 0.97 * 19.0 < rng[0] < 21.0 and rng[1] > rng[0] * 1.1



def test_mesh_line_tracking_without_tacho():
    """A mesh tone whose frequency rises by 10 % is a run-up; a steady one is not."""
    spec = preset("paper-bench")
    gs = spec.gear_set()
    mo = gs.z_sun * gs.z_ring / (gs.z_sun + gs.z_ring)
    fs, T = 5000.0, 4.0
    t = np.arange(int(fs * T)) / fs
    f0 = 29.7
    noise = 0.05 * np.random.default_rng(0).standard_normal(t.size)
    for slope, expected in ((0.0, False), (0.1 * f0 / T, True)):
        phase = 2 * np.pi * mo * (f0 * t + 0.5 * slope * t**2)
        rec = Record(np.cos(phase)[None] + noise, fs, ("a",), ("m/s^2",))
        assert (runup_range(rec, spec) is not None) == expected
    assert RUNUP_SPEED_CHANGE < 0.1
