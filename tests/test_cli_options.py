"""Every command of the CLI with bad values of every option: one ``error:`` line naming the
option, exit code 2, no traceback, and nothing computed (issue #20, item 2).

The table :data:`BAD` holds, per command, bad values of each option. A completeness test walks
the typer application and fails for any option of any command that has no row here (flags and
the options listed in :data:`NO_BAD_VALUE` aside), so a new option joins the table or the
suite fails. The expensive steps (simulation, fits, discovery, fleet runs, drive comparisons)
are replaced by functions that fail the test if called: each case is refused before any work,
so the whole table runs in a few seconds.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from dtwin.cli import main

FS = 5000.0


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A 2 s CSV record (a 500 Hz tone in noise), a plain file, and a finished result folder."""
    d = tmp_path_factory.mktemp("cli_options")
    t = np.arange(int(2 * FS)) / FS
    rng = np.random.default_rng(0)
    x = np.sin(2 * np.pi * 499.0 * t) + 0.1 * rng.standard_normal(t.size)
    rec = d / "rec.csv"
    np.savetxt(rec, np.column_stack([t, x]), delimiter=",", header="time [s],acc [m/s^2]",
               comments="")
    plain = d / "plain.txt"
    plain.write_text("not a folder\n")
    done = d / "done"
    done.mkdir()
    (done / "manifest.json").write_text(json.dumps({"files": []}))
    return {"rec": str(rec), "file": str(plain), "done": str(done),
            "under_file": str(plain / "sub"), "missing": str(d / "no-such-file.csv")}


def _boom(*a, **k):
    raise AssertionError("work started before the options were checked")


@pytest.fixture()
def no_work(monkeypatch):
    """The expensive steps fail the test if they run."""
    from importlib import import_module

    from dtwin.cli import cmd_simulate

    monkeypatch.setattr(cmd_simulate, "run_simulation", _boom)
    for module, name in (("dtwin.identify.fit", "fit"),
                         ("dtwin.identify.severity", "estimate_severity"),
                         ("dtwin.identify.fleet", "run_fleet"),
                         ("dtwin.identify.discover", "discover"),
                         ("dtwin.report.drive_comparison", "compare_drives"),
                         ("dtwin.identify.calibrate", "calibrate")):

        monkeypatch.setattr(import_module(module), name, _boom)



S = ["--preset", "paper-sim"]
R = "{rec}"
OUT_BAD = [("--out", "{file}"), ("--out", "{under_file}")]

