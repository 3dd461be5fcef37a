"""Periodic steady state (issue #21, lever 2): `dtwin.simulation.periodic` and `SolverOptions(periodic="auto")`.

Checked against things outside the tiling: the hunting period and each part's gear-set period
against a brute-force search over the gear positions, the rigid advance against the simulated
shaft angles; the tiled record against the
full time-stepping of the whole record (an independent computation of the same samples), its
spectral lines and its forward-mode Jacobian; the cases where the tiling must not be used.

Cheap settings: torsional twin at 60 Hz input speed (hunting period 0.57 s; the gear set's
period one mesh cycle healthy, 21 with a sun fault), 1 s records.
"""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dtwin.model.faults import MissingTooth
from dtwin.simulation.periodic import (
    hunting_cycles,
    hunting_period,
    mechanical_cycles,
    mechanical_period,
    periodic_reason,
    rigid_advance,
    shaft_turns,
)
from dtwin.simulation.simulate import DAQ, SolverOptions, periodic_plan, simulate
from dtwin.spec import preset
from dtwin.spec.build import build_twin

F_SUN = 60.0
DURATION = 1.0
DISCARD = 0.05
PERIODIC = SolverOptions(periodic="auto")
#: The records compared with the whole record's integration are sampled 8 times the DAQ rate:
#: at the default 4 the twin's point samples alias the mesh forces' 20th harmonic (20 kHz at
#: 60 Hz input) onto the carrier's lines; the whole record's solve passes that alias through
#: its housing high-pass (its filter state sees the continuous force), the tiled record's
#: filter, applied to the samples, cancels it (8e-4 of the rms apart, against 4e-6 at 8 times).
DAQ8 = DAQ(oversample=8)


def _with_teeth(twin, zs, zp, zr):
    lp = dataclasses.replace(twin.lp, z_sun=zs, z_planet=zp, z_ring=zr)
    return eqx.tree_at(lambda t: t.lp, twin, lp)


def _search_cycles(zs, zp, zr, planet: bool) -> int:
    """Smallest number of mesh cycles after which the carrier is back relative to the ring (a
    whole carrier turn: zr cycles), the sun relative to the carrier (zs cycles) and, with a
    planet fault, the planet relative to the carrier (zp cycles): found by stepping."""
    n = 1
    while True:
        if n % zr == 0 and n % zs == 0 and (not planet or n % zp == 0):
            return n
        n += 1


@pytest.fixture(scope="module")
def spec():
    return preset("paper-sim")


@pytest.fixture(scope="module")
def twins(spec):
    from dtwin.model.parts.housing_resonance import HousingResonance
    from dtwin.model.parts.mount_path import MountPath

    def faulty(where):
        return build_twin(spec, kind="torsional", f_sun=F_SUN,
                          faults=(MissingTooth(0.5, location=where),))

    # a housing mode in the sensor path: a second output filter, resonant (Q = 10) in the band
    housing = faulty("sun").with_parts(HousingResonance(jnp.asarray(1.0), jnp.asarray(1500.0),
                                                        jnp.asarray(0.05)))
    # a line through the housing's mounts: observed at each sample's own time, it does not
    # move the gears and so does not break the gear set's period
    mount = faulty("sun").with_parts(MountPath(jnp.asarray(0.5), jnp.asarray(0.2), f=2.1))
    return {"healthy": build_twin(spec, kind="torsional", f_sun=F_SUN),
            "sun fault": faulty("sun"), "ring fault": faulty("ring"),
            "planet fault": faulty("planet"), "housing mode": housing, "mount path": mount}


#: mesh cycles of the gear set's period on 21/30/81 (`mechanical_cycles`): the sun back
#: relative to the carrier after Zs cycles, a planet after Zp, the carrier relative to the
#: ring after Zr; the planet-pass window of the sensor does not count
GEAR_SET_CYCLES = {"healthy": 1, "sun fault": 21, "ring fault": 81, "planet fault": 30,
                   "housing mode": 21, "mount path": 21}


@pytest.fixture(scope="module")
def records(twins):
    out = {}
    for name, tw in twins.items():
        full = simulate(tw, duration=DURATION, f_sun=F_SUN, discard=DISCARD, daq=DAQ8)
        tiled = simulate(tw, duration=DURATION, f_sun=F_SUN, discard=DISCARD, daq=DAQ8,
                         solver=PERIODIC)
        out[name] = (full, tiled)
    return out


