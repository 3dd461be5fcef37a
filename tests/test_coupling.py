"""The paper's comparison (issue 6, item 4): traditional model vs the twin with the PMSM in the loop.

What each test compares against:

- structure: the coupled twin built here equals, leaf for leaf, the twin `build_twin` makes from a
  spec with ``[motor] type = "pmsm"``, and differs from the traditional one only in the drive
  (``eqx.tree_equal``);
- steady state with the motor in the loop, over whole carrier periods: the torque balance through
  the gear ratio 1 + Zr/Zs and the energy balance of the coupled ODE (conservation of energy),
  with the gearbox's dissipation computed here from the states by a probe part;
- the sideband rule of docs/references.md §2 for a sun fault (fm + k fs/N + n fc, n ≡ k mod N) and
  the motor-current-signature rule (a torque oscillation at f_x shows at f_e ± f_x in i_a);
- RMS rising with severity in both models, the autodiff sensitivity against the secant slope,
  and the figure + table + JSON of the CLI on short records.

Records are short (torsional model, one to three carrier periods after a 0.05–0.1 s transient
from a steady start); longer and translational forms are marked ``slow``.
"""

from __future__ import annotations

import json
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dtwin import DAQ, build_twin, load_spec, preset, simulate, spec_to_dict
from dtwin.model.faults import MissingTooth
from dtwin.model.gears import characteristic_frequencies
from dtwin.model.motor.drive import DrivePart
from dtwin.model.motor.pmsm import PMSM
from dtwin.model.motor.speed_source import IdealSpeedSource
from dtwin.model.parts.base import AbstractPart
from dtwin.report.drive_comparison import (
    MODELS,
    comparison_twins,
    fault_rms,
    fault_rms_and_slope,
    set_drive_parameters,
    with_severity,
)
from dtwin.signal.spectrum import amplitude_spectrum, noise_floor

F_SUN = 30.0
SPEC = preset("paper-sim")
FREQS = {k: float(v) for k, v in characteristic_frequencies(SPEC.gear_set(), F_SUN).items()}
FM, FC, FS = FREQS["f_mesh"], FREQS["f_carrier"], FREQS["f_sun_fault"]
T_CARRIER = 1.0 / FC
N_PLANETS = 3
RATIO = 1.0 + 81 / 21
LOAD = float(SPEC["operating"]["load_torque"])  # N·m on the carrier
FS_DAQ = 20000.0  # fine enough to integrate powers with mesh harmonics up to 10 kHz


def _drive_index(tw):
    return next(i for i, p in enumerate(tw.parts) if isinstance(p, DrivePart))


@pytest.fixture(scope="module")
def pair():
    return comparison_twins(SPEC, kind="torsional")


# ------------------------------------------------------------------------------ structure
def test_traditional_is_the_twin_with_the_ideal_speed_source(pair):
    trad, coup = pair
    i = _drive_index(trad)
    assert isinstance(trad.parts[i].drive, IdealSpeedSource)
    assert isinstance(coup.parts[i].drive, PMSM)
    # same shaft in both drives, same everything else (lumped parameters, supports, fault,
    # load, sensor, kind, harmonics)
    assert eqx.tree_equal(trad.parts[i].drive.shaft, coup.parts[i].drive.shaft)
    drop = lambda tw: eqx.tree_at(lambda t: t.parts, tw, tw.parts[:i] + tw.parts[i + 1 :])  # noqa: E731
    assert eqx.tree_equal(drop(trad), drop(coup))
    assert jax.tree_util.tree_structure(drop(trad)) == jax.tree_util.tree_structure(drop(coup))
    # both are exactly what the public builder makes from the spec with that [motor] type
    fault = (MissingTooth(0.0, location="sun", tooth=0),)
    for twin, motor in ((trad, "ideal"), (coup, "pmsm")):
        d = spec_to_dict(SPEC)
        d["motor"] = {"type": motor}
        ref = build_twin(load_spec(d), kind="torsional", faults=fault)
        assert eqx.tree_equal(twin, ref)
    # the severity and drive parameters are leaves: replacing them changes nothing else
    t2 = set_drive_parameters(with_severity(coup, 0.7), k_shaft=500.0, speed_bandwidth=5.0)
    assert float(t2.parts[i].drive.shaft.k_shaft) == 500.0
    assert float(t2.parts[i].drive.speed_bandwidth) == 5.0
    assert eqx.tree_equal(drop(with_severity(t2, 0.0)), drop(coup))