#: command words -> (base arguments that are valid, [(option, bad value), ...]).
#: A bad value is one value (or a tuple for options with several); ``{rec}`` etc. are filled
#: from the `files` fixture.
BAD: dict[tuple[str, ...], tuple[list[str], list[tuple[str, object]]]] = {
    ("freqs",): (S, [
        ("--preset", "paper-bex"), ("--spec", "{missing}"), ("--f-sun", "0"),
        ("--f-sun", "nan"), ("--f-sun", "1800"), ("--planet-fault", "left"), *OUT_BAD]),
    ("modes",): (S, [
        ("--preset", "nope"), ("--spec", "{file}"), ("--model", "rotational"),
        ("--planets", "0"), *OUT_BAD]),
    ("stiffness",): (S, [
        ("--preset", "nope"), ("--spec", "{missing}"), ("--fault", "sun:melted:0.5"),
        ("--planet", "7"), ("--cycles", "0"), ("--cycles", "-1"), *OUT_BAD]),
    ("simulate",): (S, [
        ("--preset", "nope"), ("--spec", "{missing}"), ("--fault", "sun:melted:0.5"),
        ("--f-sun", "-3"), ("--duration", "0"), ("--duration", "-1"), ("--discard", "-1"),
        ("--start", "flying"), ("--ramp-to", "0"), ("--kind", "quantum"),
        ("--sample-rate", "-5000"), ("--sample-rate", "200"), ("--quantity", "jerk"),
        ("--snr-db", "nan"), ("--seed", "-1"), ("--tacho-ppr", "0"), ("--band", ("550", "450")),
        *OUT_BAD]),
    ("spectrum", R): ([], [
        ("RECORD", "{missing}"), ("--channel", "nope"), ("--band", ("3000", "4000")),
        ("--window", "triangle"), ("--preset", "nope"), ("--spec", "{missing}"),
        ("--f-sun", "0"), ("--planet-fault", "x"), ("--threshold-db", "nan"),
        ("--min-spacing", "-1"), ("--max-peaks", "-3"), ("--floor-width", "1"),
        ("--sample-rate", "-1"), ("--scale", "loud"), ("--units", "furlongs"),
        ("--highpass", "0"), ("--segment", "2"), ("--overlap", "1.5"), ("--iso-group", "3"),
        ("--iso-support", "wobbly"), ("--tacho", "nope"), ("--tacho", "0:0"),
        ("--export", "{rec}"), *OUT_BAD]),
    ("view", R): (["--kind", "psd"], [
        ("RECORD", "{missing}"), ("--kind", "spectrogram"), ("--channel", "nope"),
        ("--preset", "nope"), ("--spec", "{missing}"), ("--f-sun", "0"),
        ("--band", ("-1", "5")), ("--speed-range", ("0", "5")), ("--segment", "2"),
        ("--nat", "-1"), ("--sample-rate", "0"), ("--revs", "0"), ("--scale", "loud"),
        ("--units", "furlongs"), ("--highpass", "0"), ("--export", "{rec}"),
        *OUT_BAD]),
    ("identify", R): (["--preset", "paper-sim", "--free", "sun_fault"], [
        ("RECORD", "{missing}"), ("--free", "sun_faul"), ("--spec", "{missing}"),
        ("--preset", "nope"), ("--model", "quantum"), ("--f-sun", "0"),
        ("--runup", ("50", "10")), ("--solver", "bfgs"), ("--starts", "0"), ("--refine", "0"),
        ("--jac", "central"), ("--max-steps", "0"), ("--channel", "nope"),
        ("--fit-window", "10"), ("--fit-window", "-1:4"), ("--fit-window", "0:0"),
        ("--fit-window", "1:4"), ("--fit-window", "0:0.1"),
        ("--sample-rate", "-1"), ("--out", "{done}"), ("--tacho", "0:x"), *OUT_BAD]),
    ("severity", R): (["--preset", "paper-sim"], [
        ("RECORD", "{missing}"), ("--spec", "{missing}"), ("--preset", "nope"),
        ("--location", "carrier"), ("--free", "nope"), ("--model", "quantum"),
        ("--f-sun", "0"), ("--channel", "nope"), ("--sample-rate", "-1"), ("--out", "{done}"),
        ("--fit-window", "start:4"), ("--fit-window", "0:nan"), ("--fit-window", "1.5:1"),
        ("--tacho", "nope"), ("--method", "fit"), ("--healthy", "{missing}"), *OUT_BAD]),
    ("fleet", "identify", R): (["--preset", "paper-sim", "--out", "{done}_fleet"], [
        ("--out", "{file}"), ("--spec", "{missing}"), ("--preset", "nope"),
        ("--free", "nope"), ("--model", "quantum"), ("--f-sun", "0"),
        ("--ray-address", "auto --engine local"), ("--engine", "spark"), ("--num-cpus", "0"),
        ("--batch-size", "0"), ("--max-retries", "-1"), ("--manifest", "{missing}"),
        ("--max-steps", "0"), ("--tol", "nan"), ("--tol", "2"), ("--starts", "0"),
        ("--refine", "0"), ("--grid", "bins"), ("--order-step", "0"), ("--f-max", "0"),
        ("--channel", ""), ("RECORDS", "{missing}"), ("--tacho", "0:0")]),
    ("fleet", "table"): ([], [("RESULTS", "{missing}")]),
    ("fleet", "trends"): (["{done}"], [
        ("RESULTS", "{missing}"), ("--threshold", "sun_fault>>1"), ("--horizon", "0"),
        *OUT_BAD]),
    ("calibrate", R): (["--preset", "paper-sim", "--out", "{done}_cal"], [

        ("RECORDS", "{missing}"), ("--spec", "{missing}"), ("--preset", "nope"),
        ("--model", "quantum"), ("--knots", "0"), ("--window-terms", "1"),
        ("--window-terms", "14"), ("--mesh-harmonics", "0"), ("--mesh-harmonics", "13"),
        ("--load-sharing", "maybe"), ("--f-sun", "0"), ("--tacho", "nope"),
        ("--channel", "nope"), ("--sample-rate", "-1"), *OUT_BAD]),
    ("discover", R): (["--preset", "paper-sim"], [

        ("RECORD", "{missing}"), ("--spec", "{missing}"), ("--preset", "nope"),
        ("--kind", "quantum"), ("--channel", "nope"), ("--sample-rate", "-1"),
        ("--max-steps", "-1"), ("--alpha", "0.5"), ("--alpha", "nan"), ("--n-boot", "0"),
        ("--seed", "-1"), ("--f-sun", "1800"), ("--tacho", "0:1:planet"), *OUT_BAD]),
    ("compare-drives",): (S, [
        ("--preset", "nope"), ("--spec", "{missing}"), ("--severities", "0,2"),
        ("--severities", "a,b"), ("--duration", "0"), ("--discard", "-1"),
        ("--kind", "quantum"), ("--quantity", "jerk"), ("--k-shaft", "0"),
        ("--speed-bandwidth", "-1"), *OUT_BAD]),
    ("record", "info", R): ([], [
        ("FILE", "{missing}"), ("--channels", ","), ("--sample-rate", "-1"),
        ("--time-column", "nope"), ("--units", "furlongs"), ("--sensitivity", "acc=lots"),
        ("--tacho", "nope"), ("--tacho-ppr", "0"), ("--tacho-shaft", "planet"),
        ("--group", "nope"), ("--format", "xls"), ("--preset", "nope"), ("--spec", "{missing}"),
        ("--f-sun", "0"), ("--f-mesh", "-1"), ("--f-carrier", "0"), *OUT_BAD]),
    ("record", "convert", R, "{done}/x.dtwin.h5"): ([], [
        ("FILE", "{missing}"), ("TARGET", "{done}/x.csv"), ("TARGET", "{under_file}.dtwin.h5"),
        ("--channels", ","), ("--sample-rate", "-1"), ("--time-column", "nope"),
        ("--units", "furlongs"), ("--sensitivity", "acc=lots"), ("--tacho", "nope"),
        ("--tacho-ppr", "0"), ("--tacho-shaft", "planet"), ("--group", "nope"),
        ("--format", "xls")]),
    ("spec", "check"): ([], [("FILE", "{missing}")]),
}