@pytest.mark.parametrize("teeth", [(21, 30, 81), (21, 31, 84), (16, 24, 64), (13, 19, 53)])
@pytest.mark.parametrize("where", ["sun", "planet"])
def test_hunting_period_closed_form(spec, teeth, where):
    zs, zp, zr = teeth
    tw = _with_teeth(build_twin(spec, kind="torsional", faults=(MissingTooth(0.5, location=where),)),
                     zs, zp, zr)
    cycles = hunting_cycles(tw)
    assert cycles == _search_cycles(zs, zp, zr, planet=where == "planet")
    # T = cycles / f_mesh, f_mesh = Zr f_carrier, f_carrier = f_sun Zs / (Zs + Zr)
    f_mesh = zr * 30.0 * zs / (zs + zr)
    assert float(hunting_period(tw, 30.0)) == pytest.approx(cycles / f_mesh, rel=1e-12)
    sun, car = shaft_turns(tw, cycles)
    assert sun == pytest.approx(30.0 * cycles / f_mesh, abs=1e-9)
    assert car == pytest.approx(30.0 * zs / (zs + zr) * cycles / f_mesh, abs=1e-9)


def test_hunting_period_paper_figures(spec):
    tw = build_twin(spec, kind="torsional", faults=(MissingTooth(0.5, location="sun"),))
    assert float(hunting_period(tw, 30.0)) == pytest.approx(1.133, abs=1e-3)
    pl = _with_teeth(build_twin(spec, kind="torsional",
                                faults=(MissingTooth(0.5, location="planet"),)), 21, 31, 84)
    assert float(hunting_period(pl, 30.0)) == pytest.approx(5.17, abs=0.01)


@pytest.mark.parametrize("case", sorted(GEAR_SET_CYCLES))
def test_tiled_record_equals_full(records, twins, case):
    full, tiled = records[case]
    assert full.method == "full" and tiled.method == "periodic"
    assert float(tiled.periodic_defect) < 1e-3
    # fewer solver steps: one settling time and one period of the gear set instead of the
    # record (the hunting period: 567 mesh cycles, 5670 with the planet fault)
    T = float(mechanical_period(twins[case]))
    assert T == pytest.approx(float(mechanical_period(twins[case], F_SUN)), rel=1e-12)
    assert mechanical_cycles(twins[case]) == GEAR_SET_CYCLES[case]
    assert int(tiled.num_steps) < (0.1 + T + 0.02) / DURATION * 1.05 * int(full.num_steps)
    x, y = np.asarray(full.signal), np.asarray(tiled.signal)
    assert x.shape == y.shape
    assert np.sqrt(np.mean((y - x) ** 2) / np.mean(x**2)) < 1e-4
    # the shaft angles: the full simulation's own advance over one period of the gear set is
    # the rigid rotation's (a fraction of a turn), which the tiling adds to every later sample
    fs = full.sample_rate
    t = np.asarray(full.time)
    i0 = int(np.searchsorted(t, 0.2))
    for key, advance in zip(("theta_sun", "theta_carrier"),
                            rigid_advance(twins[case], mechanical_cycles(twins[case])),
                            strict=True):
        a = np.asarray(full.outputs[key])
        adv = np.interp(t[i0] + T, t, a) - a[i0]
        assert adv == pytest.approx(advance, rel=1e-6)
        assert np.max(np.abs(np.asarray(tiled.outputs[key]) - a)) < 1e-6
    # spectral lines h f_mesh + k f_carrier within 0.1 dB
    n = x.size
    w = np.hanning(n)
    X, Y = np.abs(np.fft.rfft(x * w)), np.abs(np.fft.rfft(y * w))
    f = np.fft.rfftfreq(n, 1 / fs)
    f_c = F_SUN * 21 / (21 + 81)
    f_m = 81 * f_c
    top = X.max()
    checked = 0
    for h in range(1, 5):
        for k in range(-8, 9):
            fl = h * f_m + k * f_c
            if fl >= 0.45 * fs:
                continue
            i = int(np.argmin(np.abs(f - fl)))
            i = i - 1 + int(np.argmax(X[i - 1 : i + 2]))
            if X[i] < top * 1e-3:  # lines within 60 dB of the strongest
                continue
            assert abs(20 * np.log10(Y[i] / X[i])) < 0.1, (h, k)
            checked += 1
    assert checked >= 6


