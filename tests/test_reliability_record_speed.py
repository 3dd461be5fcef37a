"""`dtwin record info` checks its speed against the record's gear lines (issue 53: "a speed the
record contradicts passes silently ... the warning exists for every command"): `spectrum`,
`view` warn and the fits refuse, but `record info --f-sun 20` on a 29.7 Hz record printed the
frequencies at 20 Hz and "no problems found", and `--strict` passed it."""

from __future__ import annotations

import numpy as np

from dtwin.cli import main
from dtwin.io.readers import write_record
from dtwin.io.record import Record
from dtwin.model.kinematics import Kinematics
from dtwin.spec import preset

F_SUN = 29.7  # paper-bench's speed
FS = 5000.0


def _record(path, *, tone: bool = False) -> str:
    """4 s of paper-bench's gear lines at 29.7 Hz in noise, or a 200 Hz pure tone."""
    t = np.arange(int(4 * FS)) / FS
    x = 0.05 * np.random.default_rng(0).standard_normal(t.size)
    if tone:
        x += np.sin(2 * np.pi * 200.0 * t)
    else:
        kin = Kinematics.from_gear_set(preset("paper-bench").gear_set(), F_SUN)
        for m in range(1, 5):
            for n in range(-3, 4):
                f = m * kin.f_mesh + n * kin.f_carrier
                if f < 0.45 * FS:
                    x += np.cos(2 * np.pi * f * t + m + n) / (m * (1 + abs(n)))
    write_record(Record(x[None, :], FS, ("acc",), ("m/s^2",)), path)
    return str(path)


def _info(argv, capsys) -> tuple[int, str]:
    try:
        main(["record", "info", *argv])
        code = 0
    except SystemExit as e:
        code = e.code
    out, err = capsys.readouterr()
    # rich wraps to the terminal's width (narrower in CI): compare words, not line breaks
    return code, " ".join((out + err).split())


def test_record_info_flags_a_speed_the_lines_contradict(tmp_path, capsys):
    rec = _record(tmp_path / "bench.dtwin.h5")
    code, text = _info([rec, "--preset", "paper-bench", "--f-sun", "20", "--strict"], capsys)
    assert code == 2, text
    assert "--f-sun 20 Hz disagrees with the record's mesh lines" in text, text
    assert "problem(s) found with --strict (speed)" in text, text
    # without --strict: listed as a problem, exit 0
    code, text = _info([rec, "--preset", "paper-bench", "--f-sun", "20"], capsys)
    assert code == 0 and "1 problem(s)" in text and "disagrees" in text, text
    # the record's own speed (the spec's here): no problem
    code, text = _info([rec, "--preset", "paper-bench", "--strict"], capsys)
    assert code == 0 and "no problems found" in text, text


def test_record_info_flags_a_record_without_the_specs_mesh_lines(tmp_path, capsys):
    rec = _record(tmp_path / "tone.dtwin.h5", tone=True)
    code, text = _info([rec, "--preset", "paper-bench", "--strict"], capsys)
    assert code == 2, text
    assert "shows no mesh line where it puts them" in text, text
    # without a gearbox nothing is claimed, nothing checked
    code, text = _info([rec, "--strict"], capsys)
    assert code == 0 and "no problems found" in text, text

