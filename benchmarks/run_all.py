"""Run every benchmark script in this folder (``bench_*.py``) and print one table.

Each script is run in its own process with ``--json`` (plus ``--quick`` when given here) and
must print a JSON list of result records (dicts with a ``kind`` key) on stdout. The table
lists, per script and record, the headline figures found in the records; the load average
before and after each script is printed with it (timings on a shared machine are inflated by
the load). ``make bench`` calls this script.

Usage: ``python benchmarks/run_all.py [--quick] [--only NAME ...] [--json]``; with ``--json``
the table goes to stderr and stdout carries ``{script: {"records": [...], "wall_s": ...}}``
(what ``benchmarks/compare.py`` puts side by side).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

#: (key path, label, format) of the figures shown in the table when a record has them.
HEADLINE = (
    (("compile_s",), "compile", "{:.1f} s"),
    (("compile_cpu_s",), "compile (CPU)", "{:.1f} s"),
    (("run_s",), "run", "{:.2f} s"),
    (("sim_s_per_wall_s",), "sim s / wall s", "{:.2f}"),
    (("sim_s_per_cpu_s",), "sim s / CPU s", "{:.2f}"),
    (("steps_per_sim_s",), "steps / sim s", "{:.0f}"),
    (("us_per_step",), "µs / step", "{:.1f}"),
    (("RK45", "ratio_vs_jax"), "× vs scipy RK45", "{:.0f}"),
    (("DOP853", "ratio_vs_jax"), "× vs scipy DOP853", "{:.0f}"),
    (("RK45", "ratio_vs_jax_cpu"), "× vs scipy RK45 (CPU time)", "{:.0f}"),
    (("DOP853", "ratio_vs_jax_cpu"), "× vs scipy DOP853 (CPU time)", "{:.0f}"),
    (("cpu_us_per_step",), "CPU µs / step", "{:.1f}"),
    (("rel_diff", "jax_vs_RK45"), "rms diff JAX−RK45", "{:.1e}"),
    (("f_max_hz",), "f_max (Hz)", "{:.0f}"),
    (("loop", "records_per_min"), "records/min, loop", "{:.2f}"),
    (("batch", "records_per_min"), "records/min, batch", "{:.2f}"),
    (("speedup_wall",), "speed-up (wall)", "{:.2f}"),
    (("speedup_cpu",), "speed-up (CPU)", "{:.2f}"),
)


def _get(record, path):
    for key in path:
        if not isinstance(record, dict) or key not in record:
            return None
        record = record[key]
    return record


def _loadavg() -> str:
    with open("/proc/loadavg") as f:
        return " ".join(f.read().split()[:3])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="pass --quick to every script")
    p.add_argument("--only", nargs="+", default=None, help="script names (without .py) to run")
    p.add_argument("--json", action="store_true",
                   help="print every script's records as JSON on stdout, the table on stderr")
    args = p.parse_args(argv)
    scripts = sorted(HERE.glob("bench_*.py"))
    if args.only:
        scripts = [s for s in scripts if s.stem in args.only]
    if not scripts:
        print("no benchmark scripts found", file=sys.stderr)
        return 1
    rows, failed, results = [], [], {}
    for script in scripts:
        cmd = [sys.executable, str(script), "--json"] + (["--quick"] if args.quick else [])
        load_before = _loadavg()
        t0 = time.perf_counter()
        print(f"running {script.name} (load average {load_before}) ...", file=sys.stderr, flush=True)
        proc = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            failed.append(script.name)
            print(proc.stderr[-3000:], file=sys.stderr)
            rows.append((script.stem, "FAILED", f"exit {proc.returncode}", ""))
            continue
        try:
            records = json.loads(proc.stdout)
        except json.JSONDecodeError:
            failed.append(script.name)
            rows.append((script.stem, "FAILED", "no JSON on stdout", ""))
            continue
        for rec in records:
            shown = 0
            for path, label, fmt in HEADLINE:
                v = _get(rec, path)
                if v is not None:
                    rows.append((script.stem, str(rec.get("kind", "")), label, fmt.format(v)))
                    shown += 1
            if not shown:  # a script with other figures: its top-level numbers
                for key, v in rec.items():
                    if isinstance(v, (int, float)) and not isinstance(v, bool):
                        rows.append((script.stem, str(rec.get("kind", "")), key, f"{v:.4g}"))
        results[script.stem] = {"records": records, "wall_s": wall}
        rows.append((script.stem, "", "script wall time", f"{wall:.0f} s"))
        rows.append((script.stem, "", "load average before / after",
                     f"{load_before} / {_loadavg()}"))
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    header = ("script", "case", "figure", "value")
    widths = [max(w, len(h)) for w, h in zip(widths, header, strict=True)]
    table = sys.stderr if args.json else sys.stdout
    line = "  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True))
    print(line, file=table)
    print("-" * len(line), file=table)
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)), file=table)
    if args.json:
        print(json.dumps(results))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