# ------------------------------------------------------------------------------ steady state
class PowerProbe(AbstractPart):
    """Observes the gearbox's power flows from the states (torsional model): mesh damping
    ``sum c ddelta^2 sigmoid(delta/s)``, mesh elastic power ``sum k s softplus(delta/s) ddelta``,
    support damping ``q'^T C q'`` and the energies ``q'^T M q' / 2``, ``q^T K q / 2`` (J)."""

    def forces(self, twin, t, q, qdot, aux, mesh):
        s = twin.contact_smoothing
        d = jnp.concatenate([mesh.delta_sp, mesh.delta_rp])
        dd = jnp.concatenate([mesh.ddelta_sp, mesh.ddelta_rp])
        k = jnp.concatenate([mesh.k_sp, mesh.k_rp])
        c = jnp.concatenate([mesh.c_sp, mesh.c_rp])
        K = jnp.zeros((twin.n_dof, twin.n_dof))
        C = jnp.zeros((twin.n_dof, twin.n_dof))
        for p in twin.parts:
            springs = getattr(p, "linear_springs", None)
            if springs is not None:
                k_p, c_p = springs(twin)
                K, C = K + k_p, C + c_p
        qv, qdv = twin.pack(q), twin.pack(qdot)
        out = {
            "power_mesh_damping": jnp.sum(c * dd**2 * jax.nn.sigmoid(d / s)),
            "power_mesh_elastic": jnp.sum(k * s * jax.nn.softplus(d / s) * dd),
            "power_support_damping": qdv @ C @ qdv,
            "energy_kinetic": 0.5 * qdv @ twin.mass_matrix() @ qdv,
            "energy_supports": 0.5 * qv @ K @ qv,
        }
        return None, jnp.zeros(0), out


def _steady_run(coup, severity):
    tw = with_severity(coup, severity).with_parts(PowerProbe())
    daq = DAQ(sample_rate=FS_DAQ, oversample=2, quantity="acceleration")
    res = simulate(tw, duration=3 * T_CARRIER + 3 / FS_DAQ, f_sun=F_SUN, discard=0.1, daq=daq)
    return tw, {k: np.asarray(v) for k, v in res.outputs.items()}, np.asarray(res.signal), \
        np.asarray(res.time)


@pytest.fixture(scope="module")
def coupled_steady(pair):
    """The coupled twin with a whole missing sun tooth, 3 carrier periods after 0.1 s at speed
    (2 periods resolve 3 Hz, too coarse for sun-fault lines 6.2 Hz apart)."""
    return _steady_run(pair[1], 1.0)


def _whole_periods(t):
    """Sample indices spanning the largest whole number of carrier periods from the start."""
    n_per = math.floor((t[-1] - t[0]) / T_CARRIER + 1e-9)
    stop = int(round(n_per * T_CARRIER * FS_DAQ))
    return slice(0, stop + 1), n_per


def _mean(x, t, sl):
    return np.trapezoid(x[sl], t[sl]) / (t[sl][-1] - t[sl][0])


def test_steady_torque_balance_through_the_gear_ratio(coupled_steady):
    tw, out, _, t = coupled_steady
    sl, n_per = _whole_periods(t)
    assert n_per == 3
    drive = tw.parts[_drive_index(tw)].drive
    w = _mean(out["omega_motor"], t, sl)
    assert abs(w - 2 * math.pi * F_SUN) < 1e-6 * w  # the speed loop has no steady error
    t_em = _mean(out["torque_em"], t, sl)
    t_load_sun = LOAD / RATIO
    # mechanical losses between the magnets and the load, as torque at the rotor speed
    p_mech = sum(_mean(out[k], t, sl) for k in (
        "power_friction", "power_shaft_damping", "power_mesh_damping", "power_support_damping",
        "power_mesh_elastic"))
    assert t_em > t_load_sun
    assert abs(t_em - (t_load_sun + p_mech / w)) < 1e-3 * t_em
    # the losses are small: without them the balance holds to 2 %
    assert abs(t_em - t_load_sun) < 0.02 * t_em
    assert float(drive.friction) * w / t_em < 0.02


def test_steady_energy_balance_with_the_motor_in_the_loop(coupled_steady):
    tw, out, _, t = coupled_steady
    sl, _ = _whole_periods(t)
    p_in = _mean(out["power_in"], t, sl)
    p_load = _mean(out["power_load"], t, sl)
    losses = {k: _mean(out[k], t, sl) for k in (
        "power_copper", "power_friction", "power_shaft_damping", "power_mesh_damping",
        "power_support_damping", "power_mesh_elastic")}
    stored = out["energy_stored"] + out["energy_kinetic"] + out["energy_supports"]
    d_stored = (stored[sl][-1] - stored[sl][0]) / (t[sl][-1] - t[sl][0])
    # conservation of energy of the coupled ODE: exact up to quadrature and solver error
    residual = p_in - p_load - sum(losses.values()) - d_stored
    assert abs(residual) < 2e-4 * p_in
    # the form: input electrical power = load power + dissipation, within 1 %
    dissipation = sum(v for k, v in losses.items() if k != "power_mesh_elastic")
    assert abs(p_in - p_load - dissipation) < 0.01 * p_in
    # copper and friction dominate the losses; the gearbox's damping is small but not zero
    assert losses["power_copper"] > losses["power_mesh_damping"] > 0.0