#: Options without a bad value: switches and options that take any text.
NO_BAD_VALUE = {"--json", "--force", "--help", "--quiet", "--progress", "--no-progress", "--csv",
                "--strict", "--discover", "--no-sensitivity", "--sweep", "--version"}

POSITIONAL = {"RECORD", "RECORDS", "RESULTS", "FILE", "TARGET"}


def _cases():
    for words, (base, rows) in BAD.items():
        for opt, value in rows:
            yield pytest.param(words, base, opt, value,
                               id=f"{' '.join(w for w in words if '{' not in w)} {opt}={value}")


def _fill(items, files):
    return [str(a).format(**files) for a in items]


def _args(words, base, opt, value, files):
    words = list(words)
    if opt in POSITIONAL:  # replace the positional argument
        if opt == "TARGET":
            words[-1] = value
        elif opt in ("RESULTS",) and base:
            base = [value]
        elif opt == "RESULTS":
            words.append(value)
        else:
            idx = next((i for i, w in enumerate(words) if w == R), None)
            if idx is None:
                words.append(value)
            else:
                words[idx] = value
        extra = []
    elif isinstance(value, tuple):
        extra = [opt, *value]
    elif opt == "--ray-address":
        extra = [opt, *str(value).split()]
    else:
        extra = [opt, value]
    # an option repeated in `base` is replaced (the bad value wins)
    base = list(base)
    if opt in base and opt not in POSITIONAL:
        i = base.index(opt)
        del base[i:i + 2]
    return _fill(words + base + extra, files)


