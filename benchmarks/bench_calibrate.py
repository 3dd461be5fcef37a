"""Calibration of a 4 s, 5 kHz record (issue 19: at most 2 min on the 2-core CPU).

Calibrates the twin of the independent records' spec (``../shared/independent/gearbox.toml``,
beside the checkout) on ``baseline-1``, or, without that folder, the ``paper-bench`` preset on
the bundled ``data/samples/bench_healthy.dtwin.h5``, and reports the wall and CPU time of the
whole calibration (speed estimate, the simulation and its Jacobian through the solve, the
cross-validated fits, the final fit and the confirming simulation), the gaps and the load
average. ``--json`` prints a list of records for ``run_all.py``; ``--quick`` is the same run.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import _timing

ROOT = Path(__file__).resolve().parents[1]
IND = ROOT.parent / "shared" / "independent"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", action="store_true")
    p.add_argument("--quick", action="store_true")
    args = p.parse_args(argv)

    from dtwin.identify.calibrate import calibrate

    if (IND / "baseline-1.csv").exists():
        records, spec, name = [IND / "baseline-1.csv"], IND / "gearbox.toml", "independent"
    else:
        records = [ROOT / "data" / "samples" / "bench_healthy.dtwin.h5"]
        spec = ROOT / "dtwin" / "spec" / "presets" / "paper-bench.toml"
        name = "bench_healthy"
    stages: list[tuple[float, str]] = []
    t0 = time.perf_counter()
    load0 = _timing.load_average()
    res, wall, cpu = _timing.timed(lambda: calibrate(
        records, spec, progress=lambda m: stages.append((time.perf_counter() - t0, m))))
    out = [{
        "kind": "calibrate", "record": name, "run_s": wall, "cpu_s": cpu,
        "load_before": load0, "load_after": _timing.load_average(),
        "gap_before_db": res.gap_before.total, "gap_heldout_db": res.gap_heldout.total,
        "gap_confirmed_db": res.gap_confirmed.total,
        "stages": [{"at_s": round(t, 2), "stage": m} for t, m in stages],
    }]
    if args.json:
        print(json.dumps(out))
    else:
        for r in out:
            print(f"calibrate {r['record']}: {r['run_s']:.1f} s wall, {r['cpu_s']:.1f} s CPU "
                  f"(load {r['load_before'][0]:.2f} → {r['load_after'][0]:.2f}); gap "
                  f"{r['gap_before_db']:.2f} → {r['gap_confirmed_db']:.2f} dB")
            for s in r["stages"]:
                print(f"  {s['at_s']:7.1f} s  {s['stage']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