def _line(freqs, amp, f):
    """Largest amplitude within one bin of `f`."""
    df = freqs[1] - freqs[0]
    sel = np.abs(freqs - f) <= 1.01 * df
    return float(np.max(amp[sel]))


def test_sun_fault_lines_survive_with_the_motor_in_the_loop(coupled_steady):
    _, _, x, _ = coupled_steady
    freqs, amp = amplitude_spectrum(x, FS_DAQ, "hann", remove_mean=True)
    fsn = FS / N_PLANETS
    # docs/references.md §2: lines at fm + k fs/N + n fc only for n ≡ k (mod N)
    allowed = [FM + k * fsn + n * FC for k, n in ((1, 1), (1, -2), (-1, -1), (-1, 2))]
    cancelled = [FM + k * fsn + n * FC for k, n in ((1, 0), (-1, 0), (1, -1), (-1, 1))]
    lo = max(_line(freqs, amp, f) for f in cancelled)
    for f in allowed:
        a = _line(freqs, amp, f)
        assert a > 10.0 * lo, f"{f:.1f} Hz: {a:.3g} vs cancelled {lo:.3g}"


def _supply_periods(t, f_e):
    """Sample indices of the largest whole number of supply periods that is also a whole
    number of samples: the supply line then sits on a bin, and with the periodic Hann window
    its 9 A leak into no bin beyond the neighbours (the sidebands are ~1e-4 A)."""
    step = math.lcm(int(FS_DAQ), int(round(f_e))) // int(round(f_e))  # samples per block
    per_block = step * f_e / FS_DAQ
    assert abs(per_block - round(per_block)) < 1e-9
    n = (len(t) // step) * step
    return slice(0, n)


def test_motor_current_carries_the_fault_as_sidebands_of_the_supply(coupled_steady):
    """i_a = -i_q sin(theta_e) (i_d = 0): a torque oscillation at f_x modulates i_q (amplitude)
    and theta_e = p theta_m (phase), which puts lines at f_e ± f_x of size |I_q(f_x)|/2 ±
    I_0 p |Theta_m(f_x)|/2 (one sideband each, the sum 2|I_q(f_x)|/2) and nothing at f_x."""
    tw, out, _, t = coupled_steady
    drive = tw.parts[_drive_index(tw)].drive
    p = drive.pole_pairs
    f_e = p * F_SUN  # electrical (supply) frequency, Hz
    sl = _supply_periods(t, f_e)
    w_ref = 2 * math.pi * F_SUN

    def spec(x):
        return amplitude_spectrum(x[sl], FS_DAQ, "hann", remove_mean=True)

    freqs, a_ia = spec(out["i_a"])
    _, a_iq = spec(out["i_q"])
    _, a_th = spec(out["theta_motor"] - w_ref * t)  # rotor angle ripple (rad)
    _, a_tq = spec(out["torque_shaft"])
    i0 = float(np.mean(out["i_q"]))
    assert abs(float(np.mean(out["i_d"]))) < 1e-3 * i0
    assert _line(freqs, a_ia, f_e) == pytest.approx(i0, rel=1e-3)
    floor = noise_floor(a_ia, 31)
    for f_x in (FS, 2 * FS, FM):
        # the mechanical oscillation is there in the shaft torque ...
        assert _line(freqs, a_tq, f_x) > 10 * float(np.interp(f_x, freqs, noise_floor(a_tq, 31)))
        am = 0.5 * _line(freqs, a_iq, f_x)
        pm = 0.5 * i0 * p * _line(freqs, a_th, f_x)
        upper, lower = _line(freqs, a_ia, f_e + f_x), _line(freqs, a_ia, abs(f_e - f_x))
        for f_side, a in ((f_e + f_x, upper), (abs(f_e - f_x), lower)):
            # ... and in the phase current as sidebands of the supply, where theory puts them
            assert a > 30 * float(np.interp(f_side, freqs, floor)), f"{f_side:.1f} Hz"
        # amplitude modulation ± phase modulation: the sidebands are am - pm and am + pm
        assert upper + lower == pytest.approx(2 * am, rel=0.02), (f_x, upper, lower, am, pm)
        assert abs(lower - upper) == pytest.approx(2 * pm, rel=0.2), (f_x, upper, lower, am, pm)
        # not at the mechanical frequency itself
        assert _line(freqs, a_ia, f_x) < 0.01 * min(upper, lower)


# ------------------------------------------------------------------------------ the comparison
def _cli(out, *extra):
    from dtwin.cli import main

    args = ["compare-drives", "--preset", "paper-sim", "--kind", "torsional",
            "--severities", "0,0.5,1", "--duration", f"{T_CARRIER:.6f}", "--discard", "0.05",
            "--quantity", "acceleration", *extra]
    if out is not None:
        args += ["--out", str(out)]
    main(args)


def test_compare_drives_cli_figure_table_and_monotonic_rms(tmp_path, capsys):
    """The figure, the table and the JSON on one-carrier-period records; RMS rises with the
    severity in both models (reduced form: no sensitivity, which the slow test covers)."""
    out = tmp_path / "cmp"
    _cli(out, "--json", "--no-sensitivity")
    printed = json.loads(capsys.readouterr().out)
    data = json.loads((out / "compare_drives.json").read_text())
    assert printed == data
    manifest = json.loads((out / "manifest.json").read_text())
    assert set(manifest["files"]) == {"comparison.png", "compare_drives.json",
                                      "compare_drives.csv", "compare_drives.npz"}
    with np.load(out / "compare_drives.npz") as z:  # the figure's arrays, with units
        np.testing.assert_array_equal(z["rms_coupled"],
                                      [r["rms_coupled"] for r in data["comparison"]["rows"]])
        assert list(z["units"])[:2] == ["1", "m/s^2"]
    assert manifest["settings"]["kind"] == "torsional"
    assert (out / "comparison.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = data["comparison"]["rows"]
    assert [r["severity"] for r in rows] == [0.0, 0.5, 1.0]
    for m in MODELS:
        rms = np.array([r[f"rms_{m}"] for r in rows])
        assert np.all(np.diff(rms) > 0), f"{m}: RMS {rms}"
        assert rows[0][f"rise_{m}"] == 0.0
    # results are never overwritten silently
    with pytest.raises(SystemExit):
        _cli(out, "--no-sensitivity")
    assert "already" in capsys.readouterr().err


# ------------------------------------------------------------------------------ slow forms
@pytest.mark.slow
def test_compare_drives_cli_with_sensitivity(tmp_path, capsys):
    out = tmp_path / "cmp"
    _cli(out)
    text = capsys.readouterr().out
    assert "secant slope traditional" in text
    data = json.loads((out / "compare_drives.json").read_text())
    assert (out / "sensitivity.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = data["comparison"]["rows"]
    for m in MODELS:
        rms = np.array([r[f"rms_{m}"] for r in rows])
        slope = np.array([r[f"slope_{m}"] for r in rows])
        assert np.all(np.diff(rms) > 0), f"{m}: RMS {rms}"
        # the autodiff slope lies between the neighbouring secants where the RMS is convex in
        # the severity (a missing tooth's effect grows faster than linearly); not at s = 1, where
        # the floor k >= 0 of the mesh stiffness makes the RMS non-smooth (docs/coupling.md)
        sec = np.diff(rms) / 0.5
        assert sec[0] < slope[1] < sec[1], f"{m}: slope {slope} secants {sec}"


@pytest.mark.slow
def test_autodiff_sensitivity_matches_finite_differences(pair):
    from dtwin.simulation.simulate import SolverOptions

    kw = dict(f_sun=F_SUN, duration=T_CARRIER, discard=0.05, daq=DAQ(quantity="acceleration"),
              solver=SolverOptions(rtol=1e-8, atol=1e-8))
    h = 1e-3
    s = np.array([0.25, 0.5, 0.75])
    for tw in pair:
        _, d = fault_rms_and_slope(tw, s, **kw)
        fd = (fault_rms(tw, s + h, **kw) - fault_rms(tw, s - h, **kw)) / (2 * h)
        np.testing.assert_allclose(d, fd, rtol=0.01)


@pytest.mark.slow
def test_rms_rises_with_severity_translational_paper_window():
    from dtwin.report.drive_comparison import compare_drives

    cmp = compare_drives(SPEC, (0.0, 0.25, 0.5, 0.75, 1.0), kind="translational",
                         duration=3 * T_CARRIER, discard=0.1, sensitivity=False,
                         daq=DAQ(quantity="acceleration"))
    for m in MODELS:
        assert np.all(np.diff(cmp.rms[m]) > 0), f"{m}: {cmp.rms[m]}"
