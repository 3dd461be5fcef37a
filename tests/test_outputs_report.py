"""Outputs an engineer keeps (issue #54): frequencies at full precision in reports, a legend of
the line-label symbols, discover's candidate table, spectra and views exported to CSV/NPZ/HDF5."""

from __future__ import annotations

import numpy as np
import pytest

from dtwin.io.export import (
    Columns,
    Grid,
    check_export_path,
    export_arrays,
    read_columns_csv,
)
from dtwin.report.html_report import frequency_text, html_report, symbol_legend


@pytest.mark.parametrize("f, text", [(2494.8, "2494.8"), (510.75, "510.75"),
                                     (12345.678, "12345.68"), (29.6999, "29.6999"),
                                     (0.25, "0.25"), (498.958, "498.958")])
def test_frequency_text_keeps_hundredths(f, text):
    assert frequency_text(f) == text
    assert abs(float(frequency_text(f)) - f) <= 0.005 + 1e-12


def test_html_tables_print_frequencies_in_full_and_other_values_at_four_digits():
    page = html_report("t", tables={"Peaks": [{"f (Hz)": 2494.8, "amplitude": 0.123456},
                                              {"f (Hz)": 510.75, "amplitude": 3.811234}]},
                       summary={"input speed (Hz, from the data)": 29.6999, "gap (dB)": 4.1534})
    assert ">2494.8<" in page and ">510.75<" in page and ">2495<" not in page
    assert ">29.6999<" in page           # a summary key naming Hz is a frequency
    assert ">0.1235<" in page and ">4.153<" in page   # other quantities: 4 significant digits


def test_symbol_legend_defines_every_label_symbol_used():
    fs = 29.7
    freqs = {"f_sun": fs, "f_carrier": fs * 21 / 105, "f_mesh": fs * 21 / 105 * 84,
             "f_sun_fault": fs * 21 / 105 * 84 * 3 / 21}
    rows = symbol_legend(["61fsr (comb)", "fm − 7fc", "2fm + fs/3 − fc"], freqs)
    by = {r["symbol"]: r for r in rows}
    assert set(by) == {"fm", "fc", "fsr", "fs/3", "(comb)"}   # "fs" alone is not used
    assert by["fsr"]["value (Hz)"] == pytest.approx(fs)
    # fs/3 = fsr − fc (docs: the sun fault's repetition per planet)
    assert by["fs/3"]["value (Hz)"] == pytest.approx(fs - fs * 21 / 105)
    assert "comb" in by["(comb)"]["meaning"]
    page = html_report("t", tables={"Unexplained lines": [{"kinematic description":
                                                            "61fsr (comb)"}]})
    assert "Symbols of the line labels" in page and "sun (input shaft) rotation" in page
    assert "Symbols of the line labels" not in html_report("t", tables={"x": [{"a": "b"}]})


def _discovery_result():
    """A two-step search written by hand: step 1 accepted a sun fault over a housing resonance
    (identified, closed less), a motor ripple (p above the level) and a bearing (screened out);
    the last step accepted nothing."""
    from dtwin.identify.discover.results import CandidateResult, DiscoveryResult, Step
    from dtwin.identify.discover.settings import DiscoverySettings
    from dtwin.identify.gap import GapResult
    from dtwin.model.kinematics import Kinematics

    def gap(v):
        return GapResult(v, {"all": v}, {"all": 10})

    sun = CandidateResult("sun_local_fault", "sun_rotation", 0.9, [], p_value=5e-4,
                          gap_after=5.5, identified=True, significant=True)
    hous = CandidateResult("housing_resonance", "housing_resonance", 0.3, [], p_value=1e-3,
                           gap_after=9.0, identified=True, significant=True)
    motor = CandidateResult("torque_ripple_6fe", "motor", 0.2, [], p_value=0.2, gap_after=16.0)
    bearing = CandidateResult("planet_bearing_outer", "planet_bearing_outer", 0.1, [],
                              screened="screened out, score 0.5 (2 df), rank 4")
    ring = CandidateResult("ring_local_fault", "ring_local_fault", 0.95, [], p_value=0.99,
                           gap_after=5.37, identified=False, significant=False)
    step = Step(1, "sun_local_fault", "sun_rotation", "sun_rotation", [], [], [],
                {"name": "severity", "unit": "1", "value": 0.55, "interval": [0.5, 0.6],
                 "typical_range": [0.0, 1.0], "typical_note": "fraction of the face"},
                5e-4, 0.0025, gap(17.45), gap(5.49), gap(5.20), [sun, hous, motor, bearing])
    kin = Kinematics.from_gears(21, 31, 84, 3, 29.7)
    settings = DiscoverySettings()
    return DiscoveryResult(kin, 29.7, 5000.0, settings, [step], gap(19.3), gap(5.2), [], [],
                           0.05, "no candidate significant and identified", [ring],
                           np.linspace(0.0, 2500.0, 3), np.ones(3), [np.ones(3)], [[]]), settings


