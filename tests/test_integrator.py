"""`dtwin.simulation.integrator.UnrolledTsit5` is diffrax's Tsit5 with the stages written out.

Checks: on the twin (translational, sun fault: the stiffest case) it takes the same steps and
returns the same record as `diffrax.Tsit5` to rounding (integral-only step control), and to the
tolerance with the default PI control; its forward-mode derivative is the same;
under `vmap` (the fits' batched starts) each member equals its own unbatched solve; on a damped
oscillator it converges at 5th order to the exact solution, and its dense output (saving at
`ts` between steps) is Tsit5's 5th-order interpolant.
"""

from __future__ import annotations

from dataclasses import replace

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dtwin.model.faults import MissingTooth
from dtwin.simulation.integrator import UnrolledTsit5
from dtwin.simulation.simulate import SolverOptions, simulate
from dtwin.spec import preset
from dtwin.spec.build import build_twin


@pytest.fixture(scope="module")
def twin():
    return build_twin(preset("paper-sim"), kind="translational",
                      faults=(MissingTooth(0.5, location="sun", tooth=0),))


def _run(tw, unrolled, **kw):
    return simulate(tw, duration=0.2, f_sun=30.0, solver=SolverOptions(unrolled=unrolled, **kw),
                    **({"check": False} if kw.get("adjoint") else {}))


def test_same_steps_and_record_as_diffrax_tsit5(twin):
    # integral-only control: the step sequence depends on this step's error only, so rounding
    # differences (the stages are summed in another order) cannot change it. The dynamics then
    # carry those rounding differences along: over this 0.2 s record they stay near 1e-9 of the
    # signal's maximum, except as the missing tooth leaves and enters mesh, where a
    # rounding-sized shift of the contact's kink gives a spike of up to ~2e-6 (the DAQ filter,
    # flat to 0.45 fs, passes it; a filter flat to 0.3 fs leaves 2e-8). One tableau coefficient
    # off by 1e-4 of itself changes the steps and the record by ~1e-2
    a, b = _run(twin, True, pcoeff=0.0, icoeff=1.0), _run(twin, False, pcoeff=0.0, icoeff=1.0)
    assert int(a.num_steps) == int(b.num_steps) > 1000
    x, y = np.asarray(a.signal), np.asarray(b.signal)
    assert np.median(np.abs(x - y)) <= 1e-8 * np.max(np.abs(y))
    assert np.max(np.abs(x - y)) <= 1e-5 * np.max(np.abs(y))
    # the default PI controller carries the previous error forward: rounding can move a step
    # (a few in 10^4), and the records then agree to the tolerance, not to rounding
    a, b = _run(twin, True), _run(twin, False)
    assert abs(int(a.num_steps) - int(b.num_steps)) <= 0.01 * int(b.num_steps)
    x, y = np.asarray(a.signal), np.asarray(b.signal)
    assert np.sqrt(np.mean((x - y) ** 2)) <= 1e-4 * np.sqrt(np.mean(y**2))


# integral-only control below: comparisons to rounding (see the first test)
I_CONTROL = dict(pcoeff=0.0, icoeff=1.0)


def test_forward_derivative_equals_diffrax_tsit5(twin):
    def level(k, unrolled):
        tw = eqx.tree_at(lambda t: t.lp, twin, replace(twin.lp, k_sun_planet=k))
        x = simulate(tw, duration=0.1, f_sun=30.0, check=False,
                     solver=SolverOptions(unrolled=unrolled, adjoint="forward", **I_CONTROL)).signal
        return jnp.sqrt(jnp.mean(x**2))

    k0 = jnp.asarray(float(twin.lp.k_sun_planet))
    _, da = jax.jvp(lambda k: level(k, True), (k0,), (jnp.ones(()),))
    _, db = jax.jvp(lambda k: level(k, False), (k0,), (jnp.ones(()),))
    assert float(da) != 0.0
    assert abs(float(da) - float(db)) <= 1e-7 * abs(float(db))


