"""The command line on bad input and interrupts (issue 53): one ``error:`` line naming the option
and what it accepts, exit 2, before any work; Ctrl-C while the command is still importing gives
one ``interrupted`` line and exit 130, never a traceback."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from dtwin.cli import main


def _fails(argv, capsys) -> str:
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2, err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    return lines[0]


@pytest.mark.parametrize("argv,option,accepted", [
    (["simulate", "--duration", "abc"], "--duration", "a number"),
    (["simulate", "--seed", "1.5"], "--seed", "an integer"),
    (["simulate", "--band", "1", "x"], "--band", "2 numbers"),
    (["simulate", "--bogus", "3"], "--bogus", "--duration"),
    (["simulate", "--json=3"], "--json", "a flag"),
    (["spec", "check"], "FILE", "a path"),
    (["record", "nope"], "COMMAND", "convert, info"),
])
def test_usage_errors_are_one_error_line(argv, option, accepted, capsys):
    """A wrong option value, an unknown option, a missing argument, an unknown command: the
    same one line as every other bad input, ``error: <option>: <what> (accepted: ...)``."""
    line = _fails(argv, capsys)
    assert line.startswith(f"error: {option}: "), line
    assert "(accepted: " in line and accepted in line.split("(accepted: ", 1)[1], line


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
    """dtwin.memory: the simulation's estimate in closed form (points × values × 8 bytes ×
    copies) and the refusal against a given available memory."""
    from dtwin.memory import MemoryLimitError, format_bytes, require, simulation_bytes

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