def test_discovery_candidate_rows_say_why_each_was_kept_or_set_aside():
    from dtwin.identify.tables import discovery_candidate_rows

    result, settings = _discovery_result()
    rows = {(r["step"], r["candidate"]): r for r in discovery_candidate_rows(result)}
    assert len(rows) == 5
    assert rows[1, "sun_local_fault"]["outcome"] == "accepted"
    assert rows[1, "sun_local_fault"]["gap before (dB)"] == 17.45
    assert rows[1, "sun_local_fault"]["gap with it (dB)"] == 5.5
    assert "closed the gap more" in rows[1, "housing_resonance"]["why"]
    assert rows[1, "torque_ripple_6fe"]["why"] == "not significant: p = 0.2 > 0.0025"
    assert rows[1, "planet_bearing_outer"]["why"].startswith("screened out")
    last = rows[2, "ring_local_fault"]
    assert last["outcome"] == "set aside" and last["gap before (dB)"] == 5.20
    # the last step's level is alpha over the candidates it judged (one here)
    assert last["level"] == pytest.approx(settings.alpha)
    assert last["why"].startswith("not significant: p = 0.99 >")


def test_discover_html_shows_the_candidate_table(tmp_path):
    from dtwin.cli.cmd_discover import discover_files, markdown_report
    from dtwin.report.html_report import HTMLReport

    result, _ = _discovery_result()
    files = discover_files(result, {}, tmp_path / "rec.dtwin.h5", "0", "m/s^2")
    rep = files["report.html"]
    assert isinstance(rep, HTMLReport)
    page = html_report(rep.title, summary=rep.summary, tables=rep.tables,
                       frequencies=rep.frequencies)
    assert "Candidates judged in each step" in page
    for name in ("sun_local_fault", "housing_resonance", "torque_ripple_6fe",
                 "planet_bearing_outer", "ring_local_fault"):
        assert f">{name}<" in page
    assert "not significant: p = 0.2 &gt; 0.0025" in page
    md = markdown_report(result, "rec.dtwin.h5")
    assert "## Symbols of the line labels" in md and "| fm |" in md


def test_discover_markdown_prints_fitted_frequencies_in_full():
    """A step whose main value is a frequency (a housing resonance at 2494.8 Hz) keeps it, its
    interval and its parameter row in full in ``discover.md`` and on the terminal; other values
    keep four digits."""
    import dataclasses

    from dtwin.cli.cmd_discover import markdown_report, screen_summary

    result, _ = _discovery_result()
    step = result.steps[0]
    hz = {"name": "f_n", "unit": "Hz", "value": 2494.8, "interval": [2491.25, 2497.63],
          "typical_range": [500.0, 5000.0], "typical_note": "housing modes"}
    hous = dataclasses.replace(step.candidates[1], main=2494.8, main_unit="Hz",
                               main_name="f_n", main_interval=(2491.25, 2497.63))
    result.steps[0] = dataclasses.replace(
        step, effect="housing_resonance", named="housing_resonance", main=hz,
        parameters=[hz, {"name": "zeta", "unit": "1", "value": 0.0123456,
                         "interval": [0.01, 0.015]}],
        candidates=[step.candidates[0], hous, *step.candidates[2:]])
    md = markdown_report(result, "rec.dtwin.h5")
    assert "- f_n: 2494.8 Hz, 99 % interval [2491.25, 2497.63]" in md, md
    assert "| f_n | 2494.8 | [2491.25, 2497.63] | Hz |" in md
    assert "| zeta | 0.01235 |" in md
    assert "2494.8 Hz [2491.25, 2497.63]" in md  # the candidate table's fitted main value
    assert "2495" not in md and "2.49e+03" not in md
    assert any("f_n 2494.8 Hz [2491.25, 2497.63]" in ln for ln in screen_summary(result))


def test_value_text_keeps_frequencies_and_rounds_the_rest():
    from dtwin.report.html_report import value_text

    assert value_text(2494.8, "Hz", 3) == "2494.8"
    assert value_text(0.612345, "1") == "0.6123"
    assert value_text(2494.8, "m/s^2", 3) == "2.49e+03"


