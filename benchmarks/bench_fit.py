"""Benchmark: a full identification fit of a 4 s record, JAX vs SciPy with finite differences.

Issue 7, item 9. The record: the paper's gearbox (``build_twin(preset("paper-sim"))``, torsional
twin, sun missing tooth of severity 0.5, ideal speed source), `--duration` s (default 4) at
5 kHz, 10 dB SNR, seed 3, input speed given (30 Hz). Three free parameters, starting values
20 % off, in one of two cases (`--case`):

- ``determined`` (default): ``sun_fault, sensor_gain, k_sun_planet`` (the sensor gain free,
  so not profiled: ``Features(gain="fixed")``), parameters this record determines by the
  identifiability flags of `dtwin.identify.uncertainty` at the truth (95 % half-widths 21 %, 29 %
  and 49 % of the values; k_sun_planet is at the flag's 50 % margin; benchmarks/README.md
  "Fit" lists the candidates checked).
- ``stiffness``: ``sun_fault, k_sun_planet, k_ring_planet`` with the gain profiled — the two
  mesh stiffnesses are NOT determined by a 5 kHz steady record (their modes sit at 6.8–12 kHz,
  docs/identification.md): the cost of a fit whose parameters the data do not pin (LM wanders).

- **JAX** (`dtwin.identify.fit.fit`): Levenberg–Marquardt (optimistix), forward-mode Jacobians
  through diffrax, called twice with different starts: the first call includes compilation
  (persistent cache off unless `--cache`), the second is the cost of a fit once compiled
  (wall, CPU, LM steps, intervals). Then one residual evaluation (= one simulation and the
  spectrum) and one forward-mode Jacobian (``dtwin.identify.solve.jacobian_at``: residuals and Jacobian
  from one primal-and-tangents solve), each timed after compilation, five times interleaved:
  the Jacobian's cost relative to one simulation as the median of the five pairs' ratios.
- **SciPy** (what a user without JAX writes): the same residual vector computed from
  `tests/reference_numpy.py` (the twin's equations in NumPy) integrated by
  ``scipy.integrate.solve_ivp`` (RK45, same rtol/atol/largest step), the same DAQ filter and
  the same log-spectral residuals; ``scipy.optimize.least_squares(method="lm")`` would take
  ``1 + p`` such simulations per finite-difference Jacobian. One simulation over
  `--scipy-span` s is timed and extrapolated **linearly** to the record's length (a full SciPy
  fit of a 4 s record takes hours on this machine); the SciPy fit time is that times the
  number of simulations: (steps + 1) × (1 + p), the LM steps taken from the JAX fit (stated as
  an assumption: SciPy's LM on the same problem takes a similar number of steps).

`--periodic` fits with ``periodic="auto"`` (`dtwin.simulation.simulate.SolverOptions.periodic`: the record
simulated over a 0.1 s settling time and one hunting period, 1.13 s here, and tiled; issue #21
lever 2) when the library has it; without it the fit simulates the whole record
(``periodic="off"``, or a library without the option: `benchmarks/compare.py` then puts the
two side by side); `periodic` in the JSON says which was used.

`--rtol` sets the simulation tolerance of the fit (``rtol = atol``, `dtwin.identify.fit.make_problem`;
library default 1e-5), for JAX and SciPy alike.

Usage: ``python benchmarks/bench_fit.py [--case determined|stiffness] [--duration 4]
[--rtol 1e-5] [--tol TOL] [--scipy-span 0.35] [--periodic] [--cache] [--json] [--quick]``
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from _timing import load_average, timed  # noqa: E402

HERE = Path(__file__).resolve().parent
FREE = {"determined": ("sun_fault", "sensor_gain", "k_sun_planet"),
        "stiffness": ("sun_fault", "k_sun_planet", "k_ring_planet")}


def say(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--case", choices=sorted(FREE), default="determined")
    p.add_argument("--duration", type=float, default=4.0)
    p.add_argument("--rtol", type=float, default=1e-5, help="simulation rtol = atol of the fit")
    p.add_argument("--scipy-span", type=float, default=0.35)
    p.add_argument("--max-steps", type=int, default=30)
    p.add_argument("--tol", type=float, default=None,
                   help="the fit's Cauchy tolerance (dtwin.identify.fit.fit's `tol`; default: fit's)")
    p.add_argument("--cache", action="store_true", help="keep the persistent compile cache")
    p.add_argument("--periodic", action="store_true",
                   help="fit with periodic='auto' (one hunting period, tiled) where supported")
    p.add_argument("--quick", action="store_true", help="0.5 s record, 0.03 s SciPy span")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    if not args.cache:
        os.environ["DTWIN_JAX_CACHE"] = "off"
    if args.quick:
        args.duration, args.scipy_span = 0.5, 0.03
    free = FREE[args.case]

    import jax
    import jax.numpy as jnp
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    from dtwin.identify.fit import fit, make_problem
    from dtwin.identify.params import current_value
    from dtwin.identify.residuals import Features, observation_residuals, observe
    from dtwin.identify.solve import jacobian_at
    from dtwin.model.faults import MissingTooth
    from dtwin.simulation.simulate import DAQ, daq_filter, initial_state, simulate
    from dtwin.spec import preset
    from dtwin.spec.build import build_twin

    load_start = load_average()
    f_sun, fs = 30.0, 5000.0
    spec = preset("paper-sim")
    truth_tw = build_twin(spec, kind="torsional", faults=(MissingTooth(0.5, location="sun"),))
    truth = {n: current_value(truth_tw, n) for n in free}
    rec = simulate(truth_tw, duration=args.duration, f_sun=f_sun,
                   daq=DAQ(sample_rate=fs, snr_db=10.0), discard=0.05, seed=3).to_record()
    # a free sensor gain replaces the profiled one (dtwin.identify.residuals, "Gain")
    feats = Features(gain="fixed" if "sensor_gain" in free else "profile")
    kw = dict(f_sun=f_sun, features=feats, rtol=args.rtol, atol=args.rtol)
    import inspect

    has_periodic = "periodic" in inspect.signature(make_problem).parameters
    periodic = args.periodic and has_periodic
    if has_periodic:
        kw["periodic"] = "auto" if periodic else "off"
    starts = [{n: truth[n] * f for n, f in zip(free, (0.8, 1.2, 0.8), strict=True)},
              {n: truth[n] * f for n, f in zip(free, (1.2, 0.8, 1.2), strict=True)}]
    out = {"kind": "fit", "case": args.case, "duration": args.duration, "free": list(free),
           "rtol": args.rtol, "tol": args.tol, "truth": truth, "load_start": load_start,
           "periodic": bool(periodic)}

    # --- JAX fit, twice (compile + run, then run)
    fits = []
    tol = {} if args.tol is None else {"tol": args.tol}
    for i, start in enumerate(starts):
        say(f"JAX fit {i + 1} of 2 ({'with compilation' if i == 0 else 'compiled'}) from {start}")
        res, wall, cpu = timed(lambda s=start: fit(rec, spec, list(free), initial=s,
                                                     max_steps=args.max_steps, **tol, **kw))
        iv = {n: res.interval(n) for n in free}
        fits.append(dict(wall_s=wall, cpu_s=cpu, steps=res.iterations, converged=res.converged,
                         values=res.values, load=load_average(), intervals_95=iv,
                         truth_inside={n: bool(iv[n][0] <= truth[n] <= iv[n][1]) for n in free},
                         not_determined=res.not_determined,
                         evaluations=len(res.loss_history), loss=res.loss,
                         loss_history=res.loss_history,
                         rel_error={n: res.values[n] / truth[n] - 1 for n in free}))
        say(f"  {wall:.1f} s wall, {cpu:.1f} s CPU, {res.iterations} steps, "
            f"converged {res.converged}")
        if i == 0:
            out["compile_and_fit_s"] = wall
            out["compile_and_fit_cpu_s"] = cpu
    out["jax_fit"] = fits[1]
    out["jax_fit_first"] = fits[0]
    out["compile_s"] = fits[0]["wall_s"] - fits[1]["wall_s"]

    # --- one simulation (residual evaluation) vs one forward-mode Jacobian, compiled
    say("one residual evaluation vs one forward Jacobian")
    prob, _ = make_problem(rec, spec, list(free), initial=truth, **kw)
    theta = jnp.zeros(len(free))
    import equinox as eqx

    res_fn = eqx.filter_jit(lambda t, pr: pr.residuals(t))
    jax.block_until_ready(res_fn(theta, prob))
    jax.block_until_ready(jacobian_at(theta, prob))
    # interleaved repeats (simulation, Jacobian, simulation, …) so that drift in the machine's
    # load hits both alike; each figure is the median of its repeats, the ratio theirs
    reps = 5 if args.duration >= 2 else 9
    sims, jacs = [], []
    for _ in range(reps):
        sims.append(timed(lambda: jax.block_until_ready(res_fn(theta, prob)))[1:])
        jacs.append(timed(lambda: jax.block_until_ready(jacobian_at(theta, prob)))[1:])
    sim_wall, sim_cpu = (float(np.median(v)) for v in zip(*sims, strict=True))
    jac_wall, jac_cpu = (float(np.median(v)) for v in zip(*jacs, strict=True))
    out["simulation_s"] = sim_wall
    out["simulation_cpu_s"] = sim_cpu
    out["jacobian_s"] = jac_wall
    out["jacobian_cpu_s"] = jac_cpu
    out["simulation_repeats_s"] = [w for w, _ in sims]
    out["jacobian_repeats_s"] = [w for w, _ in jacs]
    # the ratio as the median over the pairs (each Jacobian over the simulation just before
    # it): the shared 2-core machine switches between a fast and a ~35 % slower state within
    # seconds, and a pair usually falls in one state where the medians may not
    out["jacobian_over_simulation"] = float(np.median([j[0] / s_[0] for s_, j in zip(sims, jacs, strict=True)]))
    out["jacobian_over_simulation_cpu"] = float(np.median([j[1] / s_[1] for s_, j in zip(sims, jacs, strict=True)]))

    # --- SciPy: the same residuals from solve_ivp over the NumPy model, one span timed
    import scipy.integrate

    sys.path.insert(0, str(HERE.parent / "tests"))  # the test oracle lives with the tests
    from reference_numpy import ReferenceModel

    tw0 = prob.pset.apply(prob.twin, prob.pset.values(theta))
    from dtwin.identify.residuals import _with_speed

    tw0 = _with_speed(tw0, prob.observations[0])
    ref = ReferenceModel(tw0)
    obs = prob.observations[0]
    taps = daq_filter(obs.oversample)
    half = (len(taps) - 1) // 2
    fs_hi = fs * obs.oversample
    n_out = int(round(args.scipy_span * fs))
    ts = obs.discard + np.arange(-half, n_out * obs.oversample + half) / fs_hi
    z0, zd0, aux0 = initial_state(tw0, f_sun, "steady")
    y0 = ref.scale(np.asarray(z0), np.asarray(zd0), np.asarray(aux0))
    f_mesh = f_sun / (1 + ref.zr / ref.zs) * ref.zr

    def scipy_signal():
        sol = scipy.integrate.solve_ivp(ref.rhs, (ts[0], ts[-1]), y0, method="RK45",
                                        rtol=prob.rtol, atol=prob.atol, max_step=0.1 / f_mesh,
                                        t_eval=ts)
        acc = ref.sensor_along(ts, sol.y)
        return np.convolve(acc, taps, mode="valid")[:: obs.oversample][:n_out]

    say(f"SciPy: solve_ivp over {args.scipy_span:g} s")
    sig, sp_wall, sp_cpu = timed(scipy_signal)
    # the residuals of that span against the record's first span (shows the pipeline runs)
    from dtwin.io.record import Record

    short = Record(rec.data[:, :n_out], rec.sample_rate, rec.channels, rec.units)
    try:
        r_short = observation_residuals(jnp.asarray(sig), observe(short, prob.twin, f_sun=f_sun,
                                                                  features=feats))
        out["scipy_residuals_finite"] = bool(np.all(np.isfinite(np.asarray(r_short))))
    except Exception as e:  # a span too short for the sideband check: timing still valid
        out["scipy_residuals_finite"] = f"not computed ({e})"
    scale = args.duration / args.scipy_span
    sim_scipy = sp_wall * scale
    p_ = len(free)
    n_sims = (fits[1]["steps"] + 1) * (1 + p_)
    out["scipy"] = dict(span_s=args.scipy_span, span_wall_s=sp_wall, span_cpu_s=sp_cpu,
                        simulation_extrapolated_s=sim_scipy,
                        fd_jacobian_extrapolated_s=(1 + p_) * sim_scipy,
                        simulations_per_fit=n_sims, fit_extrapolated_s=n_sims * sim_scipy)
    out["speedup_fit_wall"] = n_sims * sim_scipy / fits[1]["wall_s"]
    out["speedup_fit_cpu"] = n_sims * sp_cpu * scale / fits[1]["cpu_s"]
    out["speedup_jacobian_wall"] = (1 + p_) * sim_scipy / out["jacobian_s"]
    out["load_end"] = load_average()
    out["device"] = str(jax.devices()[0])

    if args.json:
        print(json.dumps([out], default=float))
        return 0
    f = out["jax_fit"]
    print(f"case {args.case}: record {args.duration:g} s at 5 kHz, free {', '.join(free)}, "
          f"rtol = atol = {args.rtol:g}, {'periodic' if periodic else 'full'} simulation; load {load_start} → {out['load_end']}")
    print(f"JAX fit: {f['wall_s']:.1f} s wall ({f['cpu_s']:.1f} s CPU), {f['steps']} LM steps, "
          f"{f['evaluations']} evaluations, converged {f['converged']}; first call (with "
          f"compilation) {out['compile_and_fit_s']:.1f} s wall "
          f"({out['compile_and_fit_cpu_s']:.1f} s CPU)")
    for n in free:
        lo, hi = f["intervals_95"][n]
        print(f"  {n}: {f['values'][n]:.5g} (truth {truth[n]:.5g}, {f['rel_error'][n]:+.3f}), "
              f"95 % [{lo:.5g}, {hi:.5g}] {'holds' if f['truth_inside'][n] else 'MISSES'} the "
              f"truth" + (" NOT DETERMINED" if n in f["not_determined"] else ""))
    g = out["jax_fit_first"]
    print("  first call: " + ", ".join(f"{n} {v:.5g}" for n, v in g["values"].items())
          + f", {g['steps']} steps, converged {g['converged']}")
    print(f"one simulation {out['simulation_s']:.2f} s ({out['simulation_cpu_s']:.2f} s CPU), "
          f"forward Jacobian {out['jacobian_s']:.2f} s ({out['jacobian_cpu_s']:.2f} s CPU) "
          f"= {out['jacobian_over_simulation']:.2f}× (CPU {out['jacobian_over_simulation_cpu']:.2f}×)")
    s = out["scipy"]
    print(f"SciPy: {s['span_s']:g} s simulated in {s['span_wall_s']:.1f} s ({s['span_cpu_s']:.1f} s "
          f"CPU) → {s['simulation_extrapolated_s']:.0f} s per {args.duration:g} s simulation, FD "
          f"Jacobian {s['fd_jacobian_extrapolated_s']:.0f} s, fit ({s['simulations_per_fit']} "
          f"simulations) {s['fit_extrapolated_s']:.0f} s → JAX {out['speedup_fit_wall']:.0f}× "
          f"faster (CPU {out['speedup_fit_cpu']:.0f}×)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
