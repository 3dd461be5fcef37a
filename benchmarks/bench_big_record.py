"""Every command that reads a record, on a big one: 60 s at 25.6 kHz, 3 channels and a tacho.

Writes a synthetic record of the paper's bench gearbox (``paper-bench``, 29.7 Hz: a mesh line
with carrier sidebands, a sun-fault impulse train ringing a 7 kHz resonance, noise; a 1 pulse
per revolution tachometer on the sun) in dtwin's format, then runs each command on it in its
own process (``python -m dtwin ...``) and measures the wall time, the CPU time (user +
system) and the process's peak resident memory (``ru_utime``, ``ru_stime``, ``ru_maxrss`` of
the child from ``os.wait4``), with the load average before and after. The target of issue #20:
each command within 30 s and 1 GB on such a record. The fits (``identify``, ``severity``) use
their default fit window (:mod:`dtwin.identify.segment`).

Usage: ``python benchmarks/bench_big_record.py [--duration 60] [--rate 25600] [--only NAME ...]
[--timeout 300] [--json] [--quick]`` (``--quick``: 10 s of record).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _timing import load_average, wait_measured  # noqa: E402

F_SUN = 29.7
ZS, ZR = 21, 84


def write_record(path: Path, duration: float, rate: float) -> Path:
    """The synthetic bench record (module docstring), written with dtwin's native writer."""
    from dtwin.io.readers import write_record as write
    from dtwin.io.record import Record

    n = int(round(duration * rate))
    t = np.arange(n) / rate
    fc = F_SUN * ZS / (ZS + ZR)
    fm = fc * ZR
    rng = np.random.default_rng(0)
    mesh = np.cos(2 * np.pi * fm * t) * (1 + 0.2 * np.cos(2 * np.pi * 3 * fc * t))
    # sun fault: an impulse every 1/(fm N / Zs) s ringing a 7 kHz resonance (1 % damping)
    f_fault = fm * 3 / ZS
    ring = np.exp(-2 * np.pi * 7000 * 0.01 * np.arange(int(0.004 * rate)) / rate) * np.sin(
        2 * np.pi * 7000 * np.arange(int(0.004 * rate)) / rate)
    pulses = np.zeros(n)
    pulses[(np.arange(0, duration, 1 / f_fault) * rate).astype(int)] = 1.0
    fault = np.convolve(pulses, ring)[:n]
    data = np.stack([mesh + 2 * fault + 0.3 * rng.standard_normal(n),
                     0.7 * mesh + 1.5 * fault + 0.3 * rng.standard_normal(n),
                     0.4 * mesh + fault + 0.3 * rng.standard_normal(n)])
    tacho = (np.sin(2 * np.pi * F_SUN * t) > 0.99).astype(np.float64) * 5.0
    rec = Record(data=data, sample_rate=rate, channels=("acc_x", "acc_y", "acc_z"),
                 units=("m/s^2",) * 3, tacho=tacho, tacho_ppr=1, tacho_shaft="sun",
                 metadata={"source": "benchmarks/bench_big_record.py", "f_sun": F_SUN})
    return write(rec, path, force=True)


def commands(rec: str, out: str) -> dict[str, list[str]]:
    """Name → command line (after ``python -m dtwin``) of every command that reads a record."""
    g = ["--preset", "paper-bench"]
    cmds = {
        "record info": ["record", "info", rec, *g],
        "spectrum": ["spectrum", rec, *g],
        "spectrum --out": ["spectrum", rec, *g, "--out", f"{out}/spectrum"],
    }
    for kind in ("order", "tsa", "envelope", "kurtogram", "cepstrum", "waterfall", "psd"):
        cmds[f"view {kind}"] = ["view", rec, "--kind", kind, *g]
    cmds["view kurtogram --out"] = ["view", rec, "--kind", "kurtogram", *g, "--out",
                                    f"{out}/kurtogram"]
    cmds["record convert"] = ["record", "convert", rec, f"{out}/converted.dtwin.h5"]
    cmds["identify"] = ["identify", rec, *g, "--free", "sun_fault", "--max-steps", "5"]
    cmds["severity"] = ["severity", rec, *g]
    return cmds


def run_one(args: list[str], timeout: float) -> dict:
    """Run ``python -m dtwin ARGS``; wall and CPU time, peak RSS (MB), exit code, last stderr
    line."""
    env = {**os.environ, "JAX_ENABLE_X64": "1", "MPLBACKEND": "Agg"}
    t0 = time.perf_counter()
    err = tempfile.TemporaryFile()
    # run outside the repository: ``python -m`` puts the working directory first on sys.path,
    # which would load the checkout's dtwin even when PYTHONPATH names another (compare.py)
    p = subprocess.Popen([sys.executable, "-m", "dtwin", "--quiet", *args],
                         stdout=subprocess.DEVNULL, stderr=err, env=env,
                         cwd=tempfile.gettempdir())
    m = wait_measured(p, t0, timeout)
    err.seek(0)
    lines = err.read().decode(errors="replace").strip().splitlines()
    return {"wall_s": m["wall_s"], "cpu_s": m["cpu_s"], "peak_rss_mb": m["peak_rss_mb"],
            "exit_code": m["returncode"], "timed_out": m["timed_out"],
            "stderr_tail": lines[-1] if lines else ""}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--rate", type=float, default=25600.0)
    ap.add_argument("--only", nargs="*", default=None, help="command names (see the table)")
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("--quick", action="store_true", help="10 s of record")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    duration = 10.0 if a.quick else a.duration
    results = []
    with tempfile.TemporaryDirectory() as d:
        rec = str(write_record(Path(d) / "big.dtwin.h5", duration, a.rate))
        size_mb = os.path.getsize(rec) / 2**20
        for name, args in commands(rec, d).items():
            if a.only and name not in a.only:
                continue
            load0 = load_average()[0]
            r = run_one(args, a.timeout)
            r.update(kind=name, command=name, duration_s=duration, rate_hz=a.rate,
                     channels=3, record_mb=size_mb, load_before=load0,
                     load_after=load_average()[0],
                     within_target=bool(r["wall_s"] <= 30 and r["peak_rss_mb"] <= 1024
                                        and r["exit_code"] == 0))
            results.append(r)
            if not a.json:
                print(f"{name:<24} {r['wall_s']:7.1f} s {r['cpu_s']:7.1f} s CPU "
                      f"{r['peak_rss_mb']:7.0f} MB  exit "
                      f"{r['exit_code']:>3}  load {load0:.1f}→{r['load_after']:.1f}  "
                      f"{'ok' if r['within_target'] else 'OVER'}  {r['stderr_tail'][:80]}",
                      flush=True)
    if a.json:
        print(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