# I control: equal to rounding as carried by the dynamics (~6e-9 of the maximum measured over
# these 0.05 s; see the first test). PI control (default): rounding moves the accepted steps,
# so members differ from their own solves at the solver's tolerance, in proportion to it
# (measured 0.8-1.2e-4 of the maximum at rtol 1e-5, 0.8-1.2e-5 at 1e-6); members that mixed
# each other's data would differ by ~1e-1 (the last assertion).
@pytest.mark.parametrize("control,tol", [(I_CONTROL, 1e-7), ({}, 3e-4)])
def test_vmap_members_equal_their_own_solves(twin, control, tol):
    ks = jnp.asarray([0.9, 1.1]) * float(twin.lp.k_sun_planet)

    def sig(k):
        tw = eqx.tree_at(lambda t: t.lp, twin, replace(twin.lp, k_sun_planet=k))
        return simulate(tw, duration=0.05, f_sun=30.0, check=False,
                        solver=SolverOptions(**control)).signal

    batched = np.asarray(jax.vmap(sig)(ks))
    for i in range(2):
        single = np.asarray(sig(ks[i]))
        assert np.max(np.abs(batched[i] - single)) <= tol * np.max(np.abs(single))
    assert np.max(np.abs(batched[0] - batched[1])) > 1e-3 * np.max(np.abs(batched[0]))


def _oscillator(solver, dt, ts):
    w, z = 2 * np.pi * 50.0, 0.05

    def vf(t, y, args):
        return jnp.stack([y[1], -(w**2) * y[0] - 2 * z * w * y[1]])

    sol = diffrax.diffeqsolve(diffrax.ODETerm(vf), solver, 0.0, 0.1, dt, jnp.asarray([1.0, 0.0]),
                              saveat=diffrax.SaveAt(ts=ts), max_steps=100_000)
    wd = w * np.sqrt(1 - z**2)
    exact = np.exp(-z * w * ts) * (np.cos(wd * ts) + z * w / wd * np.sin(wd * ts))
    return np.asarray(sol.ys[:, 0]), exact


def test_fifth_order_and_dense_output_on_a_damped_oscillator():
    ts = np.linspace(0.0, 0.1, 37)  # not on the step grid: the interpolant is used
    errs = []
    for dt in (1e-3, 5e-4):
        ours, exact = _oscillator(UnrolledTsit5(), dt, ts)
        ref, _ = _oscillator(diffrax.Tsit5(), dt, ts)
        assert np.max(np.abs(ours - ref)) <= 1e-13
        errs.append(np.max(np.abs(ours - exact)))
    order = np.log2(errs[0] / errs[1])
    assert 4.5 <= order <= 6.0


def test_default_tolerance_accuracy(twin):
    """The defaults' sensor error against a tight solution (rtol = atol = 1e-9), the figure that
    `SolverOptions` documents: rms within 1e-4 of the signal's rms (measured 4.5e-5 over 1 s),
    and the error's largest spectral line >= 80 dB below the signal's strongest (measured
    ~-98 dB): far below the sidebands and forbidden lines the dynamics tests read."""
    a = simulate(twin, duration=0.5, f_sun=30.0)
    b = simulate(twin, duration=0.5, f_sun=30.0,
                 solver=SolverOptions(rtol=1e-9, atol=1e-9, max_steps=2_000_000))
    x, y = np.asarray(a.signal), np.asarray(b.signal)
    assert np.sqrt(np.mean((x - y) ** 2)) <= 1e-4 * np.sqrt(np.mean(y**2))
    w = np.hanning(len(y))
    err_line = np.abs(np.fft.rfft((x - y) * w)).max()
    assert 20 * np.log10(err_line / np.abs(np.fft.rfft(y * w)).max()) <= -80.0
    # a coarser rate scale (velocities weighed less) takes fewer steps, a finer one more
    c = simulate(twin, duration=0.5, f_sun=30.0, solver=SolverOptions(rate_scale_hz=1000.0))
    assert int(c.num_steps) > 1.2 * int(a.num_steps)


def test_solver_options_reject_bad_values():
    for kw in (dict(rtol=0.0), dict(atol=-1.0), dict(rate_scale_hz=0.0), dict(rate_scale_hz=float("nan"))):
        with pytest.raises(ValueError, match="must be a positive number"):
            SolverOptions(**kw)
