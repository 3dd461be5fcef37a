"""The twin's dynamics against physics: sideband rule, fault families, resonance, gradients.

Records are short steady runs (2 s of signal for 0.5 Hz resolution; carrier sidebands are
~6 Hz apart) started from the steady state. Each simulation is cached for the module.
References: McFadden & Smith (1985) and docs/references.md §2 for the sideband rule; Lin & Parker
(1999) for the natural frequencies (via `dtwin.model.modal`).
"""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dtwin.errors import SolverError
from dtwin.model.faults import parse_fault
from dtwin.model.gears import characteristic_frequencies
from dtwin.model.lumped import replace
from dtwin.model.parts.base import AbstractPart
from dtwin.model.parts.local_fault import LocalFault
from dtwin.signal.spectrum import amplitude_spectrum, noise_floor
from dtwin.simulation.simulate import DAQ, SolverOptions, simulate
from dtwin.spec import preset
from dtwin.spec.build import build_twin

FS = 5000.0
DURATION = 2.0
DISCARD = 0.1


def ideal(name: str):
    """The preset with its imperfections set to zero."""
    from dtwin.spec import load_spec, spec_to_dict

    d = spec_to_dict(preset(name))
    d["imperfections"] = {}
    return load_spec(d)


@functools.cache
def run(name: str, kind: str, faults: tuple[str, ...] = (), duration: float = DURATION):
    spec = ideal(name[:-6]) if name.endswith(":ideal") else preset(name)
    f_sun = spec["operating"]["f_sun"]
    flts = tuple(parse_fault(f) for f in faults)
    tw = build_twin(spec, kind=kind, faults=flts)
    res = simulate(tw, duration=duration, f_sun=f_sun, discard=DISCARD, daq=DAQ(sample_rate=FS))
    x = np.asarray(res.signal)
    f, A = amplitude_spectrum(x, FS, "hann", remove_mean=True)
    fr = {k: float(v) for k, v in characteristic_frequencies(spec.gear_set(), f_sun).items()}
    return x, f, np.asarray(A), fr


def level(f, A, freq):
    """Largest amplitude within ±1 bin of `freq`."""
    i = int(round(freq / (f[1] - f[0])))
    return A[max(i - 1, 0) : i + 2].max()


def db(x):
    return 20.0 * np.log10(x)


@pytest.mark.parametrize("name", ["paper-sim", "paper-bench"])
def test_healthy_spectrum_obeys_sideband_rule(name):
    """Ideal, equally spaced planets with Zr mod N = 0: only fm ± k N fc survive (ref. §2)."""
    _, f, A, fr = run(name, "translational")
    fm, fc, n = fr["f_mesh"], fr["f_carrier"], 3
    floor = noise_floor(A)
    a_fm = level(f, A, fm)
    for k in (-1, 1):
        fk = fm + k * n * fc
        i = int(round(fk / (f[1] - f[0])))
        assert db(level(f, A, fk) / floor[i]) >= 20.0
    # every other local maximum in 450-550 Hz at least 40 dB below fm
    band = np.flatnonzero((f > 450) & (f < 550))
    allowed = [fm + k * n * fc for k in range(-10, 11)]
    for i in band:
        if A[i] >= A[i - 1] and A[i] >= A[i + 1]:
            if min(abs(f[i] - a) for a in allowed) <= 1.5 * (f[1] - f[0]):
                continue
            assert db(A[i] / a_fm) <= -40.0, f"unexpected line at {f[i]:.2f} Hz"


def _sun_family(fr, kmax=2, nmax=8):
    fm, fc, fsn = fr["f_mesh"], fr["f_carrier"], fr["f_sun_fault"] / 3
    lines = []
    for k in range(-kmax, kmax + 1):
        if k == 0:
            continue
        for m in range(-nmax, nmax + 1):
            if (m - k) % 3 == 0:  # n ≡ k (mod N): planets numbered with the carrier rotation
                f_ = fm + k * fsn + m * fc
                if 450 < f_ < 550:
                    lines.append(f_)
    return lines


