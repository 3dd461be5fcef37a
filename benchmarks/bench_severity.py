"""A severity with a calibrated spec: wall and CPU time per record, and what it reads.

``estimate_severity(record, spec, location)`` with the library's defaults (translational twin,
low band, the fault's default shape; with a calibrated spec, both ends of its
excitation/response split where the library fits them), each record in this process one after
the other (the first pays the compilations). The spec is the user's ``gearbox.toml`` of
``../shared/independent/`` calibrated on ``baseline-1.csv`` unless ``--spec`` names a
calibrated spec. Reports per record: wall and CPU time, load average, the peak stiffness loss
with its 95 % interval, the split and (for a planet fault) the planet-tooth flank reported
(empty where one was fitted), the number of fits and the status.

Usage: ``python benchmarks/bench_severity.py [--spec CAL.toml] [--records R.csv ...]
[--location sun] [--json]``
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

RECORDS = [IND / "sun-fault-0.60.csv", IND / "sun-fault-0.15.csv"]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--spec", type=Path, default=None, help="a calibrated spec (skip calibrate)")
    p.add_argument("--records", nargs="*", type=Path, default=RECORDS)
    p.add_argument("--location", default="sun")
    p.add_argument("--quick", action="store_true", help="the first record only")
    p.add_argument("--json", action="store_true", help="one JSON list on stdout (run_all.py)")
    args = p.parse_args(argv)
    if args.quick:
        args.records = args.records[:1]
    if args.spec is None and not (IND / "baseline-1.csv").exists():
        print("[]" if args.json else f"no independent records at {IND}")
        return 0

    from dtwin.identify.severity import estimate_severity
    from dtwin.io.readers import read_record

    rows: list = []
    spec = args.spec if args.spec is not None else baseline_calibration(rows)
    for path in args.records:
        load0, w0, c0 = load_average()[0], time.perf_counter(), time.process_time()
        est = estimate_severity(read_record(path), spec, args.location)
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        row = dict(kind="severity", record=path.name, run_s=wall, cpu_s=cpu, load_before=load0,
                   load_after=load_average()[0], peak_loss_pc=100 * est.peak_loss,
                   peak_lower_pc=100 * est.peak_interval[0],
                   peak_upper_pc=100 * est.peak_interval[1],
                   split=getattr(est, "excitation", ""), flank=getattr(est, "flank", ""),
                   fits=len(est.shapes) or 1,
                   status=est.status)
        rows.append(row)
        if not args.json:
            print(f"{path.name:20s} {wall:7.1f} s wall {cpu:7.1f} s CPU load {load0:4.1f} "
                  f"peak {row['peak_loss_pc']:.1f} % [{row['peak_lower_pc']:.1f}, "
                  f"{row['peak_upper_pc']:.1f}] {row['split'] or '-'} {row['flank'] or '-'} "
                  f"({row['fits']} fits, "
                  f"{row['status']})", flush=True)
    if args.json:
        print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