@pytest.mark.parametrize("words,base,opt,value", list(_cases()))
def test_bad_value_refused_before_work(words, base, opt, value, files, no_work, capsys):
    args = _args(words, base, opt, value, files)
    t0 = time.perf_counter()
    with pytest.raises(SystemExit) as e:
        main(args)
    elapsed = time.perf_counter() - t0
    cap = capsys.readouterr()
    err = cap.err + cap.out  # `spec check` prints its problems as its report
    assert e.value.code == 2, (args, err)
    assert "Traceback" not in err and "internal error" not in err, err
    assert "error" in err.lower() or "problem" in err.lower(), err
    name = opt.lstrip("-").lower()
    assert opt in err or any(n in err.lower() for n in (name, name.replace("-", " "),
                                                          name.replace("-", "_"))) \
        or opt in POSITIONAL, (opt, err)

    assert elapsed < 20, elapsed  # generous: only reading, no simulation or fit


def test_every_option_has_a_bad_value():
    """New options join :data:`BAD` (or :data:`NO_BAD_VALUE` when no value is bad)."""
    import typer.main

    from dtwin.cli import _load_commands
    from dtwin.cli.app import app

    _load_commands()
    covered: dict[str, set[str]] = {}
    for words, (_, rows) in BAD.items():
        key = " ".join(w for w in words if not w.startswith("{"))
        covered[key] = {opt for opt, _ in rows}
    missing = []

    def walk(cmd, path):
        if hasattr(cmd, "commands"):
            for name, sub in cmd.commands.items():
                walk(sub, path + [name])
            return
        key = " ".join(path)
        if key == "spec schema":
            return
        for p in cmd.params:
            if p.param_type_name == "argument":
                continue
            opt = max(p.opts, key=len)
            if opt in NO_BAD_VALUE or getattr(p, "is_flag", False):
                continue
            if opt not in covered.get(key, set()):
                missing.append(f"{key} {opt}")

    walk(typer.main.get_command(app), [])
    assert not missing, f"options without a bad-value case in BAD: {missing}"


def test_version_and_quiet(capsys, files):
    main(["--version"])  # returns: exit code 0
    assert capsys.readouterr().out.startswith("dtwin ")

    main(["freqs", "--preset", "paper-bench"])
    err = capsys.readouterr().err
    # warnings (the bench's profile-shift note) are single 'warning:' lines, no source file
    assert "spec.py" not in err and "UserWarning" not in err
    assert all(line.startswith("warning: ") for line in err.splitlines()), err

    main(["--quiet", "freqs", "--preset", "paper-bench"])
    assert capsys.readouterr().err == ""


def test_out_holds_nothing_after_a_failure_and_a_rerun_starts_cleanly(tmp_path, monkeypatch,
                                                                      capsys):
    """Files and manifest appear together: a failure while writing leaves neither, and the
    same command afterwards is not refused ('already holds a result')."""
    from dtwin.io import output

    out = tmp_path / "res"
    real = output.OutputFolder.savefig

    def fail(self, name, fig, **kw):
        raise KeyboardInterrupt  # as if Ctrl-C arrived while the figure was written

    monkeypatch.setattr(output.OutputFolder, "savefig", fail)
    with pytest.raises(SystemExit) as e:
        main(["stiffness", "--preset", "paper-sim", "--out", str(out)])
    assert e.value.code == 130
    assert "interrupted" in capsys.readouterr().err
    assert not out.exists() or not any(p for p in out.iterdir())
    monkeypatch.setattr(output.OutputFolder, "savefig", real)
    main(["stiffness", "--preset", "paper-sim", "--out", str(out)])
    manifest = json.loads((out / "manifest.json").read_text())
    assert sorted(manifest["files"]) == ["stiffness.csv", "stiffness.json", "stiffness.npz",
                                       "stiffness.png"]
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", *sorted(manifest["files"])]


