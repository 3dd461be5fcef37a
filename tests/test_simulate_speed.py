"""`simulate` reads the input speed from the twin's drive (issue "One address per idea", item
2): a twin built from a spec runs at the spec's ``operating.f_sun`` without being told again,
bit for bit as when told; a run-up starts from its ramp's first speed; a twin with no drive to
read gets a clear error. The grid and step limit are the ones the fitting residuals use
(`dtwin.simulation.simulate.daq_grid`, `step_limit`), checked against their closed forms."""

import math

import equinox as eqx
import numpy as np
import pytest

from dtwin.errors import SolverError
from dtwin.model.motor.drive import DrivePart
from dtwin.model.motor.shaft import Shaft
from dtwin.model.motor.speed_source import IdealSpeedSource, SpeedProfile
from dtwin.simulation.simulate import (
    DAQ,
    SolverOptions,
    daq_grid,
    drive_speed,
    simulate,
    step_limit,
)
from dtwin.spec import preset
from dtwin.spec.build import build_twin


@pytest.fixture(scope="module")
def twin():
    return build_twin(preset("paper-sim"), kind="torsional")


def test_a_spec_built_twin_runs_at_the_spec_speed_untold(twin):
    f = preset("paper-sim")["operating"]["f_sun"]
    assert drive_speed(twin) == f
    daq = DAQ(sample_rate=5000.0)
    told = simulate(twin, duration=0.05, f_sun=f, discard=0.02, daq=daq)
    untold = simulate(twin, duration=0.05, discard=0.02, daq=daq)
    np.testing.assert_array_equal(np.asarray(untold.signal), np.asarray(told.signal))


def _with_drive(twin, profile):
    i = next(j for j, p in enumerate(twin.parts) if isinstance(p, DrivePart))
    return eqx.tree_at(lambda t: t.parts[i].drive, twin, IdealSpeedSource(profile, Shaft()))


def test_a_run_up_starts_from_its_first_speed_and_a_start_from_rest_reads_the_last(twin):
    ramp = _with_drive(twin, SpeedProfile.ramp(2 * math.pi * 40.0, 1.0, 0.5,
                                               2 * math.pi * 25.0))
    assert drive_speed(ramp, 0.49) == pytest.approx(25.0)
    assert drive_speed(ramp, 1.0) == pytest.approx(32.5)
    assert drive_speed(ramp) == pytest.approx(40.0)
    step = _with_drive(twin, SpeedProfile.step(2 * math.pi * 30.0))
    assert drive_speed(step, -0.01) == pytest.approx(30.0)  # not yet turning: where it goes


def test_a_twin_without_a_drive_asks_for_the_speed(twin):
    bare = eqx.tree_at(lambda t: t.parts, twin,
                       tuple(p for p in twin.parts if not isinstance(p, DrivePart)))
    with pytest.raises(SolverError, match="f_sun"):
        drive_speed(bare)
    stopped = _with_drive(twin, SpeedProfile.constant(0.0))
    with pytest.raises(SolverError, match="f_sun"):
        drive_speed(stopped)


def test_the_grid_and_step_limit_in_closed_form(twin):
    daq = DAQ(sample_rate=5000.0)
    fs_hi, taps, ts = daq_grid(0.1, 0.02, daq)
    half = (len(taps) - 1) // 2
    assert fs_hi == 5000.0 * daq.oversample
    assert len(ts) == 500 * daq.oversample + 2 * half
    assert ts[half] == pytest.approx(0.02) and np.allclose(np.diff(ts), 1 / fs_hi)
    gs = preset("paper-sim").gear_set()
    f_mesh = 30.0 * gs.z_sun * gs.z_ring / (gs.z_sun + gs.z_ring)
    assert step_limit(twin, 30.0, SolverOptions()) == pytest.approx(0.1 / f_mesh)
    assert step_limit(twin, 30.0, SolverOptions(dtmax=1e-5)) == 1e-5