def test_sun_fault_family_rises_and_fm_pm_fs3_cancel():
    _, f, A0, fr = run("paper-sim", "torsional")
    _, _, A1, _ = run("paper-sim", "torsional", ("sun:missing_tooth:0.5",))
    fm, fc, fsn = fr["f_mesh"], fr["f_carrier"], fr["f_sun_fault"] / 3
    df = f[1] - f[0]
    risen = 0
    lines = [x for x in _sun_family(fr) if abs(((x - fm) / (3 * fc)) - round((x - fm) / (3 * fc))) > 0.1]
    for x in lines:
        if db(level(f, A1, x) / level(f, A0, x)) >= 10.0:
            risen += 1
    assert risen >= 0.8 * len(lines) and risen >= 6
    # fm ± fs/N themselves (n = 0, k = ±1 violates n ≡ k mod N) stay >= 30 dB below neighbours
    for k in (-1, 1):
        x = fm + k * fsn
        neighbours = [fm + k * fsn + m * fc for m in (k - 3 * np.sign(k), k) if m != 0]
        ref = max(level(f, A1, y) for y in neighbours)
        i = int(round(x / df))
        # fs/3 = 3.857 fc lies off the fc grid on the simulation gearbox: a clean bin
        assert db(A1[i] / ref) <= -30.0


@pytest.mark.parametrize("planet", [0, 1, 2])
def test_planet_fault_family_rises_on_each_planet(planet):
    _, f, A0, fr = run("paper-sim", "torsional")
    _, _, A1, _ = run("paper-sim", "torsional", (f"planet:missing_tooth:0.5:0:{planet}",))
    fm, fc, fp = fr["f_mesh"], fr["f_carrier"], fr["f_planet_fault"]
    lines = [fm + k * fp + m * fc for k in (-2, -1, 1, 2) for m in range(-3, 4)]
    lines = [x for x in lines if 450 < x < 550 and abs((x - fm) / fc - round((x - fm) / fc)) > 0.1]
    risen = sum(db(level(f, A1, x) / level(f, A0, x)) >= 10.0 for x in lines)
    assert risen >= 0.7 * len(lines)


def test_planet_fault_low_comb_lies_beside_k_fp_not_on_it():
    """Torque balance: below the torsional modes the planets' ring-mesh forces sum to the ring's
    reaction to the load, whatever one planet's mesh stiffness does, so a planet fault moves
    load between the planets rather than changing the sum. The planet-angle window weighs the
    planets by their angle, which turns at f_c: the moved load reaches the sensor at
    ``k fp ± n fc`` (n ≠ 0), and the line ``k fp`` itself, the window's mean times the summed
    force, only through the small dynamic torque. (k = 1 is left out: 1.85 Hz from the
    planet-pass line, it holds that line's leakage at 0.5 Hz resolution; k fp up to 9 fp stays
    ≥ 3 bins from every m·3fc.)"""
    _, f, A1, fr = run("paper-sim", "torsional", ("planet:missing_tooth:0.5:0:0",))
    fc, fp = fr["f_carrier"], fr["f_planet_fault"]
    for k in range(2, 10):
        on = level(f, A1, k * fp)
        beside = max(level(f, A1, k * fp + n * fc) for n in (-1, 1))
        assert db(on / beside) <= -30.0, (k, db(on / beside))


def test_combined_fault_shows_both_families():
    _, f, A0, fr = run("paper-sim", "torsional")
    _, _, A2, _ = run("paper-sim", "torsional", ("sun:missing_tooth:0.5", "planet:missing_tooth:0.5"))
    fm, fc, fp = fr["f_mesh"], fr["f_carrier"], fr["f_planet_fault"]
    sun = [x for x in _sun_family(fr) if abs((x - fm) / fc - round((x - fm) / fc)) > 0.1]
    planet = [fm + k * fp for k in (-2, -1, 1, 2)]
    assert np.mean([db(level(f, A2, x) / level(f, A0, x)) >= 10 for x in sun]) >= 0.7
    assert np.mean([db(level(f, A2, x) / level(f, A0, x)) >= 10 for x in planet]) >= 0.75


def test_rms_rises_with_sun_fault_severity():
    rms = []
    for sev in (0.0, 0.25, 0.5, 0.75, 1.0):
        x, *_ = run("paper-sim", "torsional", (f"sun:missing_tooth:{sev}",), 0.5)
        rms.append(np.std(x))
    assert all(b > a for a, b in zip(rms, rms[1:], strict=False)), rms


class CarrierTorqueRipple(AbstractPart):
    """A part defined in a test: a torque fluctuation on the carrier at `frequency` (Hz)."""

    amplitude: float
    frequency: float

    def forces(self, twin, t, q, qdot, aux, mesh):
        from dtwin.model.twin import Coords

        tq = self.amplitude * jnp.sin(2 * jnp.pi * self.frequency * t)
        return Coords.zeros(twin.n_planets).set(theta_c=tq), jnp.zeros(0), {}


