"""The bad-input battery: every command × {missing file, empty file, truncated, wrong format,
wrong rate, huge value, contradicting the spec, interrupt}, where it applies.

Each case runs ``python -m dtwin ...`` as its own process in a scratch folder, with a timeout
(30 s by default), the input files checksummed (sha256) before and after. A case is **ok**
when the process

- ends within the timeout (a hang is a failure),
- prints no traceback and no "internal error" (exit 70), is not killed by a signal or for
  memory,
- leaves every input file byte-identical,
- exits with the code the case expects: 2 for bad input with an ``error:`` line on stderr;
  130 for an interrupt with one ``interrupted`` line and no ``manifest.json`` in ``--out``;
  0 where the input is usable and the command says what it found (a warning, a problem).

It prints a table (case, exit code, seconds, ok or the reason), the failures with the last
line of stderr and a markdown matrix, command × kind of bad input (:data:`KINDS`: missing,
empty, truncated, wrong format, wrong rate, huge, contradicting the spec or the record's
speed, interrupt), each cell ``ok/cases``; and writes the results as JSON.

An interrupt case that ends before its SIGINT is due is a failure ("ended before the
interrupt"); a SIGINT in the first ~50 ms, before the interpreter has its own handler, ends
the process silently with -2 (a shell shows 130), which is ok.

Usage: ``python benchmarks/bad_input_battery.py [--only SUBSTRING ...] [--timeout 30]
[--json FILE] [--work DIR] [--list]``. ``--only`` keeps the cases whose name holds one of the
substrings (``record``, ``severity.truncated``, ``interrupt``). ``tests/test_reliability_battery.py``
runs :data:`CI_CASES`, a handful that take under a minute.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import os
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

#: The bench's speed (paper-bench preset): f_carrier = 29.7 · 21/105 Hz, f_mesh = 84 f_carrier.
F_SUN = 29.7
F_CARRIER = F_SUN * 21 / 105
F_MESH = 84 * F_CARRIER
RATE = 5000

#: Cases the test suite runs (< 60 s together on a loaded 2-core machine).
CI_CASES = ("record-info.truncated-wav", "record-convert.onto-input", "spec-check.contradicting",
            "simulate.huge-rate", "freqs.interrupt-import")


@dataclasses.dataclass(frozen=True)
class Case:
    """One run: `name` (``command.kind``), `argv` after ``dtwin`` (``{w}`` is the scratch
    folder), `inputs` (file names in it to checksum), `expect` (exit codes that are ok),
    `interrupt_after` (s; SIGINT then), `out` (a result folder that must hold no manifest),
    `needs` (inputs made on demand: ``sim``, the simulated record), `warn` (an exit 0 must
    come with a ``warning`` line: the input is usable but doubtful)."""

    name: str
    argv: tuple[str, ...]
    inputs: tuple[str, ...] = ()
    expect: tuple[int, ...] = (2,)
    interrupt_after: float | None = None
    out: str | None = None
    needs: tuple[str, ...] = ()
    warn: bool = False


@dataclasses.dataclass
class Result:
    name: str
    ok: bool
    reason: str
    code: int | None
    seconds: float
    stderr_tail: str

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


# ------------------------------------------------------------------------------------- inputs


def _bench_signal(duration: float, rate: float, seed: int = 0):
    """Acceleration of a planetary bench (m/s²): the mesh line and its harmonics with carrier
    sidebands, plus noise; time (s) and signal."""
    import numpy as np

    rng = np.random.default_rng(seed)
    t = np.arange(int(duration * rate)) / rate
    x = np.zeros_like(t)
    for h in (1, 2):
        for k in range(-4, 5):
            f = h * F_MESH + k * F_CARRIER
            if f < rate / 2:
                x += (1.0 if k == 0 else 0.2 / (1 + abs(k))) / h * np.sin(2 * np.pi * f * t + k)
    return t, x + 0.05 * rng.standard_normal(t.size)


def _csv(path: Path, t, x) -> None:
    import numpy as np

    np.savetxt(path, np.column_stack([t, x]), delimiter=",", header="time [s],acc [m/s^2]",
               comments="")


def make_inputs(w: Path) -> None:
    """Write the battery's input files into `w` (the simulated record only when asked)."""
    import numpy as np
    from scipy.io import wavfile

    w.mkdir(parents=True, exist_ok=True)
    t, x = _bench_signal(4.0, RATE)
    _csv(w / "good.csv", t, x)
    q = np.round(x / np.abs(x).max() * 30000).astype(np.int16)
    wavfile.write(w / "good.wav", RATE, q)
    (w / "empty.csv").write_bytes(b"")
    (w / "empty.wav").write_bytes(b"")
    (w / "empty.toml").write_bytes(b"")
    data = (w / "good.wav").read_bytes()
    (w / "truncated.wav").write_bytes(data[: 44 + (len(data) - 44) // 3])
    bits = bytearray(data)
    bits[34:36] = struct.pack("<H", 24)  # 24 bits stated, 16-bit frames stored
    (w / "bitdepth.wav").write_bytes(bytes(bits))
    lines = (w / "good.csv").read_text().splitlines()
    (w / "truncated.csv").write_text("\n".join(lines[: len(lines) // 2]) + "\n1.0")
    try:
        from nptdms import ChannelObject, TdmsWriter

        with TdmsWriter(w / "good.tdms") as tw:
            tw.write_segment([ChannelObject("g", "acc", x, properties={
                "wf_increment": 1 / RATE, "unit_string": "m/s^2"})])
        whole = (w / "good.tdms").read_bytes()
        (w / "truncated.tdms").write_bytes(whole[: int(0.7 * len(whole))])
        (w / "cutheader.tdms").write_bytes(whole[:60])  # inside the first segment's metadata
    except ImportError:  # npTDMS is optional
        pass
    (w / "text.wav").write_text("this is not a WAV file\n")
    (w / "record.xyz").write_bytes(data)
    (w / "binary.toml").write_bytes(bytes(range(256)))
    t2, x2 = _bench_signal(4.0, 500.0)  # below 2.5 f_mesh = 1247 Hz
    _csv(w / "lowrate.csv", t2, x2)
    huge = x.copy()
    huge[RATE] = 1e302
    _csv(w / "huge.csv", t, huge)
    # a pure tone the paper bench's mesh lines do not hold (contradicts the spec's speed)
    _csv(w / "tone.csv", t, np.sin(2 * np.pi * 200.0 * t) + 0.01 * np.random.default_rng(1)
         .standard_normal(t.size))
    (w / "impossible.toml").write_text(
        'name = "impossible"\n[gears]\nz_sun = 20\nz_planet = 30\nz_ring = 100\nn_planets = 3\n'
        "module = 0.002\nface_width = 0.02\n")
    (w / "truncated.toml").write_text(  # a spec cut in the middle of a string
        '[gears]\nz_sun = 20\nz_planet = 30\nz_ring = 80\nn_planets = 3\nname = "cu')
    (w / "huge.toml").write_text(  # consistent tooth counts (z_r = z_s + 2 z_p), absurd sizes
        'name = "huge"\n[gears]\nz_sun = 1000000000\nz_planet = 1000000000\n'
        "z_ring = 3000000000\nn_planets = 3\nmodule = 0.002\nface_width = 0.02\n")
    (w / "crowded.toml").write_text(
        'name = "crowded"\n[gears]\nz_sun = 20\nz_planet = 30\nz_ring = 80\nn_planets = 7\n'
        "module = 0.002\nface_width = 0.02\n")


def make_simulated(w: Path, timeout: float = 600.0) -> None:
    """The simulated bench record ``sim.dtwin.h5`` (4 s, paper-bench): the good input of the
    interrupt cases (slow: one simulation)."""
    if (w / "sim.dtwin.h5").exists():
        return
    out = w / "_sim"
    subprocess.run([sys.executable, "-m", "dtwin", "--quiet", "simulate", "--preset",
                    "paper-bench", "--duration", "4", "--out", str(out), "--force"], cwd=w,
                   check=True, timeout=timeout, capture_output=True)
    shutil.copy(out / "record.dtwin.h5", w / "sim.dtwin.h5")


def make_big(w: Path, duration: float = 60.0, rate: float = 25600.0) -> None:
    """``big.wav``: `duration` s of the bench at `rate` Hz (16-bit; the big record of issue
    53's memory row: calibrate needed > 12 GB on it), doubled until calibrating on it would
    need more than twice the memory available here (at most an hour), so that calibrate must
    refuse it on any machine."""
    if (w / "big.wav").exists():
        return
    import numpy as np
    from scipy.io import wavfile

    from dtwin.simulation.memory import available_bytes, calibration_bytes

    avail = available_bytes() or 0
    while calibration_bytes(duration * rate) <= 2 * avail and duration < 3600:
        duration *= 2
    _, x = _bench_signal(duration, rate)
    wavfile.write(w / "big.wav", int(rate), np.round(x / np.abs(x).max() * 30000)
                  .astype(np.int16))


# -------------------------------------------------------------------------------------- cases


def _reading(cmd: str, extra: Sequence[str] = (), *, spec_needed: bool = True,
             kinds: Sequence[str] = ("missing", "empty", "truncated", "bitdepth", "format",
                                     "rate", "huge", "contradicting"),
             out: bool = False) -> list[Case]:
    """Cases of a command that reads one record (FILE first)."""
    spec = ["--preset", "paper-bench"] if spec_needed else []
    tail = (["--out", "{w}/o_" + cmd.replace(" ", "_")] if out else [])
    name = cmd.replace(" ", "-")
    files = {"missing": ("nonexistent.csv", ()), "empty": ("empty.csv", ("empty.csv",)),
             "truncated": ("truncated.wav", ("truncated.wav",)),
             "truncated-tdms": ("truncated.tdms", ("truncated.tdms",)),
             "bitdepth": ("bitdepth.wav", ("bitdepth.wav",)),
             "format": ("text.wav", ("text.wav",)),
             "rate": ("lowrate.csv", ("lowrate.csv",)), "huge": ("huge.csv", ("huge.csv",)),
             "contradicting": ("tone.csv", ("tone.csv",)),
             "wrong-speed": ("good.csv", ("good.csv",))}
    out_cases = []
    for k in kinds:
        f, ins = files[k]
        doubtful = k in ("rate", "contradicting", "wrong-speed")  # a warning, or refused
        speed = ["--f-sun", "20"] if k == "wrong-speed" else []  # the record's lines: 29.7 Hz
        out_cases.append(Case(f"{name}.{k}", (*cmd.split(), "{w}/" + f, *spec, *speed, *extra,
                                              *tail),
                              ins, (0, 2) if doubtful else (2,), warn=doubtful))
    return out_cases


def _spec_cases(cmd: str, extra: Sequence[str] = ()) -> list[Case]:
    name = cmd.replace(" ", "-")
    return [
        Case(f"{name}.missing-spec", (*cmd.split(), "--spec", "{w}/nonexistent.toml", *extra)),
        Case(f"{name}.empty-spec", (*cmd.split(), "--spec", "{w}/empty.toml", *extra),
             ("empty.toml",)),
        Case(f"{name}.binary-spec", (*cmd.split(), "--spec", "{w}/binary.toml", *extra),
             ("binary.toml",)),
        Case(f"{name}.contradicting", (*cmd.split(), "--spec", "{w}/impossible.toml", *extra),
             ("impossible.toml",)),
        Case(f"{name}.crowded", (*cmd.split(), "--spec", "{w}/crowded.toml", *extra),
             ("crowded.toml",)),
        Case(f"{name}.truncated-spec", (*cmd.split(), "--spec", "{w}/truncated.toml", *extra),
             ("truncated.toml",)),
        Case(f"{name}.huge-spec", (*cmd.split(), "--spec", "{w}/huge.toml", *extra),
             ("huge.toml",)),
    ]


def _interrupt(cmd: str, argv: Sequence[str], after: float, inputs: Sequence[str] = (),
               needs: Sequence[str] = (), out: bool = True) -> Case:
    """SIGINT `after` s into ``dtwin ARGV`` (with ``--out`` unless not `out`): exit 130."""
    folder = "{w}/int_" + cmd if out else None
    return Case(f"{cmd}.interrupt", (*argv, *(("--out", folder) if out else ())), tuple(inputs),
                (130,), after, folder, tuple(needs))


def cases() -> list[Case]:
    """Every case of the battery (see the module docstring)."""
    c: list[Case] = []
    # record info / convert
    c += _reading("record info", ["--strict"], spec_needed=True,
                  kinds=("missing", "empty", "truncated-tdms", "bitdepth", "format", "rate",
                         "huge"))
    c = [dataclasses.replace(x, expect=(2,), warn=False) if x.name == "record-info.rate" else x
         for x in c]
    c.append(Case("record-info.wrong-format-ext", ("record", "info", "{w}/record.xyz"),
                  ("record.xyz",)))
    c.append(Case("record-info.truncated-wav", ("record", "info", "{w}/truncated.wav"),
                  ("truncated.wav",)))
    c.append(Case("record-info.truncated-csv", ("record", "info", "{w}/truncated.csv"),
                  ("truncated.csv",)))
    c.append(Case("record-info.cut-tdms-header", ("record", "info", "{w}/cutheader.tdms"),
                  ("cutheader.tdms",)))
    for k, f in (("missing", "nonexistent.csv"), ("empty", "empty.csv"),
                 ("truncated", "truncated.wav"), ("format", "text.wav")):
        c.append(Case(f"record-convert.{k}", ("record", "convert", "{w}/" + f,
                                              "{w}/conv.dtwin.h5"),
                      (f,) if k != "missing" else ()))
    c.append(Case("record-convert.onto-input", ("record", "convert", "{w}/in.dtwin.h5",
                                                "{w}/in.dtwin.h5", "--force"),
                  ("in.dtwin.h5",), needs=("in",)))
    c.append(Case("record-convert.onto-input-link", ("record", "convert", "{w}/in.dtwin.h5",
                                                     "{w}/link.dtwin.h5", "--force"),
                  ("in.dtwin.h5",), needs=("in",)))
    c += [Case("record-info.contradicting", ("record", "info", "{w}/tone.csv", "--preset",
                                             "paper-bench", "--strict"), ("tone.csv",)),
          Case("record-info.wrong-speed", ("record", "info", "{w}/good.csv", "--preset",
                                           "paper-bench", "--f-sun", "20", "--strict"),
               ("good.csv",)),
          _interrupt("record-info", ("record", "info", "{w}/good.csv", "--preset",
                                     "paper-bench"), 1.5, ("good.csv",)),
          _interrupt("record-convert", ("record", "convert", "{w}/good.csv",
                                        "{w}/int_conv.dtwin.h5"), 1.5, ("good.csv",),
                     out=False)]
    # spec check
    c += [Case("spec-check.missing", ("spec", "check", "{w}/nonexistent.toml")),
          Case("spec-check.empty", ("spec", "check", "{w}/empty.toml"), ("empty.toml",)),
          Case("spec-check.format", ("spec", "check", "{w}/binary.toml"), ("binary.toml",)),
          Case("spec-check.contradicting", ("spec", "check", "{w}/impossible.toml"),
               ("impossible.toml",)),
          Case("spec-check.crowded", ("spec", "check", "{w}/crowded.toml"), ("crowded.toml",)),
          Case("spec-check.truncated", ("spec", "check", "{w}/truncated.toml"),
               ("truncated.toml",)),
          Case("spec-check.huge", ("spec", "check", "{w}/huge.toml"), ("huge.toml",)),
          _interrupt("spec-check", ("spec", "check", "{w}/crowded.toml"), 1.5,
                     ("crowded.toml",), out=False)]
    # commands of a gearbox only
    for cmd in ("freqs", "modes", "stiffness"):
        c += _spec_cases(cmd)
    c.append(Case("freqs.huge", ("freqs", "--preset", "paper-bench", "--f-sun", "1e9")))
    c.append(Case("modes.huge", ("modes", "--preset", "paper-bench", "--planets", "100000")))
    c.append(Case("stiffness.huge", ("stiffness", "--preset", "paper-bench", "--cycles",
                                     "1e12")))
    c += _spec_cases("compare-drives", ["--duration", "0.2"])
    for cmd in ("modes", "stiffness"):
        c.append(_interrupt(cmd, (cmd, "--preset", "paper-bench"), 1.5))
    c.append(_interrupt("compare-drives", ("compare-drives", "--preset", "paper-bench"), 12.0))
    c.append(Case("freqs.interrupt-import", ("freqs", "--preset", "paper-bench", "--out",
                                             "{w}/int_freqs"), (), (130,), 1.0,
                  "{w}/int_freqs"))
    # simulate
    c += _spec_cases("simulate", ["--duration", "0.2"])
    c += [Case("simulate.huge-rate", ("simulate", "--preset", "paper-bench", "--sample-rate",
                                      "1e12")),
          Case("simulate.huge-discard", ("simulate", "--preset", "paper-bench", "--discard",
                                         "1e9")),
          Case("simulate.huge-duration", ("simulate", "--preset", "paper-bench", "--duration",
                                          "1e9")),
          Case("simulate.empty-out", ("simulate", "--preset", "paper-bench", "--out", "")),
          Case("simulate.huge-tacho-ppr", ("simulate", "--preset", "paper-bench",
                                           "--tacho-ppr", "1e9")),
          Case("compare-drives.huge-discard", ("compare-drives", "--preset", "paper-bench",
                                               "--discard", "1e9")),
          Case("compare-drives.huge-duration", ("compare-drives", "--preset", "paper-bench",
                                                "--duration", "1e9")),
          Case("simulate.wrong-rate", ("simulate", "--preset", "paper-bench", "--sample-rate",
                                       "500")),
          Case("simulate.usage", ("simulate", "--preset", "paper-bench", "--duration", "abc")),
          Case("simulate.unknown-option", ("simulate", "--bogus")),
          _interrupt("simulate", ("simulate", "--preset", "paper-bench", "--duration", "4"),
                     9.0)]
    # commands that read a record
    c += _reading("spectrum", out=False)
    c.append(Case("spectrum.huge-floor-width", ("spectrum", "{w}/good.csv", "--floor-width",
                                                "1e9"), ("good.csv",)))
    c += _reading("spectrum", kinds=("truncated-tdms", "wrong-speed"))
    c += _reading("view", ["--kind", "order"], kinds=(
        "missing", "empty", "truncated", "bitdepth", "format", "rate", "huge", "contradicting",
        "wrong-speed"))
    c.append(Case("view.missing-kind", ("view", "{w}/good.csv"), ("good.csv",)))
    # mid-run: `view --kind kurtogram` of this record ends in ~9 s under load, `spectrum` later
    c += [_interrupt(cmd, (cmd, "{w}/sim.dtwin.h5", "--preset", "paper-bench", *extra), after,
                     ("sim.dtwin.h5",), ("sim",))
          for cmd, extra, after in (("spectrum", (), 10.0),
                                    ("view", ("--kind", "kurtogram"), 5.0))]
    for cmd, extra in (("severity", ["--location", "sun"]), ("identify", ["--free", "sun_fault"]),
                       ("calibrate", []), ("discover", [])):
        c += _reading(cmd, extra, kinds=("wrong-speed",), out=cmd == "calibrate")
    c += [Case("calibrate.huge-record", ("calibrate", "{w}/big.wav", "--preset", "paper-bench",
                                         "--out", "{w}/o_cal_big"), ("big.wav",),
               needs=("big",))]
    c += _reading("severity", ["--location", "sun"])
    c += _reading("identify", ["--free", "sun_fault"])
    c += _reading("calibrate", out=True)
    c.append(Case("calibrate.huge-knots", ("calibrate", "{w}/good.csv", "--preset",
                                           "paper-bench", "--knots", "100000", "--out",
                                           "{w}/o_cal"), ("good.csv",)))
    c += _reading("discover")
    c.append(Case("discover.huge-n-boot", ("discover", "{w}/good.csv", "--preset",
                                           "paper-bench", "--n-boot", "1000000000"),
                  ("good.csv",)))
    c.append(Case("discover.n-boot-1e9", ("discover", "{w}/good.csv", "--preset",
                                          "paper-bench", "--n-boot", "1e9"), ("good.csv",)))
    c.append(Case("identify.huge-max-steps", ("identify", "{w}/good.csv", "--preset",
                                              "paper-bench", "--free", "sun_fault",
                                              "--max-steps", "1e9"), ("good.csv",)))
    for cmd, extra in (("severity", ["--location", "sun"]), ("identify", ["--free", "sun_fault"]),
                       ("discover", []), ("calibrate", [])):
        c.append(_interrupt(cmd, (cmd, "{w}/sim.dtwin.h5", "--preset", "paper-bench", *extra),
                            12.0, ("sim.dtwin.h5",), ("sim",)))
    # fleet
    c += [Case("fleet-identify.missing", ("fleet", "identify", "{w}/nonexistent*.csv",
                                          "--preset", "paper-bench", "--out", "{w}/o_fleet")),
          Case("fleet-identify.empty", ("fleet", "identify", "{w}/empty.csv", "--preset",
                                        "paper-bench", "--out", "{w}/o_fleet2"),
               ("empty.csv",)),
          Case("fleet-identify.truncated", ("fleet", "identify", "{w}/truncated.wav",
                                            "--preset", "paper-bench", "--out", "{w}/o_fleet3"),
               ("truncated.wav",)),
          Case("fleet-identify.format", ("fleet", "identify", "{w}/text.wav", "--preset",
                                         "paper-bench", "--out", "{w}/o_fleet4"),
               ("text.wav",)),
          Case("fleet-identify.contradicting", ("fleet", "identify", "{w}/tone.csv",
                                                "--preset", "paper-bench", "--out",
                                                "{w}/o_fleet5"), ("tone.csv",)),
          Case("fleet-identify.missing-spec", ("fleet", "identify", "{w}/good.csv", "--spec",
                                               "{w}/nonexistent.toml", "--out", "{w}/o_fleet6"),
               ("good.csv",)),
          Case("fleet-identify.huge", ("fleet", "identify", "{w}/good.csv", "--preset",
                                       "paper-bench", "--num-cpus", "1e9", "--out",
                                       "{w}/o_fleet7"), ("good.csv",)),
          _interrupt("fleet-identify", ("fleet", "identify", "{w}/sim.dtwin.h5", "--preset",
                                        "paper-bench"), 12.0, ("sim.dtwin.h5",), ("sim",)),
          Case("fleet-table.missing", ("fleet", "table", "{w}/nonexistent")),
          Case("fleet-table.empty", ("fleet", "table", "{w}/emptydir"), needs=("emptydir",)),
          Case("fleet-trends.missing", ("fleet", "trends", "{w}/nonexistent")),
          Case("fleet-trends.empty", ("fleet", "trends", "{w}/emptydir"), needs=("emptydir",)),
          Case("fleet-trends.format", ("fleet", "trends", "{w}/badresults"),
               ("badresults/records/r1.json",), needs=("badresults",)),
          Case("fleet-trends.huge", ("fleet", "trends", "{w}/badresults", "--horizon", "1e300"),
               ("badresults/records/r1.json",), needs=("badresults",))]
    # Ctrl-C while the command is still starting (the interpreter, then dtwin's imports): one
    # 'interrupted' line and 130, or the signal's default end before Python handles it
    # (-2, what a shell reports as 130); never a traceback
    for after in (0.05, 0.2, 0.5):
        c.append(Case(f"freqs.interrupt-{after:g}s", ("freqs", "--preset", "paper-bench"), (),
                      (130, -2), after))
    return c


# -------------------------------------------------------------------------------------- run


def _sha(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def _prepare(case: Case, w: Path) -> None:
    for n in case.needs:
        if n == "sim":
            make_simulated(w)
        elif n == "in":
            if not (w / "in.dtwin.h5").exists():
                subprocess.run([sys.executable, "-m", "dtwin", "--quiet", "record", "convert",
                                str(w / "good.csv"), str(w / "in.dtwin.h5")], cwd=w,
                               check=True, capture_output=True, timeout=120)
            link = w / "link.dtwin.h5"
            if not link.is_symlink():
                link.symlink_to(w / "in.dtwin.h5")
        elif n == "emptydir":
            (w / "emptydir").mkdir(exist_ok=True)
        elif n == "big":
            make_big(w)
        elif n == "badresults":
            rec = w / "badresults" / "records"
            rec.mkdir(parents=True, exist_ok=True)
            if not (rec / "r1.json").exists():
                (rec / "r1.json").write_text('{"status": "ok", "machine": "m1", "values": {')


def _default_sigint() -> None:
    """In the child, before Python starts: SIGINT's default action, as in a terminal. A script
    started in the background (``cmd &`` without job control) inherits SIGINT ignored, and an
    interrupt before dtwin installs its handler would be lost unseen."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def run_case(case: Case, w: Path, timeout: float = 30.0) -> Result:
    """Run one case in the scratch folder `w` (module docstring for what is ok)."""
    _prepare(case, w)
    argv = [a.replace("{w}", str(w)) for a in case.argv]
    out = Path(case.out.replace("{w}", str(w))) if case.out else None
    if out is not None and out.exists():
        shutil.rmtree(out)
    before = {n: _sha(w / n) for n in case.inputs}
    env = dict(os.environ, COLUMNS="200")
    env.pop("DTWIN_DEBUG", None)
    t0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-m", "dtwin", *argv], cwd=w, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True, preexec_fn=_default_sigint)
    hung = False
    early = False  # ended before the interrupt was due
    try:
        if case.interrupt_after is not None:
            try:
                p.wait(case.interrupt_after)
                early = True
            except subprocess.TimeoutExpired:
                p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=max(timeout - (time.perf_counter() - t0), 1.0))
    except subprocess.TimeoutExpired:
        hung = True
        os.killpg(p.pid, signal.SIGKILL)
        _, err = p.communicate()
    seconds = time.perf_counter() - t0
    code = p.returncode
    tail = (err or "").strip().splitlines()[-1:] or [""]
    changed = [n for n, h in before.items() if _sha(w / n) != h]
    lines = (err or "").splitlines()
    reason = ""
    if hung:
        reason = f"hang: still running after {timeout:g} s"
    elif "Traceback (most recent call last)" in (err or ""):
        reason = "traceback on stderr"
    elif code == 70 or any(line.startswith("internal error") for line in lines):
        reason = "crash: internal error (exit 70)"
    elif early:
        reason = f"ended (exit {code}) before the interrupt at {case.interrupt_after:g} s"
    elif code == -signal.SIGINT and code in case.expect and not lines:
        pass  # SIGINT before the interpreter handles it: the default end, silent (shell: 130)
    elif code is not None and (code < 0 or code in (137, 139)):
        reason = f"crash: killed (exit {code})"
    elif changed:
        reason = f"input changed: {', '.join(changed)}"
    elif code not in case.expect:
        what = {0: "accepted (exit 0)", 1: "exit 1"}.get(code, f"exit {code}")
        reason = f"{what}, expected {' or '.join(map(str, case.expect))}"
    elif code == 0 and case.warn and not any(line.startswith("warning") for line in lines):
        reason = "accepted without a warning"
    elif code == 2 and not any(line.startswith("error:") for line in lines):
        reason = "exit 2 without an 'error:' line"
    elif code == 130:
        if not any(line.startswith("interrupted") for line in lines):
            reason = "exit 130 without an 'interrupted' line"
        elif out is not None and (out / "manifest.json").exists():
            reason = "interrupted, but --out holds a manifest"
    return Result(case.name, not reason, reason or "ok", code, round(seconds, 2), tail[0])


def run(selected: Sequence[Case], w: Path, *, timeout: float = 30.0,
        log=print) -> list[Result]:
    """Run the cases one after the other in `w` (inputs made first); print one line each."""
    make_inputs(w)
    results = []
    for case in selected:
        r = run_case(case, w, timeout)
        log(f"{r.name:<36} {str(r.code):>5} {r.seconds:7.1f} s  {r.reason}")
        results.append(r)
    return results


def summary(results: Sequence[Result]) -> str:
    """The table's foot: cases, ok, and each failure with its reason and stderr's last line."""
    bad = [r for r in results if not r.ok]
    out = [f"cases: {len(results)}, ok: {len(results) - len(bad)}, failures: {len(bad)}"]
    for r in bad:
        out.append(f"  FAIL {r.name}: {r.reason}" + (f" — {r.stderr_tail[:160]}"
                                                      if r.stderr_tail else ""))
    return "\n".join(out)


#: The table's columns (the issue's kinds of bad input) and the case-name suffixes each holds.
KINDS = {
    "missing": ("missing",),
    "empty": ("empty",),
    "truncated": ("truncated", "cut-tdms-header"),
    "wrong format": ("format", "wrong-format", "binary-spec", "bitdepth", "usage",
                     "unknown-option"),
    "wrong rate": ("rate", "wrong-rate"),
    "huge": ("huge", "n-boot-1e9"),
    "contradicting": ("contradicting", "crowded", "wrong-speed", "onto-input"),
    "interrupt": ("interrupt",),
}


def kind_of(name: str) -> str:
    """The column of case `name` (``command.kind``) in :func:`matrix`."""
    suffix = name.split(".", 1)[1]
    for kind, keys in KINDS.items():
        if any(suffix.startswith(k) for k in keys):
            return kind
    return "other"


def matrix(results: Sequence[Result]) -> str:
    """A markdown table: one row per command, one column per kind of bad input; each cell
    ``ok/cases`` (bold when a case failed), ``–`` where the battery has no case."""
    cmds: dict[str, dict[str, list[Result]]] = {}
    for r in results:
        cmds.setdefault(r.name.split(".", 1)[0], {}).setdefault(kind_of(r.name), []).append(r)
    cols = [*KINDS, "other"]
    if not any("other" in row for row in cmds.values()):
        cols.remove("other")
    out = ["| command | " + " | ".join(cols) + " | all |",
           "|---|" + "---:|" * (len(cols) + 1)]
    for cmd, row in cmds.items():
        cells = []
        for k in cols:
            rs = row.get(k, [])
            ok = sum(r.ok for r in rs)
            cells.append("–" if not rs else (f"{ok}/{len(rs)}" if ok == len(rs)
                                             else f"**{ok}/{len(rs)}**"))
        every = [r for rs in row.values() for r in rs]
        ok = sum(r.ok for r in every)
        cells.append(f"{ok}/{len(every)}" if ok == len(every) else f"**{ok}/{len(every)}**")
        out.append(f"| {cmd} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", default=None, help="substrings of case names to run")
    ap.add_argument("--timeout", type=float, default=30.0, help="seconds per case (default 30)")
    ap.add_argument("--json", type=Path, default=None, help="write the results here (default "
                    "./bad_input_battery.json)")
    ap.add_argument("--work", type=Path, default=None, help="scratch folder (default: a "
                    "temporary one, removed at the end)")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    args = ap.parse_args(argv)
    selected = [c for c in cases() if not args.only or any(s in c.name for s in args.only)]
    if args.list:
        for c in selected:
            print(f"{c.name:<36} dtwin {' '.join(c.argv)}")
        return 0
    tmp = None
    if args.work is None:
        tmp = tempfile.mkdtemp(prefix="dtwin-battery-")
        w = Path(tmp)
    else:
        w = args.work.resolve()
    try:
        print(f"{'case':<36} {'exit':>5} {'time':>9}  result")
        results = run(selected, w, timeout=args.timeout)
        print(summary(results))
        print()
        print(matrix(results))
        path = args.json or (Path.cwd() / "bad_input_battery.json")
        path.write_text(json.dumps({"timeout_s": args.timeout, "cases": len(results),
                                    "ok": sum(r.ok for r in results),
                                    "results": [r.to_dict() for r in results]}, indent=1))
        print(f"wrote {path}")
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    return 0 if all(r.ok for r in results) else 1


if __name__ == "__main__":
    raise SystemExit(main())