@pytest.mark.parametrize("sig,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_signals_give_130_and_143(tmp_path, sig, code):
    """A real process: the signal arrives during work; exit code and one line, --out empty."""
    out = tmp_path / "o"
    script = (
        "import sys, time\n"
        "import dtwin.cli.cmd_freqs as m\n"
        "def slow(*a, **k):\n"
        "    print('ready', flush=True); time.sleep(60)\n"
        "m.freqs_report = slow\n"
        "from dtwin.cli import main\n"
        f"main(['freqs', '--preset', 'paper-sim', '--out', {str(out)!r}])\n"
    )
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "ready"
        p.send_signal(sig)
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == code, err
    assert "interrupted" in err and "Traceback" not in err, err
    assert not (out / "manifest.json").exists()


def test_fleet_exits_1_when_a_record_failed(files, tmp_path, monkeypatch, capsys):
    """A fleet with a failed record keeps the others and exits 1 (0 would read as success)."""
    from importlib import import_module

    fleet = import_module("dtwin.identify.fleet")

    def fake_run(records, spec, out, settings, **kw):
        return fleet.FleetRun(out, "local", 5, 0, 1, 4, 0, 0, None, 0.1, [
            {"record": f"r{i}", "stage": "read", "error_type": "RecordError", "error": "bad"}
            for i in range(4)], [])

    monkeypatch.setattr(fleet, "run_fleet", fake_run)
    with pytest.raises(SystemExit) as e:
        main(["fleet", "identify", files["rec"], "--preset", "paper-sim", "--out",
              str(tmp_path / "fleet")])
    assert e.value.code == 1
    cap = capsys.readouterr()
    assert "1 fitted, 4 failed" in cap.out and "4 of 5 record(s) failed" in cap.err


def test_presets_and_help_agree_with_the_library(capsys):
    """The CLI's preset list is the library's, and every --preset help names all of them."""
    import typer.main

    from dtwin.cli import _load_commands
    from dtwin.cli.app import app
    from dtwin.cli.options import PRESETS
    from dtwin.spec import PRESETS as LIB

    assert tuple(PRESETS) == tuple(LIB)
    _load_commands()

    def walk(cmd):
        if hasattr(cmd, "commands"):
            for sub in cmd.commands.values():
                yield from walk(sub)
        else:
            yield cmd

    for cmd in walk(typer.main.get_command(app)):
        for p in cmd.params:
            if "--preset" in getattr(p, "opts", ()):
                assert all(name in p.help for name in PRESETS), (cmd.name, p.help)


def test_unwritable_out_refused_before_work(tmp_path, monkeypatch, no_work, capsys):
    """A folder the user cannot write to is refused up front (root can write anywhere, so the
    permission probe is replaced here)."""
    from dtwin.cli import options

    monkeypatch.setattr(options, "_writable", lambda folder: False)
    with pytest.raises(SystemExit) as e:
        main(["simulate", "--preset", "paper-sim", "--out", str(tmp_path / "ro" / "x")])
    assert e.value.code == 2
    assert "not writable" in capsys.readouterr().err
    assert not (tmp_path / "ro").exists()


def test_severity_flags_reach_the_library(files, monkeypatch, capsys):
    """`dtwin severity --low-band --jackknife --shapes --splits --flanks` asks the library for
    the low band, the band jackknife, the loss shapes (dtwin.identify.severity.estimate_severity:
    ``ramps="shapes"``), both excitation/response splits and every planet-tooth flank; without
    them, the jackknife, one shape, and the low band, splits and flanks where they apply (None);
    `--no-low-band`, `--no-jackknife`, `--no-splits` and `--no-flanks` turn those off."""
    from dtwin.identify import severity

    seen = []

    class Stop(Exception):
        pass

    def capture(*a, **k):
        seen.append((k.get("low_band"), k.get("jackknife"), k.get("ramps"), k.get("splits"),
                     k.get("flanks")))
        raise Stop

    monkeypatch.setattr(severity, "estimate_severity", capture)
    for extra, want in (([], (None, True, None, None, None)),
                        (["--low-band", "--jackknife", "--shapes", "--splits", "--flanks"],
                         (True, True, "shapes", True, True)),
                        (["--no-low-band", "--no-jackknife", "--no-splits", "--no-flanks"],
                         (False, False, None, False, False))):
        with pytest.raises(SystemExit):  # the stand-in stops the command once it was called
            main(["severity", files["rec"], "--preset", "paper-sim", *extra])
        assert seen[-1] == want
    capsys.readouterr()


def test_identify_and_fleet_splits_reach_the_library(files, tmp_path, monkeypatch, capsys):
    """`dtwin identify --splits/--no-splits` hands ``splits`` to the library (for a tooth
    fault's depth on one record, dtwin.identify.severity.estimate_severity; otherwise
    dtwin.identify.fit.fit) and `dtwin fleet identify --splits/--no-splits` to FleetSettings
    (both ends of a calibrated spec's excitation/response split, dtwin.identify.split);
    without them None (where a fault severity is free)."""
    from importlib import import_module

    fit_module = import_module("dtwin.identify.fit")
    severity_module = import_module("dtwin.identify.severity")
    fleet = import_module("dtwin.identify.fleet")
    seen = []

    class Stop(Exception):
        pass

    def capture_fit(*a, **k):
        seen.append(("identify", k.get("splits")))
        raise Stop

    def capture_fleet(records, spec, out, settings, **kw):
        seen.append(("fleet", settings.splits))
        raise Stop

    monkeypatch.setattr(fit_module, "fit", capture_fit)
    monkeypatch.setattr(severity_module, "estimate_severity", capture_fit)
    monkeypatch.setattr(fleet, "run_fleet", capture_fleet)
    for extra, want in (([], None), (["--splits"], True), (["--no-splits"], False)):
        for free in ("sun_fault", "sun_fault,k_sun_planet", "zeta_mesh"):
            with pytest.raises(SystemExit):  # the stand-ins stop the commands once called
                main(["identify", files["rec"], "--preset", "paper-sim", "--free", free,
                      *extra])
            assert seen[-1] == ("identify", want), free
        with pytest.raises(SystemExit):
            main(["fleet", "identify", files["rec"], "--preset", "paper-sim", "--out",
                  str(tmp_path / "fleet"), *extra])
        assert seen[-2:] == [("identify", want), ("fleet", want)]
    capsys.readouterr()


def test_severity_report_opens_with_the_estimate():
    """`dtwin severity --out`'s report.html starts its summary with the severity, the peak
    stiffness loss (%) and their 95 % intervals, for a planet fault the flank the record chose,
    and the status (stand-in estimates)."""
    import types

    from dtwin.cli.cmd_identify import _severity_headline

    est = types.SimpleNamespace(location="sun", severity=0.4502, interval=(0.4098, 0.4914),
                                method="gaussian", peak_loss=0.3087,
                                peak_interval=(0.234, 0.491), status="ok", flank="")
    rows = _severity_headline(est)
    assert rows == {
        "sun fault severity (dimensionless)": "0.45, 95 % [0.41, 0.491] (gaussian)",
        "peak stiffness loss (% of the mean mesh stiffness)": "30.9, 95 % [23.4, 49.1]",
        "status": "ok"}
    planet = types.SimpleNamespace(**{**vars(est), "location": "planet", "flank": "ring",
                                      "method": "gaussian + flanks"})
    rows = _severity_headline(planet)
    assert list(rows)[-2:] == ["planet tooth flank", "status"]
    assert rows["planet tooth flank"] == "ring"


def test_calibrated_spec_sets_the_twin_kind(files, tmp_path, monkeypatch, capsys):
    """`dtwin severity` leaves the kind to the library (None: dtwin.spec.build.SEVERITY_KIND, the
    translational twin, for a calibrated spec and a preset alike) unless --model asks for one,
    and says so when that is not the kind a calibrated spec was calibrated with."""
    from dtwin.identify import severity
    from dtwin.spec import preset, spec_to_dict
    from dtwin.spec.writer import spec_to_toml

    data = spec_to_dict(preset("paper-sim"))
    data.pop("source", None)
    data["model"] = {"kind": "translational"}
    data["calibration"] = {"records": "healthy.csv"}
    cal = tmp_path / "calibrated.toml"
    cal.write_text(spec_to_toml(data))
    seen = []

    class Stop(Exception):
        pass

    def capture(*a, **k):
        seen.append(k.get("kind"))
        raise Stop

    monkeypatch.setattr(severity, "estimate_severity", capture)
    for where, want in ((["--spec", str(cal)], None), (["--preset", "paper-sim"], None)):
        with pytest.raises(SystemExit):
            main(["severity", files["rec"], *where])
        assert seen[-1] == want
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["severity", files["rec"], "--spec", str(cal), "--model", "torsional"])
    assert seen[-1] == "torsional"
    assert "calibrated with the translational twin" in capsys.readouterr().err