def test_part_defined_in_a_test_joins_the_twin():
    spec = preset("paper-sim")
    tw = build_twin(spec, kind="torsional", extra_parts=(CarrierTorqueRipple(10.0, 37.0),))
    res = simulate(tw, duration=DURATION, f_sun=30.0, discard=DISCARD)
    f, A1 = amplitude_spectrum(np.asarray(res.signal), FS, "hann", remove_mean=True)
    _, f, A0, fr = run("paper-sim", "torsional")
    fm = fr["f_mesh"]
    # the ripple modulates the mesh force: sidebands at fm ± 37 Hz appear, 20 dB above before
    for x in (fm - 37.0, fm + 37.0):
        assert db(level(f, np.asarray(A1), x) / level(f, A0, x)) >= 20.0


def test_paper_like_preset_shows_fm_pm_7fc_and_ideal_does_not():
    _, f, A, fr = run("paper-like", "torsional")
    _, _, A0, _ = run("paper-like:ideal", "torsional")
    fm, fc = fr["f_mesh"], fr["f_carrier"]
    floor = noise_floor(A)
    for k in (-7, 7):
        x = fm + k * fc
        i = int(round(x / (f[1] - f[0])))
        assert db(level(f, A, x) / floor[i]) >= 15.0
        assert db(level(f, A, x) / level(f, A0, x)) >= 20.0


def test_solver_failure_raises_documented_error():
    tw = build_twin(preset("paper-sim"), kind="torsional")
    with pytest.raises(SolverError, match="max_steps"):
        simulate(tw, duration=0.05, f_sun=30.0, solver=SolverOptions(max_steps=50))
    bad = eqx.tree_at(lambda t: t.lp, tw, replace(tw.lp, k_sun_planet=float("nan")))
    with pytest.raises(SolverError, match="NaN"):
        simulate(bad, duration=0.05, f_sun=30.0)
    with pytest.raises(ValueError, match="duration"):
        simulate(tw, duration=-1.0, f_sun=30.0)


@pytest.mark.parametrize("duration", [0.3, 1.0])
def test_another_speed_reuses_the_compiled_solve(duration):
    """A speed sweep in a notebook: the twin at another input speed traces no new program (its
    times, tolerances and step limit are values of the compiled solve, not constants), in full
    (0.3 s) or over one hunting period (1.0 s at 60 Hz: 0.57 s) — and the strongest line is
    each speed's mesh frequency (a stale time grid or period would leave it where it was)."""
    spec = preset("paper-sim")
    solver = SolverOptions(periodic="auto" if duration == 1.0 else "off")
    traces = []
    jax.monitoring.register_event_duration_secs_listener(
        lambda event, secs, **kw: traces.append(event) if event.endswith("trace_duration") else None)
    peaks = {}
    for f_sun in (60.0, 61.3):
        tw = build_twin(spec, kind="torsional", f_sun=f_sun)
        traces.clear()
        res = simulate(tw, duration=duration, f_sun=f_sun, daq=DAQ(sample_rate=FS), solver=solver)
        if f_sun != 60.0:
            assert traces == [], traces
        assert res.method == ("periodic" if duration == 1.0 else "full"), res.method
        f, A = amplitude_spectrum(np.asarray(res.signal), FS, "hann", remove_mean=True)
        band = (f > 900.0) & (f < 1150.0)  # both speeds' f_mesh (1000.6, 1022.2 Hz)
        peaks[f_sun] = f[band][np.argmax(A[band])]
    gs = spec.gear_set()
    for f_sun, peak in peaks.items():
        fm = float(characteristic_frequencies(gs, f_sun)["f_mesh"])
        assert abs(peak - fm) <= 1.5 / duration, (f_sun, peak, fm)


# ------------------------------------------------------------------------- gradients
def _line_level(tw, p, fm, df_line, dur=0.4):
    """Amplitude of the line at fm + df_line (Hz) in a short record, differentiable."""
    res = simulate(tw, duration=dur, f_sun=30.0, discard=0.05, check=False,
                   solver=SolverOptions(adjoint="forward", rtol=1e-8, atol=1e-8))
    x = res.signal
    n = x.shape[0]
    k = jnp.arange(n, dtype=jnp.float64)
    t = k / FS
    w = 0.5 - 0.5 * jnp.cos(2 * jnp.pi * k / n)
    f0 = fm + df_line
    arg = 2 * jnp.pi * f0 * t
    c = jnp.sum(w * x * jnp.cos(arg))
    s = jnp.sum(w * x * jnp.sin(arg))
    return 2 * jnp.sqrt(c**2 + s**2) / jnp.sum(w)


