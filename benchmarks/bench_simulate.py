"""Benchmark: the paper's gearbox simulated with diffrax (dtwin.simulate) against SciPy.

For each model kind (translational, torsional) of ``build_twin(preset("paper-sim"))`` with a sun
missing tooth (severity 0.5), ideal speed source at 30 Hz, 50 N·m load, 5 kHz acceleration
record:

- `dtwin.simulation.simulate.simulate` for `--duration` seconds (default 4): first call (compile + run)
  and second call (run); compile time = first − second; simulated seconds per wall second,
  accepted steps per simulated second, wall time per step; the cost of one right-hand side
  evaluation in a jitted loop (what a step costs at the least: Tsit5 takes 6 per step);
- the same equations (`tests/reference_numpy.py`, an independent NumPy implementation,
  faults and sensor included) integrated by `scipy.integrate.solve_ivp` with RK45 and DOP853 at
  the same `rtol`, `atol` and largest step on the same scaled state (both use the RMS norm of
  the error over ``atol + rtol |y|``) over `--scipy-span` seconds, timed and extrapolated
  linearly to `--duration`; its sensor goes through the same DAQ filter. Both records are
  compared with a tight DOP853 solution (rtol = atol = 1e-10) and with each other;
- the highest natural frequency (twin's `linear_stiffness()` / `mass_matrix()`) and the
  largest stable step of each explicit method on the linearised system's eigenvalues: the step
  limit that sets the steps per simulated second.

Prints a table (and `--json`); `--quick` is a short smoke run. The compilation cache is off
unless `--cache` (the compile time is then the true cold compile).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from _timing import load_average  # noqa: E402

HERE = Path(__file__).resolve().parent


# ----------------------------------------------------------------------------- stability
def _stability_function(A, b):
    """R(z) = 1 + z b^T (I - z A)^-1 1 of an explicit Runge-Kutta tableau."""
    b = np.asarray(b, dtype=complex)
    A0 = np.asarray(A, dtype=complex)
    A = np.zeros((len(b), len(b)), dtype=complex)
    A[: A0.shape[0], : A0.shape[1]] = A0
    one = np.ones(len(b))

    def R(z):
        return 1.0 + z * (b @ np.linalg.solve(np.eye(len(b)) - z * A, one))

    return R


def _tableaus():
    import scipy.integrate._ivp.rk as rk
    from diffrax._solver.tsit5 import _tsit5_tableau as tab

    s = len(tab.b_sol)
    A = np.zeros((s, s))
    for i, row in enumerate(tab.a_lower):
        A[i + 1, : len(row)] = row
    return {
        "Tsit5": (A, np.asarray(tab.b_sol)),
        "RK45": (rk.RK45.A, rk.RK45.B),
        "DOP853": (rk.DOP853.A[: rk.DOP853.n_stages, : rk.DOP853.n_stages],
                   rk.DOP853.B),
    }


def largest_stable_step(eigenvalues, method):
    """Largest h with |R(h lambda)| <= 1 for every eigenvalue (s), by bisection on h."""
    R = _stability_function(*_tableaus()[method])
    lam = np.asarray(eigenvalues)
    # rigid-body modes (free rotation of the gear train: lambda ~ 0 up to rounding) are
    # stable for any h in practice (R(0) = 1); keep the vibration modes
    lam = lam[np.abs(lam) > 1e-6 * np.max(np.abs(lam))]

    def stable(h):
        return all(abs(R(h * x)) <= 1.0 + 1e-12 for x in lam)

    lo, hi = 0.0, 10.0 / np.max(np.abs(lam))
    while stable(hi):
        hi *= 2
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def linear_modes(twin, ref):
    """Natural frequencies (Hz, twin's own K and M) and the eigenvalues of the damped linear
    first-order system (mean mesh stiffness, mesh and support damping), in the coordinates q."""
    import scipy.linalg

    K = np.asarray(twin.linear_stiffness(modal=False))
    M = np.asarray(twin.mass_matrix())
    lam = scipy.linalg.eigh(K, M, eigvals_only=True)
    f = np.sqrt(np.clip(lam, 0.0, None)) / (2 * np.pi)
    C = ref.L.T @ (ref.c_mesh[:, None] * ref.L) + ref.C
    n = K.shape[0]
    Minv = np.linalg.inv(M)
    S = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ C]])
    return f, np.linalg.eigvals(S)


def _line_changes(x_ref, x, fs, f_sun, ref):
    """Largest change (dB) of the spectral lines ``h f_mesh + k f_carrier`` (h = 1..4,
    |k| <= 8) of `x` against `x_ref`, for lines within 40 dB and within 40–60 dB of the
    strongest (Hann window, whole record)."""
    def spec(v):
        w = np.hanning(len(v))
        return np.abs(np.fft.rfft((v - v.mean()) * w)), np.fft.rfftfreq(len(v), 1.0 / fs)

    a_ref, f = spec(x_ref)
    a, _ = spec(x)
    fc = f_sun / (1 + ref.zr / ref.zs)
    fm = fc * ref.zr
    lines = [h * fm + k * fc for h in (1, 2, 3, 4) for k in range(-8, 9) if h * fm + k * fc < fs / 2]
    idx = np.array([np.argmin(np.abs(f - x)) for x in lines])
    lev = 20 * np.log10(a_ref[idx])
    d = np.abs(20 * np.log10(a[idx]) - lev)
    top = lev.max()
    return {"within_40dB": float(d[lev > top - 40].max()),
            "40_to_60dB": float(d[(lev <= top - 40) & (lev > top - 60)].max())}


# ----------------------------------------------------------------------------- runs
def bench_kind(kind, args):
    import jax
    import jax.numpy as jnp
    import scipy.integrate
    import scipy.signal

    from dtwin.model.faults import MissingTooth
    from dtwin.simulation.simulate import (
        DAQ,
        SolverOptions,
        daq_filter,
        initial_state,
        simulate,
        state_scales,
    )
    from dtwin.spec import preset
    from dtwin.spec.build import build_twin

    sys.path.insert(0, str(HERE.parent / "tests"))  # the test oracle lives with the tests
    from reference_numpy import ReferenceModel

    f_sun = 30.0
    spec = preset("paper-sim")
    twin = build_twin(spec, kind=kind, faults=(MissingTooth(0.5, location="sun", tooth=0),))
    ref = ReferenceModel(twin)
    daq = DAQ(sample_rate=5000.0, quantity="acceleration")
    opts = SolverOptions()
    out = {"kind": kind, "n_dof": twin.n_dof, "duration": args.duration}

    # --- diffrax
    load0 = load_average()
    t0, c0 = time.perf_counter(), time.process_time()
    r1 = simulate(twin, duration=args.duration, f_sun=f_sun, daq=daq, solver=opts)
    jax.block_until_ready(r1.signal)
    first, first_cpu = time.perf_counter() - t0, time.process_time() - c0
    t0, c0 = time.perf_counter(), time.process_time()
    r2 = simulate(twin, duration=args.duration, f_sun=f_sun, daq=daq, solver=opts)
    jax.block_until_ready(r2.signal)
    second, second_cpu = time.perf_counter() - t0, time.process_time() - c0
    taps = daq_filter(daq.oversample)
    half = (len(taps) - 1) // 2
    fs_hi = daq.sample_rate * daq.oversample
    span = args.duration + 2 * half / fs_hi  # integrated interval (filter margins)
    steps = int(r2.num_steps)
    out.update(
        load_jax=load0, first_call_s=first, run_s=second, compile_s=first - second,
        compile_cpu_s=first_cpu - second_cpu,
        run_cpu_s=second_cpu, sim_s_per_cpu_s=span / second_cpu,
        sim_s_per_wall_s=span / second, steps=steps, steps_per_sim_s=steps / span,
        us_per_step=1e6 * second / steps, cpu_us_per_step=1e6 * second_cpu / steps,
    )

    # cost of one right-hand side evaluation: a jitted loop with the twin as an argument (as in
    # `_solve`: its parameters are traced, not folded into constants), CPU time
    import equinox as eqx

    z0, zd0, aux0 = initial_state(twin, f_sun)
    n = twin.n_dof

    @eqx.filter_jit
    def loop(tw, z0, zd0, aux0):
        ops = tw.operators()
        sz, sv = state_scales(tw)

        def body(i, y):
            dz, dzd, da = tw.vector_field(1e-6 * i, (y[:n] * sz, y[n:2 * n] * sv, y[2 * n:]), ops)
            return y + 1e-12 * jnp.concatenate([dz / sz, dzd / sv, da])

        return jax.lax.fori_loop(0, 20000, body, jnp.concatenate([z0 / sz, zd0 / sv, aux0]))

    jax.block_until_ready(loop(twin, z0, zd0, aux0))
    c0 = time.process_time()
    jax.block_until_ready(loop(twin, z0, zd0, aux0))
    out["us_per_rhs_jax"] = 1e6 * (time.process_time() - c0) / 20000

    # --- scipy with the NumPy right-hand side
    y0n = ref.scale(np.asarray(z0), np.asarray(zd0), np.asarray(aux0))
    t_start = -half / fs_hi
    n_out = int(round(args.scipy_span * daq.sample_rate))
    ts = t_start + np.arange(n_out * daq.oversample + 2 * half) / fs_hi
    s_span = ts[-1] - ts[0]
    f_mesh = f_sun / (1 + ref.zr / ref.zs) * ref.zr
    dtmax = 0.1 / f_mesh
    c0 = time.process_time()
    for _ in range(500):
        ref.rhs(0.0, y0n)
    out["us_per_rhs_numpy"] = 1e6 * (time.process_time() - c0) / 500

    def record(sol):
        acc = ref.sensor_along(ts, sol.y)
        return np.convolve(acc, taps, mode="valid")[:: daq.oversample]

    jax_rec = np.asarray(r2.signal)[:n_out]
    recs = {}
    for method in ("RK45", "DOP853"):
        load1 = load_average()
        t0, c0 = time.perf_counter(), time.process_time()
        sol = scipy.integrate.solve_ivp(ref.rhs, (ts[0], ts[-1]), y0n, method=method,
                                        rtol=opts.rtol, atol=opts.atol, max_step=dtmax,
                                        t_eval=ts)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        if not sol.success:
            raise RuntimeError(f"solve_ivp {method} failed: {sol.message}")
        t0, c0 = time.perf_counter(), time.process_time()
        recs[method] = record(sol)
        wall_sensor, cpu_sensor = time.perf_counter() - t0, time.process_time() - c0
        per_stage = {"RK45": 6, "DOP853": 12}[method]
        out[method] = dict(
            load=load1, span_s=s_span, wall_s=wall, sensor_s=wall_sensor, nfev=int(sol.nfev),
            steps_approx=int(sol.nfev / per_stage),
            steps_per_sim_s=sol.nfev / per_stage / s_span,
            extrapolated_s=(wall + wall_sensor) * span / s_span,
            ratio_vs_jax=(wall + wall_sensor) * span / s_span / second,
            cpu_s=cpu, sensor_cpu_s=cpu_sensor,
            ratio_vs_jax_cpu=(cpu + cpu_sensor) * span / s_span / second_cpu,
        )
    if not args.quick:
        sol = scipy.integrate.solve_ivp(ref.rhs, (ts[0], ts[-1]), y0n, method="DOP853",
                                        rtol=1e-10, atol=1e-10, max_step=dtmax, t_eval=ts)
        truth = record(sol)
    else:
        truth = recs["DOP853"]
    rms = float(np.sqrt(np.mean(truth**2)))
    out["signal_rms"] = rms
    out["rel_diff"] = {
        "jax_vs_truth": float(np.sqrt(np.mean((jax_rec - truth) ** 2)) / rms),
        "RK45_vs_truth": float(np.sqrt(np.mean((recs["RK45"] - truth) ** 2)) / rms),
        "DOP853_vs_truth": float(np.sqrt(np.mean((recs["DOP853"] - truth) ** 2)) / rms),
        "jax_vs_RK45": float(np.sqrt(np.mean((jax_rec - recs["RK45"]) ** 2)) / rms),
        "jax_vs_DOP853": float(np.sqrt(np.mean((jax_rec - recs["DOP853"]) ** 2)) / rms),
    }
    out["truth"] = "DOP853 rtol=atol=1e-10" if not args.quick else "DOP853 at the same tolerance"

    # --- the same JAX run at other settings: cost and accuracy (signal and spectral lines)
    def timed_run(o, **info):
        jax.block_until_ready(simulate(twin, duration=args.duration, f_sun=f_sun, daq=daq,
                                       solver=o).signal)
        t0, c0 = time.perf_counter(), time.process_time()
        r3 = simulate(twin, duration=args.duration, f_sun=f_sun, daq=daq, solver=o)
        jax.block_until_ready(r3.signal)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        rec = np.asarray(r3.signal)[:n_out]
        return dict(
            **info, run_s=wall, run_cpu_s=cpu, sim_s_per_wall_s=span / wall,
            sim_s_per_cpu_s=span / cpu, steps_per_sim_s=int(r3.num_steps) / span,
            cpu_us_per_step=1e6 * cpu / int(r3.num_steps),
            rel_diff_vs_truth=float(np.sqrt(np.mean((rec - truth) ** 2)) / rms),
            line_db_vs_default=_line_changes(np.asarray(r2.signal), np.asarray(r3.signal),
                                             daq.sample_rate, f_sun, ref),
        )

    out["other_tolerances"] = [timed_run(SolverOptions(rtol=tol, atol=tol), tol=tol)
                               for tol in args.tolerances]
    # the step loop and controller before this round, at the default tolerance: diffrax's own
    # Tsit5 (stage loop) with the integral-only controller, then the unrolled stages alone
    out["variants"] = [
        timed_run(SolverOptions(unrolled=False, pcoeff=0.0, icoeff=1.0),
                  label="diffrax.Tsit5, I controller (0, 1)"),
        timed_run(SolverOptions(unrolled=True, pcoeff=0.0, icoeff=1.0),
                  label="UnrolledTsit5, I controller (0, 1)"),
    ] if not args.quick else []

    # --- what limits the step
    f, lam = linear_modes(twin, ref)
    out["f_max_hz"] = float(np.max(f))
    out["f_max_numpy_hz"] = float(np.max(ref.natural_frequencies()))
    lam_max = lam[np.argmax(np.abs(lam))]
    out["zeta_of_fastest"] = float(-lam_max.real / abs(lam_max))
    out["stable_steps_per_s"] = {m: 1.0 / largest_stable_step(lam, m)
                                 for m in ("Tsit5", "RK45", "DOP853")}
    out["dtmax_steps_per_s"] = 1.0 / dtmax
    out["load_end"] = load_average()
    return out


def _table(results):
    rows = []
    for r in results:
        k = r["kind"]
        rows += [
            (k, "compile (first − second call), wall (CPU)",
             f"{r['compile_s']:.1f} s ({r['compile_cpu_s']:.1f} s)"),
            (k, f"run {r['duration']:g} s simulated", f"{r['run_s']:.2f} s"),
            (k, "simulated s per wall s (per CPU s)",
             f"{r['sim_s_per_wall_s']:.2f} ({r['sim_s_per_cpu_s']:.2f})"),
            (k, "accepted steps per simulated s", f"{r['steps_per_sim_s']:.0f}"),
            (k, "wall (CPU) per step", f"{r['us_per_step']:.1f} µs ({r['cpu_us_per_step']:.1f} µs)"),
            (k, "one RHS eval (CPU), JAX / NumPy", f"{r['us_per_rhs_jax']:.2f} / {r['us_per_rhs_numpy']:.1f} µs"),
            (k, "stable-step limit (Tsit5/RK45/DOP853)",
             " / ".join(f"{r['stable_steps_per_s'][m]:.0f}" for m in ("Tsit5", "RK45", "DOP853"))
             + " steps/s"),
            (k, "highest natural frequency", f"{r['f_max_hz']:.0f} Hz (ζ={r['zeta_of_fastest']:.3f})"),
        ]
        for m in ("RK45", "DOP853"):
            s = r[m]
            rows.append((k, f"scipy {m} ({s['span_s']:.3f} s, ×{r['duration'] / s['span_s']:.0f})",
                         f"{s['extrapolated_s']:.0f} s → JAX {s['ratio_vs_jax']:.0f}× faster"
                         f" (CPU time {s['ratio_vs_jax_cpu']:.0f}×; {s['steps_per_sim_s']:.0f}"
                         " attempted steps/s)"))
        d = r["rel_diff"]
        rows.append((k, f"rms diff vs {r['truth']}",
                     f"JAX {d['jax_vs_truth']:.1e}, RK45 {d['RK45_vs_truth']:.1e}, "
                     f"DOP853 {d['DOP853_vs_truth']:.1e}; JAX−RK45 {d['jax_vs_RK45']:.1e}"))
        for o in r.get("other_tolerances", []):
            rows.append((k, f"JAX at rtol = atol = {o['tol']:g}",
                         f"{o['sim_s_per_wall_s']:.2f} sim s per wall s ({o['sim_s_per_cpu_s']:.2f} per CPU s),"
                         f" {o['steps_per_sim_s']:.0f} steps/s, {o['cpu_us_per_step']:.1f} µs CPU/step,"
                         f" rms diff {o['rel_diff_vs_truth']:.1e}, lines ±"
                         f"{o['line_db_vs_default']['within_40dB']:.2f} dB (≤ 40 dB down) / ±"
                         f"{o['line_db_vs_default']['40_to_60dB']:.2f} dB (40–60 dB down) vs default"))
        for o in r.get("variants", []):
            rows.append((k, f"default tolerance, {o['label']}",
                         f"{o['sim_s_per_wall_s']:.2f} sim s per wall s ({o['sim_s_per_cpu_s']:.2f} per CPU s),"
                         f" {o['steps_per_sim_s']:.0f} steps/s, {o['cpu_us_per_step']:.1f} µs CPU/step,"
                         f" rms diff {o['rel_diff_vs_truth']:.1e}"))
        rows.append((k, "load average (start of JAX run / end)",
                     f"{r['load_jax'][0]:.1f} / {r['load_end'][0]:.1f}"))
    w = max(len(a) + len(b) for a, b, _ in rows) + 3
    return "\n".join(f"{a:<14}{b:<{w - 14}} {c}" for a, b, c in rows)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="short smoke run (0.2 s, scipy 0.01 s)")
    p.add_argument("--duration", type=float, default=4.0, help="simulated seconds (JAX)")
    p.add_argument("--scipy-span", type=float, default=0.1, help="simulated seconds (scipy)")
    p.add_argument("--kinds", nargs="+", default=["translational", "torsional"])
    p.add_argument("--cache", action="store_true", help="keep the persistent compilation cache")
    p.add_argument("--tolerances", type=float, nargs="*", default=[1e-4, 5e-5],
                   help="further rtol = atol of JAX runs (cost, accuracy and spectral lines)")
    p.add_argument("--json", action="store_true", help="print JSON instead of the table")
    args = p.parse_args(argv)
    if args.quick:
        args.duration, args.scipy_span = 0.2, 0.01
    if not args.cache:
        os.environ["DTWIN_JAX_CACHE"] = "off"
    import dtwin  # noqa: F401  (float64, cache setting)

    results = [bench_kind(k, args) for k in args.kinds]
    if args.json:
        print(json.dumps(results, indent=1, default=float))
    else:
        print(_table(results))
    return results


if __name__ == "__main__":
    main()