def test_jacobian_of_tiled_record_equals_full(spec, records):
    from dtwin.identify.fit import make_problem

    rec = records["sun fault"][0].to_record()
    free = ["sun_fault", "k_sun_planet"]
    jacs = {}
    for mode in ("off", "auto"):
        prob, _ = make_problem(rec, spec, free, f_sun=F_SUN, periodic=mode, oversample=8)

        @eqx.filter_jit
        def jac(theta, prob):
            return jax.jacfwd(lambda th: prob.signals(th)[0][0])(theta)

        jacs[mode] = np.asarray(jac(jnp.zeros(len(free)), prob))
    a, b = jacs["off"], jacs["auto"]
    for j in range(len(free)):
        col = a[:, j]
        assert np.sqrt(np.mean((b[:, j] - col) ** 2) / np.mean(col**2)) < 1e-3, free[j]


def test_falls_back(spec, twins, records):
    from dtwin.identify.residuals import drive_at

    tw = twins["sun fault"]
    fs_hi = 20_000.0
    # a run-up: the speed is not constant
    ramp = drive_at(tw, 20.0, 40.0, duration=4.0, discard=0.05)
    assert "not constant" in periodic_reason(ramp)
    T, why = periodic_plan(ramp, 20.0, 0.0, 4.0, PERIODIC, fs_hi)
    assert T is None and why.startswith("full")
    # a start from rest
    T, why = periodic_plan(tw, F_SUN, 0.0, 4.0, PERIODIC, fs_hi, start="rest")
    assert T is None and "rest" in why
    # a planet fault on 21/31/84: its hunting period (5.2 s) is longer than the record, the
    # gear set's (Zp = 31 mesh cycles, 0.06 s at 30 Hz) is not
    pl = _with_teeth(build_twin(spec, kind="torsional",
                                faults=(MissingTooth(0.5, location="planet"),)), 21, 31, 84)
    T, why = periodic_plan(pl, 30.0, 0.0, 4.0, PERIODIC, fs_hi)
    assert why == "periodic" and T == pytest.approx(31 / (84 * 30.0 * 21 / 105))
    # a record too short for the settling time and one period (0.021 s at 60 Hz)
    T, why = periodic_plan(tw, F_SUN, 0.0, 0.15, PERIODIC, fs_hi)
    assert T is None and "period" in why
    # the plan of the records above: tiled
    T, why = periodic_plan(tw, F_SUN, 0.0, DURATION, PERIODIC, fs_hi)
    assert why == "periodic" and T == pytest.approx(float(mechanical_period(tw)))
    # a periodicity check that fails: integrated in full, the record is the full one
    strict = dataclasses.replace(PERIODIC, periodic_tol=1e-12)
    r = simulate(tw, duration=DURATION, f_sun=F_SUN, discard=DISCARD, daq=DAQ8, solver=strict)
    assert r.method.startswith("full (periodic: the signal's rms change")
    np.testing.assert_array_equal(np.asarray(r.signal), np.asarray(records["sun fault"][0].signal))


def test_inert_parts_keep_the_hunting_period(spec):
    """Parts that cannot break the period at their present values: a planet fault of severity
    0 adds no planet dependence (discovery's extended model at θ = 0), a fluctuating load of
    amplitude 0 is constant, a motor's torque ripple follows the sun's angle (the sun turns a
    whole number of times over the period). Checked against the cycle count found by stepping."""
    from dtwin.model.motor.drive import LoadPart
    from dtwin.model.motor.loads import FluctuatingLoad
    from dtwin.model.motor.torque_ripple import TorqueRipple

    def planet_fault(sev):
        return _with_teeth(build_twin(spec, kind="torsional",
                                      faults=(MissingTooth(sev, location="planet"),)), 21, 31, 84)

    assert hunting_cycles(planet_fault(0.0)) == _search_cycles(21, 31, 84, planet=False)
    assert hunting_cycles(planet_fault(0.3)) == _search_cycles(21, 31, 84, planet=True)
    tw = build_twin(spec, kind="torsional")
    base = hunting_cycles(tw)
    assert base == _search_cycles(21, 30, 81, planet=False)
    ripple = eqx.tree_at(lambda t: t.parts, tw,
                         tuple(tw.parts) + (TorqueRipple(jnp.asarray(0.1), jnp.asarray(0.0)),))
    assert hunting_cycles(ripple) == base
    i = next(k for k, p in enumerate(tw.parts) if isinstance(p, LoadPart))

    def with_fluctuation(amp):
        return eqx.tree_at(lambda t: t.parts[i].load, tw, FluctuatingLoad(40.0, amp, 2.1))

    assert hunting_cycles(with_fluctuation(0.0)) == base
    assert hunting_cycles(with_fluctuation(1.0)) is None
    assert "varies in time" in periodic_reason(with_fluctuation(1.0))