@pytest.mark.parametrize(
    "param,value,rel_step",
    [("k_sun_planet", None, 1e-4), ("zeta_sun_planet", None, 1e-3), ("sun_fault", 0.3, 1e-3)],
)
def test_gradient_matches_finite_differences(param, value, rel_step):
    spec = preset("paper-sim")
    base = build_twin(spec, kind="torsional", faults=(parse_fault("sun:missing_tooth:0.3"),))
    fr = {k: float(v) for k, v in characteristic_frequencies(spec.gear_set(), 30.0).items()}
    fm, fsn, fc = fr["f_mesh"], fr["f_sun_fault"] / 3, fr["f_carrier"]
    df_line = fsn - 2 * fc  # a sun-fault line (k = 1, n = -2)

    def with_value(v):
        if param == "sun_fault":
            i = next(j for j, p in enumerate(base.parts) if isinstance(p, LocalFault))
            return eqx.tree_at(lambda t: t.parts[i].fault.severity, base, v)
        return eqx.tree_at(lambda t: t.lp, base, replace(base.lp, **{param: v}))

    v0 = jnp.asarray(value if value is not None else float(getattr(base.lp, param)))

    def g(v):
        return _line_level(with_value(v), param, fm, df_line)

    _, d_ad = jax.jvp(g, (v0,), (jnp.ones(()),))
    h = rel_step * float(v0)
    d_fd = (g(v0 + h) - g(v0 - h)) / (2 * h)
    # tolerance: 1 % plus a small absolute term (FD truncation and solver noise), see README
    scale = abs(float(g(v0))) / float(v0)
    assert abs(float(d_ad) - float(d_fd)) <= 0.01 * abs(float(d_fd)) + 1e-4 * scale