def test_export_round_trips_full_precision(tmp_path):
    f = np.linspace(0.0, 2500.0, 10001)
    a = np.abs(np.sin(f / 7.0)) + 1e-9 / 3
    cols = Columns({"frequency": f, "amplitude": a}, {"frequency": "Hz", "amplitude": "m/s^2"})
    grid = Grid(("time", np.arange(3.0), "s"), ("frequency", np.arange(4.0), "Hz"),
                ("amplitude", np.arange(12.0).reshape(4, 3), "m/s^2"))
    export_arrays(tmp_path / "s.csv", {"spectrum": cols})
    back, units = read_columns_csv(tmp_path / "s.csv")
    assert np.array_equal(back["frequency"], f) and np.array_equal(back["amplitude"], a)
    assert units == {"frequency": "Hz", "amplitude": "m/s^2"}
    export_arrays(tmp_path / "s.npz", {"spectrum": cols})
    z = np.load(tmp_path / "s.npz")
    assert np.array_equal(z["amplitude"], a) and list(z["units"]) == ["Hz", "m/s^2"]
    import h5py

    export_arrays(tmp_path / "sub" / "s.h5", {"spectrum": cols, "waterfall": grid},
                  attrs={"record": "r.h5"})
    with h5py.File(tmp_path / "sub" / "s.h5") as h:
        assert np.array_equal(h["spectrum/amplitude"][()], a)
        assert h["spectrum/frequency"].attrs["unit"] == "Hz"
        assert h["waterfall/amplitude"].shape == (4, 3)
        assert h.attrs["record"] == "r.h5"


def test_check_export_path_refuses_inputs_unknown_suffixes_and_existing_files(tmp_path):
    from dtwin.errors import DtwinError

    rec = tmp_path / "rec.h5"
    rec.write_bytes(b"x")
    with pytest.raises(DtwinError, match="input"):
        check_export_path(rec, inputs=[rec], force=True)
    with pytest.raises(DtwinError, match=r"\.csv"):
        check_export_path(tmp_path / "x.txt")
    (tmp_path / "y.csv").write_text("a")
    with pytest.raises(DtwinError, match="--force"):
        check_export_path(tmp_path / "y.csv")
    assert check_export_path(tmp_path / "y.csv", force=True) == tmp_path / "y.csv"
    assert rec.read_bytes() == b"x"


def test_kurtogram_table_holds_every_band_and_the_picked_one():
    from dtwin.cli.cmd_view import kurtogram_columns
    from dtwin.signal.envelope import fast_kurtogram

    rng = np.random.default_rng(0)
    fs = 5000.0
    t = np.arange(20000) / fs
    x = rng.normal(size=t.size)
    x += 8.0 * np.sin(2 * np.pi * 1800.0 * t) * (np.mod(t, 0.05) < 0.004)  # bursts at 1.8 kHz
    kg = fast_kurtogram(x, sample_rate=fs)
    c = kurtogram_columns(kg).columns
    assert c["kurtosis"].size == int(np.sum(kg.n_bands))
    assert np.all(c["f_high"] - c["f_low"] == pytest.approx(fs / 2 / c["n_bands"]))
    best = int(np.nanargmax(c["kurtosis"]))
    assert (c["f_low"][best], c["f_high"][best]) == pytest.approx(tuple(kg.best_band))
    assert c["f_low"][best] <= 1800.0 <= c["f_high"][best]


def test_discover_lists_a_line_below_the_scored_band_as_not_scored():
    """A line under the lowest knot of the calibrated response (0.8 N fc: 14.26 Hz at 29.7 Hz
    on 21/31/84) is listed in every output, marked as not scored; a line above is not marked."""
    import dataclasses

    from dtwin.cli.cmd_discover import markdown_report, screen_summary
    from dtwin.identify.lines import ResidualLine

    result, _ = _discovery_result()
    f_lo = 0.8 * 3 * result.kinematics.f_carrier
    low = ResidualLine("measured", result.kinematics.f_carrier, 24, 26.9, 40.0, (), 0.0)
    high = ResidualLine("measured", 1111.3, 4445, 20.0, 30.0, (), 0.0)
    result = dataclasses.replace(result, unexplained=[low, high], scored_from=f_lo)
    text = [ln for ln in screen_summary(result) if ln.startswith("unexplained")]
    assert "below the scored band from 14.26 Hz" in text[0] and "below" not in text[1]
    md = markdown_report(result, "rec.dtwin.h5")
    assert "lines outside are listed, not scored" in md
    assert sum("below the scored band" in ln for ln in md.splitlines()) == 1
    assert result.to_dict()["scored_from_hz"] == pytest.approx(f_lo)
