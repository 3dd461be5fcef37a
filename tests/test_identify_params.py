"""dtwin.identify.params: registry names, transforms, writing values into a twin; and bad inputs that
must fail before any simulation (issue 7, "bad input gives a clear error before any compute")."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dtwin.errors import ParameterError, RecordError
from dtwin.identify.params import ParameterSet, current_value
from dtwin.io.record import Record
from dtwin.model.motor.drive import LoadPart
from dtwin.model.parts.local_fault import LocalFault
from dtwin.spec import preset
from dtwin.spec.build import build_twin

FREE = ["k_sun_planet", "k_ring_planet", "zeta_mesh", "sun_fault"]


@pytest.fixture(scope="module")
def twin():
    return build_twin(preset("paper-sim"), kind="torsional")


def test_unknown_name_suggests(twin):
    with pytest.raises(ParameterError, match="k_sun_planet"):
        ParameterSet.build(["k_sun_plant"], twin)
    with pytest.raises(ParameterError, match="unknown parameter"):
        ParameterSet.build("k_sun_planet,zeta_mush", twin)


def test_tie_and_member_refused(twin):
    with pytest.raises(ParameterError, match="ties"):
        ParameterSet.build(["zeta_mesh", "zeta_sun_planet"], twin)
    with pytest.raises(ParameterError, match="operating point"):
        ParameterSet.build(["f_sun"], twin)


def test_transforms_round_trip_and_bounds(twin):
    ps = ParameterSet.build(FREE, twin, initial={"sun_fault": 0.3})
    assert ps.transforms == ("log", "log", "logit", "logit")
    v0 = np.asarray(ps.values(np.zeros(4)))
    # theta = 0 is the initial value: the spec's ISO stiffness, its damping ratio, the given severity
    np.testing.assert_allclose(v0, [float(twin.lp.k_sun_planet), float(twin.lp.k_ring_planet),
                                    0.07, 0.3], rtol=1e-12)
    # log: theta is the relative change, exp(0.3) = +35 %
    np.testing.assert_allclose(np.asarray(ps.values(np.array([0.3, 0, 0, 0])))[0] / v0[0],
                               np.exp(0.3), rtol=1e-12)
    # bounded parameters never leave their bounds, whatever theta
    for t in (-40.0, 40.0):
        v = np.asarray(ps.values(np.full(4, t)))
        assert 0.0 <= v[2] <= 0.5 and 0.0 <= v[3] <= 1.0
    vals = {"k_sun_planet": 2.5e8, "k_ring_planet": 1.9e8, "zeta_mesh": 0.1, "sun_fault": 0.62}
    np.testing.assert_allclose(np.asarray(ps.values(ps.theta(vals))), list(vals.values()),
                               rtol=1e-10)
    # the derivative of the transform against a finite difference
    th = ps.theta(vals)
    d = np.asarray(ps.dvalues_dtheta(th))
    h = 1e-6
    fd = [(np.asarray(ps.values(th + h * e)) - np.asarray(ps.values(th - h * e)))[i] / (2 * h)
          for i, e in enumerate(np.eye(4))]
    np.testing.assert_allclose(d, fd, rtol=1e-6)


def test_apply_sets_fields_ties_faults_load(twin):
    ps = ParameterSet.build(FREE + ["load_torque", "sensor_gain"], twin,
                            initial={"sun_fault": 0.2})
    tw = ps.prepare(twin)
    faults = [p for p in tw.parts if isinstance(p, LocalFault)]
    assert len(faults) == 1 and faults[0].fault.location == "sun"
    assert float(faults[0].fault.severity) == 0.0  # added healthy: bit-identical dynamics
    vals = jnp.asarray([2.0e8, 3.0e8, 0.11, 0.45, 80.0, 2.0])
    out = ps.apply(tw, vals)
    assert float(out.lp.k_sun_planet) == 2.0e8 and float(out.lp.k_ring_planet) == 3.0e8
    assert float(out.lp.zeta_sun_planet) == 0.11 == float(out.lp.zeta_ring_planet)
    assert current_value(out, "sun_fault") == 0.45
    assert float(next(p for p in out.parts if isinstance(p, LoadPart)).load.torque_value) == 80.0
    assert float(ps.gain(vals)) == 2.0
    # apply is differentiable: d k_sun_planet / d theta_0 = k (log transform)
    g = jax.grad(lambda t: ps.apply(tw, ps.values(t)).lp.k_sun_planet)(jnp.zeros(6))
    np.testing.assert_allclose(float(g[0]), float(twin.lp.k_sun_planet), rtol=1e-12)
    text = ps.summary()
    for n in FREE:
        assert n in text


def test_priors_and_fixed(twin):
    ps = ParameterSet.build(["k_sun_planet"], twin, fixed={"zeta_mesh": 0.05},
                            priors={"k_sun_planet": (2e8, 2e7)})
    tw = ps.prepare(twin)
    assert float(tw.lp.zeta_sun_planet) == 0.05
    r = ps.prior_residuals(jnp.asarray([2.2e8]))
    np.testing.assert_allclose(np.asarray(r), [1.0])
    with pytest.raises(ParameterError, match="both free and fixed"):
        ParameterSet.build(["k_sun_planet"], twin, fixed={"k_sun_planet": 1e8})


# --------------------------------------------------------------------------- bad inputs
def _record(n=5000, fs=5000.0, f_sun=30.0):
    t = np.arange(n) / fs
    x = np.sin(2 * np.pi * 500.3 / 30.0 * f_sun * t) + 0.01 * np.random.default_rng(0).normal(size=n)
    return Record(x[None, :], fs, ("vibration",), ("m/s^2",))


@pytest.fixture
def no_compute(monkeypatch):
    """Any simulation during the test fails it: errors must come before compute."""
    import dtwin.identify.residuals as res

    def boom(*a, **k):
        raise AssertionError("simulated although the input was bad")

    monkeypatch.setattr(res, "_simulate_jittable", boom)


@pytest.mark.parametrize(
    "make, error, match",
    [
        (lambda: _record(n=1000), RecordError, "too short to resolve the carrier sidebands"),
        (lambda: _record(fs=1000.0, n=1000), RecordError, "below 2.5"),
        (lambda: Record(np.where(np.arange(5000) == 7, np.nan, _record().data[0])[None, :],
                        5000.0, ("vibration",), ("m/s^2",)), RecordError, "NaN"),
    ],
    ids=["too-short", "rate-too-low", "nan"],
)
def test_bad_records_fail_before_compute(no_compute, make, error, match):
    from dtwin.identify.fit import fit

    with pytest.raises(error, match=match):
        fit(make(), preset("paper-sim"), ["sun_fault"], f_sun=30.0)


def test_unknown_free_name_fails_before_compute(no_compute):
    from dtwin.identify.fit import fit

    with pytest.raises(ParameterError, match="Did you mean"):
        fit(_record(), preset("paper-sim"), ["sun_fualt"], f_sun=30.0)
