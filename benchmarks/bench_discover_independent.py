"""Discovery on the independent records (issue #19): wall and CPU time per record.

The user's spec (``../shared/independent/gearbox.toml``) is calibrated on ``baseline-1.csv``
(:func:`dtwin.identify.calibrate.calibrate`; timed separately, or skipped with ``--spec``
naming a calibrated spec), then ``discover`` runs on each record with the default settings
(``DiscoverySettings()``: n_boot 400, max_steps 3), each in this process one after the other
(the first pays the compilations). Target: ≤ 5 min per record on the 2-core CPU. Reports per
record: wall and CPU time, load average, the groups named, the gap before and after, the
located modulation frequency.

Usage: ``python benchmarks/bench_discover_independent.py [--spec CAL.toml] [--records a b]
[--max-steps 3] [--json]``
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

from _timing import load_average  # noqa: E402

IND = Path(__file__).resolve().parents[2] / "shared" / "independent"
RECORDS = ["baseline-2", "sun-fault-0.15", "sun-fault-0.30", "sun-fault-0.60", "sun-fault-0.90",
           "sun-ecc", "planet-fault", "ring-fault", "spacing", "load-fluct", "tone"]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--spec", type=Path, default=None, help="a calibrated spec (skip calibrate)")
    p.add_argument("--records", nargs="*", default=RECORDS)
    p.add_argument("--max-steps", type=int, default=3)
    p.add_argument("--quick", action="store_true", help="load-fluct and tone, one step")
    p.add_argument("--json", action="store_true", help="one JSON list on stdout (run_all.py)")
    args = p.parse_args(argv)
    if args.quick:
        args.records, args.max_steps = ["load-fluct", "tone"], 1
    if not (IND / "baseline-1.csv").exists():
        print("[]" if args.json else f"no independent records at {IND}")
        return 0

    from dtwin.identify.calibrate import calibrate
    from dtwin.identify.discover import DiscoverySettings, discover
    from dtwin.io.readers import read_record

    spec = args.spec
    if spec is None:
        w0 = time.perf_counter()
        res = calibrate([IND / "baseline-1.csv"], IND / "gearbox.toml")
        spec = Path(tempfile.mkdtemp()) / "calibrated.toml"
        res.write_spec(spec)
        rows = [dict(kind="calibrate", run_s=time.perf_counter() - w0)]
    else:
        rows = []
    for name in args.records:
        load0, w0, c0 = load_average()[0], time.perf_counter(), time.process_time()
        r = discover(read_record(IND / f"{name}.csv"), spec,
                     settings=DiscoverySettings(max_steps=args.max_steps))
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        row = dict(kind="discover_independent", record=name, run_s=wall, cpu_s=cpu,
                   load_before=load0, load_after=load_average()[0], named=r.named,
                   groups=r.groups, summaries=[s.summary for s in r.steps],
                   gap_before_db=r.initial_gap.total, gap_after_db=r.final_gap.total,
                   located_hz=None if r.modulation is None else r.modulation.f_x,
                   stop=r.stop_reason, target_s=300.0)
        rows.append(row)
        if not args.json:
            print(f"{name:16s} {wall:7.1f} s wall {cpu:7.1f} s CPU load {load0:4.1f} "
                  f"named {r.named} gap {row['gap_before_db']:.2f} → {row['gap_after_db']:.2f} dB "
                  f"({r.stop_reason})", flush=True)
    if args.json:
        print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
