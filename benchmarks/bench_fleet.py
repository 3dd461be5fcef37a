"""Benchmark: fleet throughput — one vmapped ``fit_batch`` call vs a loop of single fits.

A small fleet of `--records` short synthetic records of the paper's gearbox (torsional twin,
`--duration` s at 5 kHz, `--snr` dB, sun-fault severities spread over 0.35 … 0.65, input speeds
spread over 29.5 … 30.6 Hz and estimated from each record), one free parameter (``sun_fault``,
start 0.3), residuals in the order domain (``Features(grid="orders", f_max=31.5)``, the fleet's
default), Levenberg–Marquardt (`--tol`, `--max-steps`) with forward-mode Jacobians, intervals
computed (as :mod:`dtwin.identify.fleet` does). The same records and settings for both paths:

- **loop**: ``dtwin.identify.fit.fit`` record after record (one start each);
- **batch**: ``dtwin.identify.fit.fit_batch`` on all records: one compiled, ``vmap``-ed optimistix
  call (records step in lockstep; the batch costs its slowest member's iterations).

Each is called twice: the first call includes compilation (the persistent compilation cache
is off unless `--cache`), the second is the steady-state cost. Reported: wall and process
(CPU) seconds, records per minute (second call), compile time, the largest difference of the
fitted severities between the two, the JAX device and the load average before and after (the
shared 2-core machine is loaded by other developers: CPU time is the more reliable figure).

Usage: ``python benchmarks/bench_fleet.py [--records 4] [--duration 0.35] [--tol 1e-3]
[--json] [--quick]``
"""

from __future__ import annotations

import argparse
import json
import os
import sys

from _timing import load_average, timed  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--records", type=int, default=4)
    p.add_argument("--duration", type=float, default=0.35)
    p.add_argument("--max-steps", type=int, default=40)
    p.add_argument("--tol", type=float, default=1e-3)
    p.add_argument("--snr", type=float, default=30.0)
    p.add_argument("--cache", action="store_true", help="keep the persistent compile cache")
    p.add_argument("--quick", action="store_true", help="3 records")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    if not args.cache:
        os.environ["DTWIN_JAX_CACHE"] = "off"
    n = 3 if args.quick else args.records
    load_before = load_average()

    import jax
    import numpy as np

    from dtwin.build import build_twin
    from dtwin.faults import MissingTooth
    from dtwin.identify.fit import fit, fit_batch
    from dtwin.identify.residuals import Features
    from dtwin.simulate import DAQ, simulate
    from dtwin.spec import preset

    spec = preset("paper-sim")
    sev = np.linspace(0.35, 0.65, n)
    speeds = np.linspace(29.5, 30.6, n)
    recs = []
    for i, (s, f) in enumerate(zip(sev, speeds, strict=True)):
        tw = build_twin(spec, kind="torsional", faults=(MissingTooth(float(s), location="sun"),),
                        f_sun=float(f))
        recs.append(simulate(tw, duration=args.duration, f_sun=float(f),
                             daq=DAQ(sample_rate=5000.0, snr_db=args.snr), discard=0.05,
                             seed=i).to_record())
    kw = dict(kind="torsional", initial={"sun_fault": 0.3}, max_steps=args.max_steps,
              tol=args.tol, features=Features(grid="orders", f_max=31.5))

    def loop():
        return [fit(r, spec, ["sun_fault"], **kw) for r in recs]

    def batch():
        return fit_batch(recs, spec, ["sun_fault"], **kw)

    res = {}
    for name, fn in (("loop", loop), ("batch", batch)):
        out1, w1, c1 = timed(fn)
        out2, w2, c2 = timed(fn)
        res[name] = dict(first_wall_s=w1, first_cpu_s=c1, wall_s=w2, cpu_s=c2,
                         compile_s=max(w1 - w2, 0.0),
                         records_per_min=60.0 * n / w2, records_per_cpu_min=60.0 * n / c2,
                         iterations=[f.iterations for f in out2],
                         converged=[bool(f.converged) for f in out2],
                         severity=[f.values["sun_fault"] for f in out2],
                         theta=[float(f.theta[0]) for f in out2])
    diff = float(np.max(np.abs(np.subtract(res["loop"]["severity"], res["batch"]["severity"]))))
    dtheta = float(np.max(np.abs(np.subtract(res["loop"]["theta"], res["batch"]["theta"]))))
    record = {
        "kind": "fleet_throughput", "records": n, "duration_s": args.duration,
        "speeds_hz": speeds.tolist(), "snr_db": args.snr, "tol": args.tol,
        "max_steps": args.max_steps, "max_theta_diff": dtheta,
        "device": str(jax.devices()[0]), "cpu_count": os.cpu_count(),
        "load_before": load_before, "load_after": load_average(), "loop": res["loop"],
        "batch": res["batch"], "speedup_wall": res["batch"]["records_per_min"]
        / res["loop"]["records_per_min"],
        "speedup_cpu": res["batch"]["records_per_cpu_min"] / res["loop"]["records_per_cpu_min"],
        "max_severity_diff": diff, "truth": sev.tolist(),
    }
    if args.json:
        print(json.dumps([record]))
        return 0
    print(f"fleet of {n} records of {args.duration} s at {speeds.min():.1f}–{speeds.max():.1f} Hz"
          f", tol {args.tol:g}, device {record['device']}, "
          f"load {load_before} -> {record['load_after']}")
    print(f"{'':8} {'compile s':>10} {'wall s':>8} {'CPU s':>8} {'rec/min':>8} "
          f"{'rec/CPU-min':>12}  iterations (converged)")
    for name in ("loop", "batch"):
        r = res[name]
        print(f"{name:8} {r['compile_s']:>10.1f} {r['wall_s']:>8.1f} {r['cpu_s']:>8.1f} "
              f"{r['records_per_min']:>8.2f} {r['records_per_cpu_min']:>12.2f}  {r['iterations']} "
              f"({sum(r['converged'])}/{n})")
    print(f"batch / loop throughput: {record['speedup_wall']:.2f}× wall, "
          f"{record['speedup_cpu']:.2f}× CPU; largest difference: severity {diff:.2e}, "
          f"θ {dtheta:.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
