"""The command line on bad input and interrupts (issue 53): one ``error:`` line naming the option
and what it accepts, exit 2, before any work; Ctrl-C while the command is still importing gives
one ``interrupted`` line and exit 130, never a traceback."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest
from _cli_errors import one_error_line

from dtwin.cli import main

_fails = one_error_line


@pytest.mark.parametrize("argv,option,accepted", [
    (["simulate", "--duration", "abc"], "--duration", "a number"),
    (["simulate", "--seed", "1.5"], "--seed", "an integer"),
    (["simulate", "--band", "1", "x"], "--band", "2 numbers"),
    (["simulate", "--bogus", "3"], "--bogus", "--duration"),
    (["simulate", "--json=3"], "--json", "a flag"),
    (["spec", "check"], "FILE", "a path"),
    (["record", "nope"], "COMMAND", "convert, info"),
    # an option without its value: what the option takes (before: "a value" for every one)
    (["simulate", "--preset", "paper-sim", "--duration"], "--duration", "a number"),
    (["fleet", "identify", "r.h5", "--num-cpus"], "--num-cpus", "an integer"),
    (["identify", "r.h5", "--runup", "1"], "--runup", "2 numbers"),
])
def test_usage_errors_are_one_error_line(argv, option, accepted, capsys):
    """A wrong option value, an unknown option, a missing argument, an unknown command: the
    same one line as every other bad input, ``error: <option>: <what> (accepted: ...)``."""
    line = _fails(argv, capsys)
    assert line.startswith(f"error: {option}: "), line
    assert "(accepted: " in line and accepted in line.split("(accepted: ", 1)[1], line


@pytest.mark.parametrize("argv,where,accepted", [
    ([], "dtwin", "calibrate, compare-drives, discover, fleet"),
    (["--quiet"], "dtwin", "severity, simulate, spec"),
    (["fleet"], "dtwin fleet", "identify, table, trends"),
    (["spec"], "dtwin spec", "check, schema"),
    (["record"], "dtwin record", "convert, info"),
])
def test_a_missing_command_is_one_error_line(argv, where, accepted, capsys):
    """`dtwin` or a command group without its command: the one `error:` line naming the
    commands it accepts, nothing on stdout (before: typer's help box, exit 2)."""
    with pytest.raises(SystemExit) as e:
        main(argv)
    out, err = capsys.readouterr()
    assert e.value.code == 2 and out == "", (out, err)
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: COMMAND: missing (accepted: "), err
    assert accepted in err and f"see {where} --help)" in err, err


def test_simulate_refuses_absurd_options_before_any_work(monkeypatch, capsys):
    """--discard beyond its range, an empty --out and a sample rate whose record cannot fit in
    memory are refused at once (the simulation is never started)."""
    import dtwin.cli.cmd_simulate as cmd

    def never(*a, **k):
        raise AssertionError("the simulation started")

    monkeypatch.setattr(cmd, "run_simulation", never)
    line = _fails(["simulate", "--preset", "paper-sim", "--discard", "1e9"], capsys)
    assert line.startswith("error: --discard: ") and "[0, 60]" in line
    for out in (["--out", ""], ["--out="], ["--out", " "]):
        line = _fails(["simulate", "--preset", "paper-sim", *out], capsys)
        assert line.startswith("error: --out: is empty")
    line = _fails(["simulate", "--preset", "paper-sim", "--sample-rate", "1e12"], capsys)
    assert line.startswith("error: --sample-rate: ") and "PiB" in line
    assert "lower --sample-rate or --duration" in line


def test_memory_estimate_and_refusal():
    """dtwin.simulation.memory: the simulation's estimate in closed form (points × values × 8 bytes ×
    copies) and the refusal against a given available memory."""
    from dtwin.simulation.memory import MemoryLimitError, format_bytes, require, simulation_bytes

    need = simulation_bytes(2.0, 1000.0, 10, oversample=4, n_observables=8)
    assert need == 2.0 * 1000.0 * 4 * (20 + 8) * 8 * 3
    require(need, what="x", option="--o", fix="f", available=int(need / 0.8) + 1)
    with pytest.raises(MemoryLimitError, match=r"^--o: x needs about 5\.13 MiB") as e:
        require(need, what="x", option="--o", fix="lower it", available=int(need))
    assert format_bytes(need) in str(e.value) and "lower it" in str(e.value)
    assert format_bytes(2**40) == "1 TiB" and format_bytes(512) == "512 B"


def _interrupt_during_import(argv: list[str], delay_s: float | None) -> tuple[int, str]:
    """Start dtwin as a new process, send SIGINT while it imports, return (code, stderr)."""
    p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        if delay_s is None:  # the script says when it starts importing dtwin (which takes
            # seconds: JAX); 0.2 s later the import is under way
            assert p.stdout.readline().strip() == "importing"
            delay_s = 0.2
        time.sleep(delay_s)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    return p.returncode, err


def test_ctrl_c_while_importing_gives_one_line_and_130():
    """SIGINT while `import dtwin` runs (seconds: JAX): one line `interrupted …`, exit 130. The
    console script runs ``from dtwin.cli import main`` with ``sys.argv[0]`` ending in
    ``dtwin``; the second case is ``python -m dtwin`` interrupted half a second after start."""
    script = ("import sys; sys.argv = ['/usr/bin/dtwin', 'freqs', '--preset', 'paper-sim']\n"
              "print('importing', flush=True)\n"
              "from dtwin.cli import main\n"
              "sys.exit(main())\n")
    for argv, delay in (([sys.executable, "-c", script], None),
                        ([sys.executable, "-m", "dtwin", "freqs", "--preset", "paper-sim"], 0.5)):
        code, err = _interrupt_during_import(argv, delay)
        assert code == 130, (code, err)
        assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
        lines = err.splitlines()
        assert len(lines) == 1 and lines[0].startswith("interrupted"), err


def test_importing_dtwin_in_a_program_keeps_its_sigint_handling():
    """A program (not the dtwin command) that imports dtwin still gets KeyboardInterrupt."""
    script = ("import signal, dtwin\n"
              "print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)\n")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         timeout=120)
    assert out.stdout.strip() == "True", out.stderr


@pytest.mark.parametrize("argv,option,bound", [
    (["discover", "missing.wav", "--preset", "paper-bench", "--n-boot", "1000000000"],
     "--n-boot", "[20, 100000]"),
    (["calibrate", "missing.wav", "--preset", "paper-bench", "--knots", "100000", "--out", "o"],
     "--knots", "[1, 40]"),
])
def test_unbounded_work_options_are_bounded(argv, option, bound, tmp_path, monkeypatch,
                                            capsys):
    """`discover --n-boot 1e9` (each draw one refit: runs for ever) and `calibrate --knots 1e5`
    (gigabytes): refused before the record is opened, with the accepted range."""
    monkeypatch.chdir(tmp_path)
    line = _fails(argv, capsys)
    assert line.startswith(f"error: {option}: must lie in {bound}"), line


def _no_work(monkeypatch):
    """The expensive steps fail the test if they run."""
    from importlib import import_module

    def never(*a, **k):
        raise AssertionError("work started before the options were checked")

    import dtwin.cli.cmd_simulate as cmd

    monkeypatch.setattr(cmd, "run_simulation", never)
    for module, name in (("dtwin.identify.fit", "fit"), ("dtwin.identify.fleet", "run_fleet"),
                         ("dtwin.identify.discover", "discover"),
                         ("dtwin.report.drive_comparison", "compare_drives")):
        monkeypatch.setattr(import_module(module), name, never)


#: (argv, the line's start): counts written as `1e9` (the issue's spelling), refused with the
#: accepted range; the bounds are the documented ones (docs/guide.md)
SCIENTIFIC = [
    (["discover", "missing.wav", "--preset", "paper-bench", "--n-boot", "1e9"],
     "error: --n-boot: must lie in [20, 100000], got 1000000000"),
    (["calibrate", "missing.wav", "--preset", "paper-bench", "--knots", "1e5", "--out", "o"],
     "error: --knots: must lie in [1, 40], got 100000"),
    (["discover", "missing.wav", "--preset", "paper-bench", "--seed", "1e30"],
     "error: --seed: must lie in [0, 4294967295], got 1.000e+30"),
    (["identify", "missing.wav", "--preset", "paper-sim", "--free", "sun_fault", "--starts",
      "1e9"], "error: --starts: must lie in [1, 3], got 1000000000"),  # 3^1 grid points
    (["identify", "missing.wav", "--preset", "paper-sim", "--free", "sun_fault,k_sun_planet",
      "--starts", "9", "--refine", "1e1"], "error: --refine: must lie in [1, 9], got 10"),
    (["identify", "missing.wav", "--preset", "paper-sim", "--free", "sun_fault", "--max-steps",
      "1e9"], "error: --max-steps: must lie in [1, 1000], got 1000000000"),
    (["fleet", "identify", "missing.wav", "--preset", "paper-sim", "--out", "o",
      "--max-retries", "1e9"], "error: --max-retries: must lie in [0, 10], got 1000000000"),
    (["spectrum", "missing.wav", "--floor-width", "1e9"],
     "error: --floor-width: must lie in [3, 10001], got 1000000000"),
    (["simulate", "--preset", "paper-sim", "--duration", "1e9"],
     "error: --duration: must lie in (0, 3600] s, got 1e+09"),
    (["compare-drives", "--preset", "paper-sim", "--discard", "1e9"],
     "error: --discard: must lie in [0, 60] s"),
    (["compare-drives", "--preset", "paper-sim", "--duration", "1e9"],
     "error: --duration: must lie in (0, 3600] s, got 1e+09"),
    # paper-sim: a 5000 Hz DAQ and 30 Hz on the sun: floor(2500 / 30) = 83 pulses per turn
    (["simulate", "--preset", "paper-sim", "--tacho-ppr", "1e9"],
     "error: --tacho-ppr: must lie in [1, 83], got 1000000000"),
    (["discover", "missing.wav", "--preset", "paper-bench", "--n-boot", "2.5"],
     "error: --n-boot: '2.5' is not a whole number (accepted: an integer)"),
]


def _case_id(argv: list[str], start: str) -> str:
    option = start.split(": ")[1]
    return f"{argv[0]} {option}={argv[argv.index(option) + 1]}"


@pytest.mark.parametrize("argv,start", SCIENTIFIC, ids=[_case_id(*c) for c in SCIENTIFIC])
def test_absurd_counts_are_refused_with_their_range(argv, start, tmp_path, monkeypatch, capsys):
    """`--n-boot 1e9` and the other counts across commands: a count may be written 1e3, and
    one beyond what can run (for ever, or out of memory) is one `error:` line with the
    accepted range, before any record is opened or anything simulated or fitted."""
    monkeypatch.chdir(tmp_path)
    _no_work(monkeypatch)
    line = _fails(argv, capsys)
    assert line.startswith(start), line


def test_num_cpus_bounded_by_the_machine(tmp_path, monkeypatch, capsys):
    import os

    monkeypatch.chdir(tmp_path)
    _no_work(monkeypatch)
    cpus = os.cpu_count()
    line = _fails(["fleet", "identify", "missing.wav", "--preset", "paper-sim", "--out", "o",
                   "--num-cpus", "1e9"], capsys)
    assert line.startswith(f"error: --num-cpus: must lie in [1, {cpus}], got 1000000000"), line


def test_view_counts_bounded_by_the_record(tmp_path, capsys):
    """view --revs and --segment beyond the record: named by their option with the record's
    range (the record: 0.5 s at 8 kHz, 4000 samples, the input shaft at 30 Hz, about 15
    revolutions), not by the library argument behind them."""
    import numpy as np
    from scipy.io import wavfile

    fs, n = 8000, 4000
    path = tmp_path / "tone.wav"
    wavfile.write(path, fs, (10000 * np.sin(2 * np.pi * 504.0 * np.arange(n) / fs))
                  .astype(np.int16))
    line = _fails(["view", str(path), "--kind", "waterfall", "--segment", "1e9"], capsys)
    assert line.startswith(f"error: --segment: must lie in [16, {n}], got 1000000000"), line
    with pytest.raises(SystemExit) as e:
        main(["view", str(path), "--kind", "ordermap", "--preset", "paper-bench", "--f-sun",
              "30", "--revs", "1e9"])
    assert e.value.code == 2
    last = capsys.readouterr().err.splitlines()[-1]  # after the short-record warnings
    assert last.startswith("error: --revs: must lie in [1, 1") and "got 1000000000" in last
    assert int(last.split("[1, ")[1].split("]")[0]) in (14, 15), last


def test_ctrl_c_inside_a_gc_callback_prints_no_traceback():
    """SIGINT while the main thread runs a garbage-collector callback (JAX registers one): the
    KeyboardInterrupt cannot leave the callback, and Python would print "Exception ignored in
    …" with a traceback. The dtwin command prints its one line and exits 130."""
    script = (
        "import gc, sys, time\n"
        "import dtwin.cli.cmd_freqs as m\n"
        "def slow(phase, info):\n"
        "    if phase == 'start':\n"
        "        time.sleep(0.05)\n"
        "def work(*a, **k):\n"
        "    gc.callbacks.append(slow)\n"
        "    print('ready', flush=True)\n"
        "    t = time.time()\n"
        "    while time.time() - t < 60:\n"
        "        gc.collect()\n"
        "m.freqs_report = work\n"
        "sys.argv = ['/usr/bin/dtwin', 'freqs', '--preset', 'paper-sim']\n"
        "from dtwin.cli import main\n"
        "main()\n")
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "ready"
        time.sleep(0.3)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130, err
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert err.splitlines() == [line for line in err.splitlines()
                                if line.startswith("interrupted")] and err.strip(), err
