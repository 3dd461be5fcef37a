"""Benchmark: fleet throughput — one vmapped ``fit_batch`` call vs a loop of single fits.

A small fleet of `--records` short synthetic records of the paper's gearbox (torsional twin,
`--duration` s at 5 kHz, `--snr` dB, sun-fault severities spread over 0.35 … 0.65, input speeds
spread over 29.5 … 30.6 Hz and estimated from each record), one free parameter (``sun_fault``,
start 0.3), residuals in the order domain (``Features(grid="orders", f_max=31.5)``, the fleet's
default), Levenberg–Marquardt (`--tol`, `--max-steps`) with forward-mode Jacobians, intervals
computed (as :mod:`dtwin.identify.fleet` does). The same records and settings for both paths:

- **loop**: ``dtwin.identify.fit.fit`` record after record (one start each);
- **batch**: ``dtwin.identify.fit.fit_batch`` on all records: one compiled call (``vmap`` on a
  GPU, where the records step in lockstep and the batch costs its slowest member's iterations;
  ``jax.lax.map`` on a CPU).

Each is called twice: the first call includes compilation (the persistent compilation cache
is off unless `--cache`), the second is the steady-state cost. Reported: wall and process
(CPU) seconds, records per minute (second call), compile time, the largest difference of the
fitted severities between the two, the JAX device and the load average before and after (the
shared 2-core machine is loaded by other developers: CPU time is the more reliable figure).

`--sizes 3,32,128` times the batch at several fleet sizes (the records are the first *n* of
one fleet of ``max(sizes)``; each size compiles its own program); the loop runs on the first
size only, or not at all with `--no-loop`. `--records-file F` reads the fleet (and its duration
and SNR) from the pickle `F` when it exists and writes it there otherwise, so that a GPU machine
need not simulate it;
`--out F` appends one JSON line per size as soon as it is measured.

Usage: ``python benchmarks/bench_fleet.py [--records 4] [--duration 0.35] [--tol 1e-3]
[--sizes 3,32] [--no-loop] [--records-file F] [--out F] [--json] [--quick]``
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import sys

from _timing import load_average, timed  # noqa: E402


def _fleet(n: int, duration: float | None, snr: float | None, path: str | None):
    """`n` records (severities 0.35 … 0.65, speeds 29.5 … 30.6 Hz), read from or written to
    the pickle `path`; `duration` (s) and `snr` (dB) default to the file's, else 0.35 s and
    30 dB. Returns (records, severities, speeds, duration, snr)."""
    import numpy as np

    if path and os.path.exists(path):
        with open(path, "rb") as fh:
            saved = pickle.load(fh)
        duration = saved["duration"] if duration is None else duration
        snr = saved["snr"] if snr is None else snr
        if len(saved["records"]) < n or saved["duration"] != duration or saved["snr"] != snr:
            raise SystemExit(
                f"{path} holds {len(saved['records'])} records of "
                f"{saved['duration']} s at {saved['snr']} dB; asked for {n} of "
                f"{duration} s at {snr} dB: remove it or change the options"
            )
        truth, speeds = np.asarray(saved["truth"]), np.asarray(saved["speeds"])
        return saved["records"], truth, speeds, duration, snr
    duration = 0.35 if duration is None else duration
    snr = 30.0 if snr is None else snr
    import jax

    from dtwin.model.faults import MissingTooth
    from dtwin.simulation.simulate import DAQ, simulate
    from dtwin.spec import preset
    from dtwin.spec.build import build_twin

    spec = preset("paper-sim")
    sev = np.linspace(0.35, 0.65, n)
    speeds = np.linspace(29.5, 30.6, n)
    recs = []
    for i, (s, f) in enumerate(zip(sev, speeds, strict=True)):
        tw = build_twin(
            spec, kind="torsional", faults=(MissingTooth(float(s), location="sun"),), f_sun=float(f)
        )
        recs.append(
            simulate(
                tw,
                duration=duration,
                f_sun=float(f),
                daq=DAQ(sample_rate=5000.0, snr_db=snr),
                discard=0.05,
                seed=i,
            ).to_record()
        )
        # each record's twin is its own compiled program (severity and speed are static):
        # without this a fleet of hundreds fills the memory with them
        jax.clear_caches()
    if path:
        tmp = f"{path}.tmp"
        with open(tmp, "wb") as fh:
            pickle.dump(
                {
                    "records": recs,
                    "truth": sev.tolist(),
                    "speeds": speeds.tolist(),
                    "duration": duration,
                    "snr": snr,
                },
                fh,
            )
        os.replace(tmp, path)
    return recs, sev, speeds, duration, snr


def _summary(out, n, w1, c1, w2, c2, truth) -> dict:
    import numpy as np

    sev = [float(f.values["sun_fault"]) for f in out]
    return dict(
        first_wall_s=w1,
        first_cpu_s=c1,
        wall_s=w2,
        cpu_s=c2,
        compile_s=max(w1 - w2, 0.0),
        records_per_min=60.0 * n / w2,
        records_per_cpu_min=60.0 * n / c2,
        iterations=[int(f.iterations) for f in out],
        converged=[bool(f.converged) for f in out],
        severity=sev,
        theta=[float(f.theta[0]) for f in out],
        max_abs_error=float(np.max(np.abs(np.subtract(sev, truth[:n])))),
    )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--records", type=int, default=4)
    p.add_argument("--duration", type=float, default=None, help="s (default 0.35)")
    p.add_argument("--max-steps", type=int, default=40)
    p.add_argument("--tol", type=float, default=1e-3)
    p.add_argument("--snr", type=float, default=None, help="dB (default 30)")
    p.add_argument("--sizes", default=None, help="comma-separated fleet sizes for the batch")
    p.add_argument("--no-loop", action="store_true", help="time the batch only")
    p.add_argument("--records-file", default=None, help="pickle of the fleet (read or written)")
    p.add_argument("--out", default=None, help="append a JSON line per size to this file")
    p.add_argument("--cache", action="store_true", help="keep the persistent compile cache")
    p.add_argument("--quick", action="store_true", help="3 records")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    if not args.cache:
        os.environ["DTWIN_JAX_CACHE"] = "off"
    n0 = 3 if args.quick else args.records
    sizes = [int(s) for s in args.sizes.split(",")] if args.sizes else [n0]
    if any(s < 1 for s in sizes):
        raise SystemExit(f"--sizes must be positive integers, got {args.sizes!r}")
    load_before = load_average()

    import jax
    import numpy as np

    from dtwin.identify.fit import fit, fit_batch
    from dtwin.identify.residuals import Features
    from dtwin.spec import preset

    spec = preset("paper-sim")
    recs, sev, speeds, args.duration, args.snr = _fleet(
        max(sizes), args.duration, args.snr, args.records_file
    )
    kw = dict(
        kind="torsional",
        initial={"sun_fault": 0.3},
        max_steps=args.max_steps,
        tol=args.tol,
        features=Features(grid="orders", f_max=31.5),
    )
    device = str(jax.devices()[0])
    records_out = []
    for k, n in enumerate(sizes):
        fleet = recs[:n]
        paths = [("batch", lambda f=fleet: fit_batch(f, spec, ["sun_fault"], **kw))]
        if k == 0 and not args.no_loop:
            paths.insert(
                0, ("loop", lambda f=fleet: [fit(r, spec, ["sun_fault"], **kw) for r in f])
            )
        res = {}
        for name, fn in paths:
            out1, w1, c1 = timed(fn)
            out2, w2, c2 = timed(fn)
            res[name] = _summary(out2, n, w1, c1, w2, c2, sev)
        record = {
            "kind": "fleet_throughput",
            "records": n,
            "duration_s": args.duration,
            "speeds_hz": speeds[:n].tolist(),
            "snr_db": args.snr,
            "tol": args.tol,
            "max_steps": args.max_steps,
            "device": device,
            "backend": jax.default_backend(),
            "cpu_count": os.cpu_count(),
            "jax": jax.__version__,
            "load_before": load_before,
            "load_after": load_average(),
            "truth": sev[:n].tolist(),
            **res,
        }
        if "loop" in res:
            b, lp = res["batch"], res["loop"]
            record.update(
                speedup_wall=b["records_per_min"] / lp["records_per_min"],
                speedup_cpu=b["records_per_cpu_min"] / lp["records_per_cpu_min"],
                max_severity_diff=float(np.max(np.abs(np.subtract(lp["severity"], b["severity"])))),
                max_theta_diff=float(np.max(np.abs(np.subtract(lp["theta"], b["theta"])))),
            )
        records_out.append(record)
        if args.out:
            with open(args.out, "a") as fh:
                fh.write(json.dumps(record) + "\n")
        if not args.json:
            _print(record, args)
    if args.json:
        print(json.dumps(records_out))
    return 0


def _print(record: dict, args) -> None:
    n = record["records"]
    sp = record["speeds_hz"]
    print(
        f"fleet of {n} records of {args.duration} s at {min(sp):.1f}–{max(sp):.1f} Hz"
        f", tol {args.tol:g}, device {record['device']}, "
        f"load {record['load_before']} -> {record['load_after']}"
    )
    print(
        f"{'':8} {'compile s':>10} {'wall s':>8} {'CPU s':>8} {'rec/min':>8} "
        f"{'rec/CPU-min':>12} {'max |err|':>9}  iterations (converged)"
    )
    for name in ("loop", "batch"):
        if name not in record:
            continue
        r = record[name]
        its = r["iterations"] if n <= 8 else f"{min(r['iterations'])}–{max(r['iterations'])}"
        print(
            f"{name:8} {r['compile_s']:>10.1f} {r['wall_s']:>8.1f} {r['cpu_s']:>8.1f} "
            f"{r['records_per_min']:>8.2f} {r['records_per_cpu_min']:>12.2f} "
            f"{r['max_abs_error']:>9.3f}  {its} ({sum(r['converged'])}/{n})"
        )
    if "speedup_wall" in record:
        print(
            f"batch / loop throughput: {record['speedup_wall']:.2f}× wall, "
            f"{record['speedup_cpu']:.2f}× CPU; largest difference: severity "
            f"{record['max_severity_diff']:.2e}, θ {record['max_theta_diff']:.2e}"
        )


if __name__ == "__main__":
    sys.exit(main())