def test_resonance_moves_with_sun_planet_stiffness():
    """A speed sweep's response peaks where the modal analysis puts the mesh-stiffness mode.

    The torsional model's rotational mode near 12 kHz is the one the sun-planet stiffness
    controls (relative sensitivity ~0.48, `dtwin.model.modal`); the 20th mesh harmonic (stiffness
    series with 24 harmonics) sweeps across it, seen in the sun-mesh deflection. The peak
    of that harmonic's response by the ratio the modal analysis predicts. Raising it by 20 %
    moves the mode by ~9 %.
    """
    from dtwin.model.modal import frequency_sensitivities, modal_analysis
    from dtwin.model.motor.drive import DrivePart
    from dtwin.model.motor.shaft import Shaft
    from dtwin.model.motor.speed_source import IdealSpeedSource, SpeedProfile

    spec = preset("paper-sim")
    zr, zs = spec["gears"]["z_ring"], spec["gears"]["z_sun"]
    h, fs_hi, dur = 20, 48000.0, 0.6
    base = build_twin(spec, kind="torsional", n_harmonics=24)
    res0 = modal_analysis(base.lp, model="torsional")
    sens = np.asarray(frequency_sensitivities(base.lp, ("k_sun_planet",), "torsional")["k_sun_planet"])
    j = int(np.argmax(sens))
    f_mode = float(res0.frequencies[j])
    assert sens[j] > 0.3 and f_mode > 5000.0
    mesh_per_sun = zr / (1 + zr / zs)  # f_mesh / f_sun
    f_lo, f_hi = 0.85 * f_mode / h / mesh_per_sun, 1.25 * f_mode / h / mesh_per_sun
    i = next(k for k, p in enumerate(base.parts) if isinstance(p, DrivePart))
    peaks, modes = [], []
    for scale in (1.0, 1.2):
        tw = eqx.tree_at(lambda t: t.lp, base, replace(base.lp, k_sun_planet=base.lp.k_sun_planet * scale))
        modes.append(float(modal_analysis(tw.lp, model="torsional").frequencies[j]))
        prof = SpeedProfile.ramp(2 * math.pi * f_hi, dur, 0.0, 2 * math.pi * f_lo)
        tw = eqx.tree_at(lambda t: t.parts[i].drive, tw, IdealSpeedSource(prof, Shaft()))
        res = simulate(tw, duration=dur, f_sun=f_lo, daq=DAQ(sample_rate=fs_hi, oversample=2))
        # the sun-planet mode shows in the sun-mesh deflection (the housing sensor sees the
        # ring mesh, in which this mode hardly participates; the mesh *force* adds the
        # non-resonant k_h * delta_0 term, which shifts its peak)
        x = np.asarray(res.outputs["deflection_sun_planet"])
        fmh = h * np.asarray(res.outputs["omega_sun"]) / (2 * np.pi) * mesh_per_sun
        phase = 2 * np.pi * np.cumsum(fmh) / fs_hi
        seg = 1024
        amps, freqs = [], []
        for s0 in range(0, len(x) - seg, seg // 4):
            sl = slice(s0, s0 + seg)
            amps.append(abs(np.sum(np.hanning(seg) * x[sl] * np.exp(-1j * phase[sl]))))
            freqs.append(fmh[sl].mean())
        peaks.append(freqs[int(np.argmax(amps))])
    ratio_sim, ratio_modal = peaks[1] / peaks[0], modes[1] / modes[0]
    assert ratio_modal > 1.06
    assert abs(ratio_sim - ratio_modal) < 0.3 * (ratio_modal - 1.0), (peaks, modes)


def test_velocity_and_displacement_sensors_integrate_acceleration():
    """The sensor's quantity (issue 3, item 2): velocity and displacement are the acceleration
    integrated once and twice, so at the mesh frequency |V| = |A| / (2π fm) and
    |D| = |A| / (2π fm)² (within 1 %: the 2 Hz drift high-pass and the ±1-bin peak search each
    change a 500 Hz line by well under that)."""
    spec = preset("paper-sim")
    f_sun = spec["operating"]["f_sun"]
    tw = build_twin(spec, kind="torsional")
    fm = float(characteristic_frequencies(spec.gear_set(), f_sun)["f_mesh"])
    lines = {}
    for q in ("acceleration", "velocity", "displacement"):
        res = simulate(tw, duration=0.4, f_sun=f_sun, discard=DISCARD,
                       daq=DAQ(sample_rate=FS, quantity=q))
        assert res.quantity == q
        x = np.asarray(res.signal)
        assert np.all(np.isfinite(x))
        f, A = amplitude_spectrum(x, FS, "hann", remove_mean=True)
        lines[q] = level(f, np.asarray(A), fm)
    w = 2 * math.pi * fm
    assert lines["velocity"] == pytest.approx(lines["acceleration"] / w, rel=0.01)
    assert lines["displacement"] == pytest.approx(lines["acceleration"] / w**2, rel=0.01)


def test_contact_force_and_its_derivative_rule():
    """`dtwin.model.twin.contact_force` (one exponential, hand-written JVP) against the textbook
    ``k s softplus(d/s) + c d' sigmoid(d/s)`` and JAX's own derivative of it, from deep
    separation to deep contact (|d/s| up to 800, where a naive exp overflows)."""
    from dtwin.model.twin import contact_force

    s = 2e-8
    d = jnp.asarray(np.concatenate([np.linspace(-16e-6, 16e-6, 41), [0.0, 1e-9, -1e-9]]))
    dd = jnp.linspace(-1e-3, 1e-3, d.shape[0])
    k = jnp.full(d.shape, 3.1e8)
    c = jnp.full(d.shape, 2.5e3)

    def textbook(d, dd, k, c):
        return k * s * jax.nn.softplus(d / s) + c * dd * jax.nn.sigmoid(d / s)

    args = (d, dd, k, c)
    np.testing.assert_allclose(contact_force(*args, s), textbook(*args), rtol=1e-13, atol=1e-18)
    for i in range(4):
        def ours(a, i=i):
            return contact_force(*args[:i], a, *args[i + 1 :], s)

        def theirs(a, i=i):
            return textbook(*args[:i], a, *args[i + 1 :])

        got, want = jax.jacfwd(ours)(args[i]), jax.jacfwd(theirs)(args[i])
        assert bool(jnp.all(jnp.isfinite(got)))
        np.testing.assert_allclose(jnp.diag(got), jnp.diag(want), rtol=1e-12, atol=1e-16)
    g = jax.grad(lambda x: jnp.sum(contact_force(x, dd, k, c, s)))(d)
    g_want = jax.grad(lambda x: jnp.sum(textbook(x, dd, k, c)))(d)
    np.testing.assert_allclose(g, g_want, rtol=1e-12, atol=1e-16)