def test_periodicity_tolerance_follows_the_solver_tolerance():
    """The defect holds the integrator's own error of two periods, so the default tolerance
    grows with rtol: 1e-3 up to rtol 2e-5, 50 rtol above; an explicit value is kept."""
    assert SolverOptions().periodic_tolerance == 1e-3
    assert SolverOptions(rtol=1e-4, atol=1e-4).periodic_tolerance == pytest.approx(5e-3)
    assert SolverOptions(rtol=1e-4, periodic_tol=2e-4).periodic_tolerance == 2e-4
    with pytest.raises(ValueError):
        SolverOptions(periodic_tol=-1.0)


def test_a_slowly_settling_twin_is_tiled_after_a_longer_settle():
    """Where one period after 0.1 s is not periodic, `simulate` settles longer before it gives
    up the tiling, and the tiled record then matches the whole record's integration."""
    from _gearboxes import SLOW_SETTLING

    from dtwin.spec import load_spec
    from dtwin.spec.build import daq_from_spec

    spec = load_spec(SLOW_SETTLING)
    twin = build_twin(spec, kind="torsional", f_sun=20.0)
    daq = daq_from_spec(spec, snr_db=None)
    kw = dict(duration=1.2, f_sun=20.0, daq=daq, discard=0.3)
    unchecked = simulate(twin, solver=PERIODIC, check=False, **kw)
    # the default settling time leaves a transient (the case this test is about)
    assert float(unchecked.periodic_defect) > PERIODIC.periodic_tolerance
    tiled = simulate(twin, solver=PERIODIC, **kw)
    assert tiled.method == "periodic", tiled.method
    assert float(tiled.periodic_defect) <= PERIODIC.periodic_tolerance
    full = np.asarray(simulate(twin, solver=SolverOptions(), **kw).signal)
    y = np.asarray(tiled.signal)
    assert np.std(y - full) < 2e-4 * np.std(full), np.std(y - full) / np.std(full)
    # the unsettled tiling is what the check protects against: far off the whole record
    assert np.std(np.asarray(unchecked.signal) - full) > 1e-3 * np.std(full)
    # a record too short for the longer settling time is integrated in full, once
    kw = dict(kw, duration=0.6, discard=0.05)
    short = simulate(twin, solver=PERIODIC, **kw)
    assert short.method.startswith("full (periodic: the signal's rms change"), short.method
    whole = np.asarray(simulate(twin, solver=SolverOptions(), **kw).signal)
    np.testing.assert_allclose(np.asarray(short.signal), whole, rtol=0,
                               atol=1e-9 * np.std(whole))


def test_gear_set_period_of_each_part(spec):
    """`mechanical_cycles` of each part against the cycle count found by stepping: the sun's
    run-out turns with the sun relative to the carrier (Zs), a torque ripple of electrical order
    h p with the sun's absolute angle, an inert part adds nothing, a sensor path whose states
    act back on the gear set has no known period."""
    from fractions import Fraction

    from dtwin.model.motor.torque_ripple import TorqueRipple
    from dtwin.model.parts.imperfections import SunEccentricity
    from dtwin.model.parts.transfer_path import AbstractTransferPath

    tw = build_twin(spec, kind="torsional")
    assert mechanical_cycles(tw) == 1
    assert mechanical_cycles(tw.with_parts(SunEccentricity(jnp.asarray(2e-7)))) == 21
    assert mechanical_cycles(tw.with_parts(SunEccentricity(jnp.asarray(0.0)))) == 1

    def stepped(order):  # least n with n * order * (Zs + Zr) / (Zs Zr) an integer
        n = 1
        while (Fraction(n * order * 102, 21 * 81)).denominator != 1:
            n += 1
        return n

    for pole_pairs, harmonic in ((4, 6), (2, 1), (3, 2)):
        ripple = tw.with_parts(TorqueRipple(jnp.asarray(0.1), jnp.asarray(0.0),
                                            pole_pairs=pole_pairs, harmonic=harmonic))
        assert mechanical_cycles(ripple) == stepped(pole_pairs * harmonic)
        assert hunting_cycles(ripple) % mechanical_cycles(ripple) == 0

    class Feedback(AbstractTransferPath):  # states of its own, not declared a one-way filter
        @property
        def aux_size(self):
            return 1

        def acceleration(self, twin, t, q, qdot, qddot, mesh, aux):
            return aux[0]

    odd = tw.with_parts(Feedback())
    assert mechanical_cycles(odd) is None
    from dtwin.simulation.periodic import mechanical_reason

    assert "not a filter of the gear set's motion" in mechanical_reason(odd)
    T, why = periodic_plan(odd, 30.0, 0.0, 4.0, PERIODIC, 20_000.0)
    assert T is None and "not a filter" in why
