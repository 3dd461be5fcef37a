"""The whole workflow on 4 s, 5 kHz records (issue #21: calibrate ≤ 60 s, discover ≤ 60 s).

Calibrates the user's spec of the independent records (``../shared/independent/gearbox.toml``,
beside the checkout) on ``baseline-1`` (:func:`dtwin.identify.calibrate.calibrate`), then runs
discovery (:func:`dtwin.identify.discover.discover`, the default settings) with the calibrated
spec on faulty records of the same machine, one after the other in this process. Per stage: wall
and CPU time, the wall time JAX spent compiling (tracing, lowering and XLA compilation, from
``jax.monitoring``; the persistent compilation cache follows ``DTWIN_JAX_CACHE``, off under
``benchmarks/compare.py``) and the number of compilations, the peak resident memory of the
process so far, the load average before and after, and the stage's outcome (gaps, groups
named). Without the independent records it prints nothing (``[]`` with ``--json``).

Usage: ``python benchmarks/bench_workflow.py [--records sun-fault-0.60 load-fluct]
[--max-steps 3] [--quick] [--json] [--log-compiles]``; ``--quick``: sun-fault-0.60 only, one
step; ``--log-compiles``: the ten costliest compiled functions of each stage by name.
"""

from __future__ import annotations

import argparse
import json
import logging
import re
import resource
import tempfile
from pathlib import Path

import _timing

ROOT = Path(__file__).resolve().parents[1]
IND = ROOT.parent / "shared" / "independent"
RECORDS = ["sun-fault-0.60", "load-fluct"]

_COMPILE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration",
                   "/jax/core/compile/jaxpr_to_mlir_module_duration",
                   "/jax/core/compile/backend_compile_duration")
_compile = {"s": 0.0, "n": 0}
#: XLA compilations by function name (``--log-compiles``): name -> [count, seconds]
_by_name: dict[str, list] = {}


class _CompileLog(logging.Handler):
    """Collects JAX's "Finished XLA compilation of NAME in T sec" lines (jax_log_compiles)."""

    def emit(self, record):
        m = re.match(r"Finished XLA compilation of (.+) in ([0-9.eE+-]+) sec",
                     record.getMessage())
        if m:
            e = _by_name.setdefault(m.group(1), [0, 0.0])
            e[0] += 1
            e[1] += float(m.group(2))


def _on_event(event: str, duration: float, **_) -> None:
    if event in _COMPILE_EVENTS:
        _compile["s"] += duration
        if event == "/jax/core/compile/backend_compile_duration":
            _compile["n"] += 1


def _stage(fn):
    """Run `fn()`; its result and the figures of the stage."""
    load0 = _timing.load_average()
    c_s, c_n = _compile["s"], _compile["n"]
    _by_name.clear()
    out, wall, cpu = _timing.timed(fn)
    top = sorted(_by_name.items(), key=lambda kv: -kv[1][1])[:10]
    return out, dict(run_s=wall, cpu_s=cpu, compile_s=_compile["s"] - c_s,
                     compiled=[dict(name=k, count=v[0], s=round(v[1], 2)) for k, v in top],
                     compilations=_compile["n"] - c_n,
                     peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                     load_before=list(load0), load_after=list(_timing.load_average()),
                     target_s=60.0)


def _n_refit(res) -> int:
    """Candidates refit over the whole search (those with a p-value)."""
    seen = {id(c): c for s in res.steps for c in s.candidates}
    seen.update({id(c): c for c in res.last_candidates})
    return sum(1 for c in seen.values() if c.p_value == c.p_value)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--records", nargs="*", default=RECORDS)
    p.add_argument("--max-steps", type=int, default=3)
    p.add_argument("--quick", action="store_true", help="sun-fault-0.60 only, one step")
    p.add_argument("--json", action="store_true", help="one JSON list on stdout (run_all.py)")
    p.add_argument("--log-compiles", action="store_true",
                   help="name the functions compiled in each stage (the ten costliest)")
    args = p.parse_args(argv)
    if args.quick:
        args.records, args.max_steps = ["sun-fault-0.60"], 1
    if not (IND / "baseline-1.csv").exists():
        print("[]" if args.json else f"no independent records at {IND}")
        return 0

    import jax

    jax.monitoring.register_event_duration_secs_listener(_on_event)
    if args.log_compiles:
        jax.config.update("jax_log_compiles", True)
        for name in ("jax._src.interpreters.pxla", "jax._src.dispatch"):
            lg = logging.getLogger(name)
            lg.addHandler(_CompileLog())
            lg.propagate = False
    from dtwin.identify.calibrate import calibrate
    from dtwin.identify.discover import DiscoverySettings, discover
    from dtwin.io.readers import read_record

    rows = []
    cal, row = _stage(lambda: calibrate([IND / "baseline-1.csv"], IND / "gearbox.toml"))
    spec = Path(tempfile.mkdtemp()) / "calibrated.toml"
    cal.write_spec(spec)
    row.update(kind="calibrate", stage="calibrate", record="baseline-1",
               gap_heldout_db=cal.gap_heldout.total, gap_confirmed_db=cal.gap_confirmed.total)
    rows.append(row)
    for name in args.records:
        res, row = _stage(lambda name=name: discover(
            read_record(IND / f"{name}.csv"), spec,
            settings=DiscoverySettings(max_steps=args.max_steps)))
        row.update(kind=f"discover {name}", stage="discover", record=name, named=res.named,
                   gap_before_db=res.initial_gap.total, gap_after_db=res.final_gap.total,
                   stop=res.stop_reason, refit=_n_refit(res))
        rows.append(row)
    if args.json:
        print(json.dumps(rows))
    else:
        for r in rows:
            what = (f"gap {r['gap_heldout_db']:.2f} dB held out" if r["stage"] == "calibrate"
                    else f"named {r['named']} gap {r['gap_before_db']:.2f} → "
                         f"{r['gap_after_db']:.2f} dB, {r['refit']} refit")
            print(f"{r['stage']:9s} {r['record']:15s} {r['run_s']:7.1f} s wall "
                  f"{r['cpu_s']:7.1f} s CPU, compile {r['compile_s']:6.1f} s "
                  f"({r['compilations']}), peak RSS {r['peak_rss_mb']:.0f} MB, load "
                  f"{r['load_before'][0]:.1f} → {r['load_after'][0]:.1f}; {what}", flush=True)
            for c in r["compiled"]:
                print(f"    compiled {c['count']:3d}× {c['s']:6.2f} s  {c['name']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
