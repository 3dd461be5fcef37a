"""Benchmark: a run-up recorded at 25.6 kHz, simulated in full (issue #21: "run-ups at 25.6 kHz
no slower than today").

The paper's gearbox (``build_twin(preset("paper-sim"))``, translational twin, sun missing tooth
of severity 0.5, ideal speed source) run up linearly from 20 to 40 Hz over `--duration` s
(default 0.5) after a 0.05 s discard, recorded by an accelerometer at 25.6 kHz
(`dtwin.simulation.simulate.DAQ`, 4× oversampling). A run-up is never tiled (its speed is not constant),
so this measures the whole-record solve: `simulate` is called twice with the persistent
compilation cache as the environment sets it (``benchmarks/compare.py`` turns it off); the
first call includes compilation, the second is the cost of a run once compiled (wall and CPU
time, accepted steps, rms of the record).

Usage: ``python benchmarks/bench_runup.py [--duration 0.5] [--json]``
"""

from __future__ import annotations

import argparse
import json

from _timing import load_average, timed


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=0.5)
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)

    import numpy as np

    from dtwin.identify.residuals import drive_at
    from dtwin.model.faults import MissingTooth
    from dtwin.simulation.simulate import DAQ, simulate
    from dtwin.spec import preset
    from dtwin.spec.build import build_twin

    discard = 0.05
    twin = build_twin(preset("paper-sim"), kind="translational",
                      faults=(MissingTooth(0.5, location="sun"),))
    twin = drive_at(twin, 20.0, 40.0, duration=a.duration, discard=discard)
    daq = DAQ(sample_rate=25_600.0)
    out = {"duration_s": a.duration, "rate_hz": 25_600.0, "load_start": load_average()}

    def run():
        r = simulate(twin, duration=a.duration, f_sun=20.0, daq=daq, discard=discard)
        r.signal.block_until_ready()
        return r

    first, out["first_wall_s"], out["first_cpu_s"] = timed(run)
    second, out["wall_s"], out["cpu_s"] = timed(run)
    out["method"] = second.method
    out["steps"] = int(second.num_steps)
    out["signal_rms"] = float(np.sqrt(np.mean(np.asarray(second.signal) ** 2)))
    out["load_end"] = load_average()
    if a.json:
        print(json.dumps(out))
    else:
        for k, v in out.items():
            print(f"{k:>14}: {v}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