def test_twin_kind_resolution():
    """dtwin.spec.build.twin_kind: the asked kind; else a calibrated spec's own; else torsional."""
    from dtwin.errors import SpecError
    from dtwin.spec import load_spec, preset, spec_to_dict
    from dtwin.spec.build import twin_kind

    plain = preset("paper-bench")
    assert plain["model"]["kind"] == "translational"
    assert twin_kind(plain) == "torsional"
    assert twin_kind(plain, "translational") == "translational"
    data = spec_to_dict(plain)
    data.pop("source", None)
    cal = load_spec({**data, "calibration": {"records": "a.h5"}})
    assert twin_kind(cal) == "translational"
    with pytest.warns(UserWarning, match="calibrated with the translational twin"):
        assert twin_kind(cal, "torsional") == "torsional"
    with pytest.raises(SpecError, match="model.kind"):
        twin_kind(cal, "rigid")


def test_a_warning_text_is_shown_once_per_command(capsys):
    """A warning raised again from another call site (the CLI and the library both resolving
    the twin kind) is one line on stderr; the next command shows it again."""
    import warnings

    from dtwin.cli.logs import setup_logging

    old = warnings.showwarning
    try:
        for _ in range(2):
            setup_logging()
            with warnings.catch_warnings():
                warnings.simplefilter("always")
                warnings.warn("the same text", UserWarning, stacklevel=1)
                warnings.warn("the same text", UserWarning, stacklevel=1)
                warnings.warn("another text", UserWarning, stacklevel=1)
            err = capsys.readouterr().err
            assert err.count("the same text") == 1 and err.count("another text") == 1, err
    finally:
        warnings.showwarning = old


