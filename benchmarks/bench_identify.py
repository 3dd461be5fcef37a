"""Identify with a calibrated spec: wall and CPU time per record, and what the fit reads.

``fit(record, spec, free)`` with the library's defaults (the twin the spec was calibrated with,
one start; with a calibrated spec and a free fault severity, both ends of its
excitation/response split where the library fits them, ``dtwin.identify.split``), each record
in this process one after the other (the first pays the compilations). The spec is the user's
``gearbox.toml`` of ``../shared/independent/`` calibrated on ``baseline-1.csv`` unless
``--spec`` names a calibrated spec. Reports per record: wall and CPU time, load average, each
free parameter's value and 95 % interval, the split reported (empty where one was fitted) and
the loss.

Usage: ``python benchmarks/bench_identify.py [--spec CAL.toml] [--records R.csv ...]
[--free sun_fault] [--json]``
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

from _independent import IND, baseline_calibration  # noqa: E402
from _timing import load_average  # noqa: E402

RECORDS = [IND / "sun-fault-0.60.csv"]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--spec", type=Path, default=None, help="a calibrated spec (skip calibrate)")
    p.add_argument("--records", nargs="*", type=Path, default=RECORDS)
    p.add_argument("--free", default="sun_fault", help="comma-separated registry names")
    p.add_argument("--json", action="store_true", help="one JSON list on stdout (run_all.py)")
    args = p.parse_args(argv)
    if args.spec is None and not (IND / "baseline-1.csv").exists():
        print("[]" if args.json else f"no independent records at {IND}")
        return 0

    from dtwin.identify.fit import fit
    from dtwin.io.readers import read_record

    rows: list = []
    spec = args.spec if args.spec is not None else baseline_calibration(rows)
    free = [n.strip() for n in args.free.split(",") if n.strip()]
    for path in args.records:
        load0, w0, c0 = load_average()[0], time.perf_counter(), time.process_time()
        res = fit(read_record(path), spec, free)
        row = dict(kind="identify", record=path.name, run_s=time.perf_counter() - w0,
                   cpu_s=time.process_time() - c0, load_before=load0,
                   load_after=load_average()[0], loss=res.loss,
                   excitation=getattr(res, "excitation", ""),
                   fits=max(1, len(getattr(res, "splits", []))))
        for n in free:
            lo, hi = res.interval(n)
            row.update({n: res.values[n], f"{n}_lo95": lo, f"{n}_hi95": hi,
                        f"{n}_status": res.status(n)})
        rows.append(row)
        if not args.json:
            print(f"{path.name}: {row['run_s']:.1f} s wall ({row['cpu_s']:.1f} s CPU, load "
                  f"{load0:.2f}), " + ", ".join(f"{n} {res.values[n]:.4g} "
                                               f"[{row[f'{n}_lo95']:.4g}, {row[f'{n}_hi95']:.4g}]"
                                               for n in free)
                  + (f", split {row['excitation']}" if row["excitation"] else ""))
    if args.json:
        print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
