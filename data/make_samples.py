"""Make the bundled sample records in data/samples/ (run: python data/make_samples.py).

The records stand in for measurements of the paper's test bench (21/31/84, 1782 rpm actual):
they are made with the twin in a *higher-fidelity* configuration than the default fitted model,
so that fits on them are not an inverse crime:

- the full translational model (fits default to the torsional reduction or the spec's kind);
- 20 stiffness harmonics instead of 12;
- a static transmission error of 0.5 µm (first and second mesh harmonics);
- planet pin-hole position errors of 0.1 and −0.075 mrad (5 and 4 µm: a precision carrier),
  which load the planets unequally;
- measurement noise at 25 dB SNR, and the DAQ's anti-aliasing filter (internal rate 4× the
  output rate, FIR low-pass, decimation), as `dtwin.simulate` records every signal;
- the `paper-bench` preset's housing, 20 kg on mounts at 200 Hz, so that the levels are a
  bench's (healthy: 0.21 m/s² RMS, 1.6 mm/s, ISO 20816-3 zone B).

Records (dtwin's own format, `*.dtwin.h5`; metadata hold the truth):

- `bench_healthy.dtwin.h5`        4 s at 5 kHz, no fault
- `bench_sun_fault.dtwin.h5`      4 s at 5 kHz, sun missing tooth, severity 0.6
- `bench_combined.dtwin.h5`       4 s at 5 kHz, sun missing tooth 0.6 + planet pitting 0.5
- `bench_runup.dtwin.h5`          2 s at 25.6 kHz, input 20 → 35 Hz, sun missing tooth 0.3,
                                  tachometer 1 pulse/rev on the sun

The seeds are fixed; re-running gives the same files (up to the library versions, recorded in
each file's metadata).
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp

import dtwin
from dtwin.io.readers import write_record
from dtwin.model.faults import parse_fault
from dtwin.model.motor.drive import DrivePart
from dtwin.model.motor.shaft import Shaft
from dtwin.model.motor.speed_source import IdealSpeedSource, SpeedProfile
from dtwin.model.parts.imperfections import PlanetPositionErrors, TransmissionError
from dtwin.simulation.simulate import simulate
from dtwin.spec import preset
from dtwin.spec.build import build_twin, daq_from_spec

OUT = Path(__file__).resolve().parent / "samples"
F_SUN = 29.7  # Hz: the bench's actual 1782 rpm
SNR_DB = 25.0
TRUTH_EXTRA = dict(te_amplitude=0.5e-6, te_harmonics=(1.0, 0.3), planet_position_errors=(0.0, 1e-4, -7.5e-5))

RECORDS = {
    "bench_healthy": dict(faults=(), duration=4.0, seed=1),
    "bench_sun_fault": dict(faults=("sun:missing_tooth:0.6",), duration=4.0, seed=2),
    "bench_combined": dict(faults=("sun:missing_tooth:0.6", "planet:pitting:0.5:0:0"), duration=4.0, seed=3),
    "bench_runup": dict(faults=("sun:missing_tooth:0.3",), duration=2.0, seed=4, ramp=(20.0, 35.0),
                        sample_rate=25600.0, tacho_ppr=1),
}


def truth_twin(spec, faults, f_sun):
    extra = (
        TransmissionError(jnp.asarray(TRUTH_EXTRA["te_amplitude"]), jnp.asarray(TRUTH_EXTRA["te_harmonics"]),
                          jnp.zeros(2)),
        PlanetPositionErrors(jnp.asarray(TRUTH_EXTRA["planet_position_errors"])),
    )
    return build_twin(spec, kind="translational", faults=tuple(parse_fault(f) for f in faults),
                      f_sun=f_sun, extra_parts=extra, n_harmonics=20)


def make(name: str, cfg: dict, force: bool = False) -> Path:
    spec = preset("paper-bench")
    f0 = cfg.get("ramp", (F_SUN,))[0]
    tw = truth_twin(spec, cfg["faults"], f0)
    daq = daq_from_spec(spec, quantity="acceleration", snr_db=SNR_DB,
                        sample_rate=cfg.get("sample_rate", 5000.0), tacho_ppr=cfg.get("tacho_ppr"))
    if "ramp" in cfg:
        lo, hi = cfg["ramp"]
        i = next(j for j, p in enumerate(tw.parts) if isinstance(p, DrivePart))
        prof = SpeedProfile.ramp(2 * math.pi * hi, cfg["duration"], 0.1, 2 * math.pi * lo)
        tw = eqx.tree_at(lambda t: t.parts[i].drive, tw, IdealSpeedSource(prof, Shaft()))
    res = simulate(tw, duration=cfg["duration"], f_sun=f0, daq=daq, discard=0.1, seed=cfg["seed"],
                   progress=False)
    meta = {
        "source": "data/make_samples.py (dtwin twin, higher-fidelity truth configuration)",
        "spec": "paper-bench", "f_sun": f0, "faults": list(cfg["faults"]), "snr_db": SNR_DB,
        "seed": cfg["seed"], "truth": {"kind": "translational", "n_harmonics": 20,
                                       **{k: list(v) if isinstance(v, tuple) else v
                                          for k, v in TRUTH_EXTRA.items()}},
        "ramp_hz": list(cfg["ramp"]) if "ramp" in cfg else None,
        "dtwin_version": dtwin.__version__, "machine": "bench-1",
        "timestamp": "2026-11-22T00:00:00Z",
    }
    rec = res.to_record(metadata=meta)
    if daq.tacho_ppr is not None:
        rec = dataclasses.replace(rec, tacho_ppr=daq.tacho_ppr, tacho_shaft="sun")
    OUT.mkdir(parents=True, exist_ok=True)
    return write_record(rec, OUT / f"{name}.dtwin.h5", force=force)


if __name__ == "__main__":
    force = "--force" in sys.argv
    names = [a for a in sys.argv[1:] if not a.startswith("--")] or list(RECORDS)
    for n in names:
        print("writing", make(n, RECORDS[n], force=force))