def test_identify_warns_when_a_tooth_fault_is_fitted_with_the_torsional_twin(files, monkeypatch,
                                                                             capsys):
    """`dtwin identify --free sun_fault --model torsional` warns that a torsional twin reads
    tooth-fault severities small (dtwin.spec.build.warn_torsional_tooth_fault); without --model a
    tooth fault's depth on one record is fitted with severity's (translational) twin, and
    with --model translational or no fault free there is nothing to warn of."""
    from importlib import import_module

    class Stop(Exception):
        pass

    kinds = []

    def capture(*a, **k):
        kinds.append(k.get("kind"))
        raise Stop

    monkeypatch.setattr(import_module("dtwin.identify.fit"), "fit", capture)
    monkeypatch.setattr(import_module("dtwin.identify.severity"), "estimate_severity", capture)
    for extra, warned in ((["--free", "sun_fault", "--model", "torsional"], True),
                          (["--free", "sun_fault"], False),
                          (["--free", "sun_fault", "--model", "translational"], False),
                          (["--free", "zeta_mesh"], False)):
        with pytest.raises(SystemExit):
            main(["identify", files["rec"], "--preset", "paper-sim", *extra])
        err = capsys.readouterr().err
        assert ("sun_fault fitted with the torsional twin" in err) == warned, err
    # the depth of the sun fault alone: severity's own twin unless one is asked for
    assert kinds[:3] == ["torsional", None, "translational"], kinds
