"""Teeth that part: the least mesh deflection of a simulation against the static deflection
under load, and calibration's contact rows (docs/calibration.md, "Teeth that part").

A transmission error subtracted from every ring mesh's deflection moves the deflection only
by the part the gears cannot follow: on the paper's gearbox (f_m ≈ 500 Hz, far below its mesh
modes) one of 30 times the static deflection at f_m leaves the least deflection at half the
mean, and one of 150 times parts the teeth (100 times: −0.007, measured). The contact rows of the calibration's
residuals are zero while the first-order least deflection stays above zero and grow linearly
below it."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from dtwin.identify.calibrate import contact_margin
from dtwin.identify.calibration_model import CONTACT_TOL, _contact_rows, _Data
from dtwin.simulation.simulate import simulate
from dtwin.spec import load_spec, preset, spec_to_dict
from dtwin.spec.build import build_twin, daq_from_spec


def _margin(spec, te: float):
    data = spec_to_dict(spec)
    data.pop("source", None)
    data["mesh"]["excitation_ring_cos"] = [te]
    data["mesh"]["excitation_ring_sin"] = [0.0]
    s = load_spec(data)
    res = simulate(build_twin(s), duration=0.1, daq=daq_from_spec(s), discard=0.1)
    return res, contact_margin(res)


def test_a_transmission_error_beyond_the_static_deflection_parts_the_teeth():
    spec = preset("paper-sim")
    res, healthy = _margin(spec, 0.0)
    static = float(np.mean(np.asarray(res.outputs["deflection_ring_planet"])))
    assert static > 0
    # the stiffness waveform alone moves the deflection by far less than its mean
    assert 0.3 < healthy < 1.0, healthy
    least = np.asarray(res.outputs["least_deflection_ring_planet"])
    mean = np.asarray(res.outputs["deflection_ring_planet"])
    assert np.all(least <= mean + 1e-18)  # the least over the planets, sample by sample
    _, followed = _margin(spec, 30.0 * static)
    assert 0 < followed < healthy, (followed, healthy)
    _, parted = _margin(spec, 150.0 * static)
    assert parted < 0, parted


def _data(d0, J, theta_lin, mean):
    z = jnp.zeros((1, 2))
    return _Data(Z0=z.astype(complex), JZ=jnp.zeros((1, 2, J.shape[1]), complex),
                 theta_lin=jnp.asarray(theta_lin), A=z, F=z, S=z, W=z, B=jnp.zeros((2, 1)),
                 prior_sd=jnp.ones(J.shape[1]), smooth=1.0, frf_prior=1.0,
                 contact_d0=jnp.asarray(d0), contact_J=jnp.asarray(J),
                 contact_scale=CONTACT_TOL * mean)


def test_contact_rows_are_zero_in_contact_and_linear_below_it():
    mean = 5e-7
    J = np.array([[1e-8, 0.0], [0.0, -2e-8]])
    data = _data([2e-7, 1e-7], J, [0.0, 0.0], mean)
    assert np.all(np.asarray(_contact_rows(jnp.zeros(2), data)) == 0.0)
    # θ moves the second sample's deflection to 1e-7 - 2e-8 * 10 = -1e-7: one row of
    # 1e-7 / (CONTACT_TOL mean) = 10, the first sample still in contact
    rows = np.asarray(_contact_rows(jnp.array([0.0, 10.0]), data))
    np.testing.assert_allclose(rows, [0.0, 1e-7 / (CONTACT_TOL * mean)])
    # a linearisation elsewhere: the rows follow d0 + J (θ - θ_lin)
    data2 = _data([-5e-8, 1e-7], J, [1.0, 0.0], mean)
    np.testing.assert_allclose(np.asarray(_contact_rows(jnp.array([1.0, 0.0]), data2)),
                               [5e-8 / (CONTACT_TOL * mean), 0.0])
    assert np.asarray(_contact_rows(jnp.zeros(2), _data([], np.zeros((0, 2)), [0.0, 0.0],
                                                         mean))).size == 0


def _result(margin):
    from dtwin.identify.calibration_result import CalibrationResult
    from dtwin.identify.gap import GapResult

    g = GapResult(1.0, {"all": 1.0}, {"all": 10})
    spec = {"calibration": {} if margin is None else {"contact_margin": margin}}
    z = np.zeros(2)
    return CalibrationResult(spec, [], 30.0, GapResult(8.0, {"all": 8.0}, {"all": 10}), g, g,
                             z, z, z, z, 0.1, ["baseline-1.csv"])


def test_a_calibration_says_when_its_twins_teeth_part():
    parted, kept, unknown = _result(-1.77), _result(0.73), _result(None)
    assert parted.teeth_part and parted.contact_margin == -1.77
    assert not kept.teeth_part and not unknown.teeth_part and unknown.contact_margin is None
    assert parted.to_dict()["teeth_part"] and parted.to_dict()["contact_margin"] == -1.77
    assert "teeth part every mesh cycle" in parted.table()
    assert "teeth part" not in kept.table()
