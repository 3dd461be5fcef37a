"""Fleet trends say what they know (issue 53): a record beyond its alarm threshold is a crossing
whatever the trend; "too few records for a trend" is a state of its own, on the screen."""

from __future__ import annotations

import json

import numpy as np
import pytest


def _rows(machine, values, half=0.02):
    return [{"status": "ok", "machine": machine, "record": f"{machine}/r{d}.h5", "key": f"{machine}{d}",
             "timestamp": f"2026-03-{1 + d:02d}T00:00:00+00:00", "names": ["sun_fault"],
             "values": {"sun_fault": v}, "intervals_95": {"sun_fault": [v - half, v + half]}}
            for d, v in enumerate(values)]


#: machine → severities, one record a day, and the state against 0.4 above
FLEET = {
    "two_above": ([0.2, 0.51], "crossed"),       # the case: 2 records, the last above
    "two_below": ([0.1, 0.15], "too_few"),       # no trend, nothing above: not "ok"
    "jump": ([0.2, 0.2, 0.2, 0.2, 0.5], "crossed"),  # the line ends below 0.4, the record above
    "flat": ([0.1, 0.11, 0.1, 0.12], "ok"),
    "dip": ([0.2, 0.5, 0.2, 0.2], "crossed"),   # a record above, the last back below
    "one_above": ([0.45], "crossed"),           # one record: no trend, but above
}


def test_crossing_whatever_the_trend_and_too_few_records():
    from dtwin.identify.trends import fit_trend, machine_trends

    rows = [r for m, (v, _) in FLEET.items() for r in _rows(m, v)]
    tr = machine_trends(rows, {"sun_fault": (0.4, "above")})
    for m, (_, state) in FLEET.items():
        f = tr[m].parameters["sun_fault"].flag
        assert f.state == state, (m, f)
        assert tr[m].state == state
    # the jump: the weighted line (numpy's polyfit for equal intervals) ends below the threshold
    days = np.arange(5.0)
    b, a = np.polyfit(days, FLEET["jump"][0], 1)
    assert a + 4 * b < 0.4
    assert fit_trend(days, FLEET["jump"][0])[0] == pytest.approx(a)
    jump = tr["jump"].parameters["sun_fault"].flag
    assert jump.crossing_time.startswith("2026-03-05")  # the record above, day 4
    assert "0.5 is above 0.4" in jump.reason
    assert tr["two_above"].parameters["sun_fault"].flag.crossing_time.startswith("2026-03-02")
    assert "too few for a trend" in tr["two_below"].parameters["sun_fault"].flag.reason
    assert tr["flat"].flagged == [] and tr["two_below"].flagged == ["sun_fault"]
    dip = tr["dip"].parameters["sun_fault"].flag  # the record above is day 1
    assert dip.crossing_time.startswith("2026-03-02")
    assert "record 2 of 4 at 0.5 is above 0.4" in dip.reason and "back within" in dip.reason
    assert tr["one_above"].parameters["sun_fault"].flag.crossing_time.startswith("2026-03-01")


def test_fleet_trends_screen_shows_each_state(tmp_path, capsys):
    """`dtwin fleet trends` on a small results folder: the screen's state column and reasons."""
    from dtwin.cli import main
    from dtwin.identify.fleet.settings import SCHEMA

    res = tmp_path / "results"
    (res / "records").mkdir(parents=True)
    for m, (values, _) in FLEET.items():
        for r in _rows(m, values):
            r["schema"] = SCHEMA
            (res / "records" / f"{r['key']}.json").write_text(json.dumps(r))
    main(["fleet", "trends", str(res), "--threshold", "sun_fault>0.4"])
    lines = capsys.readouterr().out.splitlines()
    table = {line.split()[0]: line for line in lines[1:]}
    for m, (_, state) in FLEET.items():
        assert table[m].split()[2] == state, table[m]
    assert "too few for a trend" in table["two_below"]
    assert "0.51 is above 0.4" in table["two_above"]
    written = json.loads((res / "trends" / "trends.json").read_text())
    assert written["machines"]["two_below"]["state"] == "too_few"


def test_a_fleet_none_of_whose_records_can_be_fitted_is_refused_at_once(tmp_path, monkeypatch,
                                                                       capsys):
    """Issue 53's battery: `fleet identify` on one truncated (or unreadable, or empty) record
    started Ray (half a minute) to end in "1 failed". Now the records are checked first, in the
    command, until one can be fitted: none can, one error line naming each, exit 2, no results
    folder; one that can, and the run starts (its tasks report the others, as before)."""
    from _cli_errors import one_error_line
    from scipy.io import wavfile

    import dtwin.identify.fleet
    from dtwin.cli import main
    from dtwin.io.readers import write_record
    from dtwin.io.record import Record
    from dtwin.model.kinematics import Kinematics
    from dtwin.spec import preset

    class Started(Exception):
        pass

    def started(*a, **k):
        raise Started

    monkeypatch.setenv("DTWIN_DEBUG", "1")
    monkeypatch.setattr(dtwin.identify.fleet, "run_fleet", started)
    wav = tmp_path / "cut.wav"
    wavfile.write(wav, 5000, np.zeros(4000, np.int16))
    wav.write_bytes(wav.read_bytes()[:3000])
    text = tmp_path / "text.wav"
    text.write_text("not a WAV file\n")
    out = tmp_path / "results"
    line = one_error_line(["fleet", "identify", str(wav), str(text), "--preset", "paper-bench",
                           "--out", str(out)], capsys)
    assert "none of the 2 record(s) can be fitted" in line, line
    assert "cut.wav: WAV file is truncated" in line and "text.wav: not a WAV file" in line, line
    assert not out.exists()
    # a record with the spec's mesh lines among them: the run starts
    kin = Kinematics.from_gear_set(preset("paper-bench").gear_set(), 29.7)
    t = np.arange(20000) / 5000.0
    x = 0.05 * np.random.default_rng(0).standard_normal(t.size)
    for m in range(1, 4):
        for n in range(-2, 3):
            x += np.cos(2 * np.pi * (m * kin.f_mesh + n * kin.f_carrier) * t) / (m * (1 + abs(n)))
    good = tmp_path / "good.dtwin.h5"
    write_record(Record(x[None, :], 5000.0, ("acc",), ("m/s^2",), metadata={"f_sun": 29.7}), good)
    with pytest.raises(Started):
        main(["fleet", "identify", str(wav), str(good), "--preset", "paper-bench", "--out",
              str(out)])
