"""What `dtwin discover` says of each candidate, and how its reports write line labels and
frequencies, checked on a search written by hand (no discovery is run):

- the terminal, ``discover.json``, ``discover.md`` and ``report.html`` give every candidate the
  same "identified" and the same verdict (one table,
  :meth:`dtwin.identify.discover.DiscoveryResult.candidate_table`), a candidate judged in two
  steps included;
- the HTML report holds the candidate table (name, group, score and rank, coverage, fitted
  value, out-of-range note, why set aside);
- every symbol of every line label in ``discover.md`` and ``report.html`` is defined in the
  page's legend, the legend and docs/signal_processing.md come from one table in code, and a
  label cannot use a symbol that table lacks;
- frequencies in the HTML keep 0.01 Hz (2494.8 Hz is not 2495), a fitted frequency too.
"""

from __future__ import annotations

import html as html_mod
import json
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _gap(v):
    from dtwin.identify.gap import GapResult

    return GapResult(v, {"all": v}, {"all": 10})


def _line(f, text="", comb="", excess=12.0):
    """A measured residual line at `f` (Hz) described by `text` ("" for none)."""
    from dtwin.identify.lines import Description, ResidualLine

    desc = (Description((), f, 0.0, 1, 1, text),) if text else ()
    return ResidualLine("measured", f, 0, excess, excess + 6.0, desc, 0.05, comb)


def _result():
    """Two steps and a last one that accepted nothing, written by hand.

    Step 1 accepted a sun fault whose linearised severity left its range (refitted inside it
    in full: no interval); a planet fault was significant and identified but not kept once
    simulated in full; a torque ripple was not significant; a bearing was screened out. Step 2
    accepted a load fluctuation; the torque ripple, judged again, was significant but not
    identified. The last step set aside a housing resonance (a failed refit)."""
    from dtwin.identify.discover.results import CandidateResult, DiscoveryResult, Step
    from dtwin.identify.discover.settings import DiscoverySettings
    from dtwin.model.kinematics import Kinematics

    kin = Kinematics.from_gears(21, 31, 84, 3, 29.7, pole_pairs=2)
    sun = CandidateResult("sun_local_fault", "sun_rotation", 0.9, [], p_value=5e-4,
                          gap_after=5.5, identified=True, significant=True, main=0.55,
                          main_interval=(float("nan"), float("nan")),
                          out_of_range="pitting severity = 1.19 1 lies outside its physical "
                                       "range [0, 1]; refitted inside the range in full "
                                       "simulation (6 trials, held-out gap 4.10 to 6.20 dB): "
                                       "0.55, no interval from the linearised model",
                          score=40.0, score_df=2, score_rank=1, main_name="pitting severity",
                          main_unit="1")
    planet = CandidateResult("planet_local_fault", "planet_fault", 0.7, [], p_value=1e-3,
                             gap_after=6.0, identified=True, significant=False, main=0.3,
                             main_interval=(0.2, 0.4), score=30.0, score_df=2, score_rank=2,
                             rejected="not kept: simulated in full, the held-out gap went "
                                      "17.45 → 18.00 dB (linearised 6.00 dB)",
                             main_name="pitting severity", main_unit="1")
    ripple1 = CandidateResult("torque_ripple_6fe", "motor", 0.2, [], p_value=0.2,
                              gap_after=16.0, identified=False, significant=False, main=0.01,
                              main_interval=(-0.01, 0.03), score=3.0, score_df=2,
                              score_rank=3, main_unit="N*m")
    bearing = CandidateResult("planet_bearing_outer", "planet_bearing_outer", 0.1, [],
                              score=0.5, score_df=2, score_rank=4,
                              screened="screened out, score 0.5 (2 df), rank 4")
    fluct = CandidateResult("load_fluctuation_2fc", "load_fluctuation", 0.6, [], p_value=1e-3,
                            gap_after=4.0, identified=True, significant=True, main=0.8,
                            main_interval=(0.6, 1.0), score=20.0, score_df=2, score_rank=1,
                            main_unit="N*m")
    ripple2 = CandidateResult("torque_ripple_6fe", "motor", 0.3, [], p_value=1e-4,
                              gap_after=4.5, identified=False, significant=True, main=0.02,
                              main_interval=(-0.01, 0.05), score=9.0, score_df=2,
                              score_rank=2, main_unit="N*m")
    resonance = CandidateResult("housing_resonance", "housing_resonance", 0.4, [],
                                rejected="refit failed: FloatingPointError: overflow",
                                score=5.0, score_df=1, score_rank=1)
    main_sun = {"name": "pitting severity", "unit": "1", "value": 0.55,
                "interval": [float("nan"), float("nan")], "typical_range": [0.0, 1.0],
                "typical_note": "fraction of the face"}
    main_fl = {"name": "torque amplitude", "unit": "N*m", "value": 0.8, "interval": [0.6, 1.0],
               "typical_range": [0.1, 5.0], "typical_note": "process loads"}
    matched1 = [_line(kin.f_mesh - 7 * kin.f_carrier, "fm − 7fc"),
                _line(61 * kin.f_sun, comb="61fsr"), _line(1000.0, "4BSF + fcage"),
                _line(1100.0, "fm + BPFO + fp")]
    step1 = Step(1, "sun_local_fault", "sun_rotation", "sun_rotation", [], matched1, [],
                 main_sun, 5e-4, 0.0025, _gap(17.45), _gap(5.49), _gap(5.20),
                 [sun, planet, ripple1, bearing],
                 matched_labels=["fm − 7fc", "61fsr", "", "2fm + fs/3 − fc"],
                 heldout_before=_gap(19.3), heldout_after=_gap(6.1))
    step2 = Step(2, "load_fluctuation_2fc", "load_fluctuation", "load_fluctuation",
                 [], [_line(2 * kin.f_carrier, "2fc")], [], main_fl, 1e-3, 0.005,
                 _gap(5.20), _gap(4.0), _gap(4.1), [fluct, ripple2],
                 matched_labels=["2fc"], heldout_before=_gap(6.1), heldout_after=_gap(5.0))
    unexplained = [_line(2494.8, "alias of 5fm"), _line(510.75, "fm + fs/3 − 6fe"),
                   _line(3.3, "fx"), _line(123.4), _line(0.6 * kin.f_mesh, "fr + 2fc")]
    return DiscoveryResult(kin, 29.7, 5000.0, DiscoverySettings(), [step1, step2], _gap(19.3),
                           _gap(5.0), unexplained, [], 0.05,
                           "no candidate significant and identified", [resonance],
                           np.linspace(0.0, 2500.0, 5), np.ones(5), [np.ones(5)] * 3,
                           [[], [], []])


def _record(path: Path) -> Path:
    """A 6 s record at 5 kHz (a mesh tone at 497 Hz with its carrier sidebands, in noise)."""
    from scipy.io import wavfile

    fs = 5000
    t = np.arange(6 * fs) / fs
    rng = np.random.default_rng(0)
    x = (np.sin(2 * np.pi * 497.0 * t) + 0.3 * np.sin(2 * np.pi * 491.1 * t)
         + 0.3 * np.sin(2 * np.pi * 502.9 * t) + 0.05 * rng.standard_normal(t.size))
    wavfile.write(path, fs, (8000 * x).astype(np.int16))
    return path


def _html_rows(page: str, caption: str) -> list[dict[str, str]]:
    """The rows of the HTML table captioned `caption` (cell texts by header)."""
    part = page.split(f"{html_mod.escape(caption)}</caption>", 1)[1].split("</table>", 1)[0]
    head = [html_mod.unescape(h) for h in re.findall(r"<th>(.*?)</th>", part)]
    rows = []
    for tr in re.findall(r"<tr>(.*?)</tr>", part.split("<tbody>", 1)[1]):
        cells = [html_mod.unescape(c) for c in re.findall(r"<td[^>]*>(.*?)</td>", tr)]
        rows.append(dict(zip(head, cells, strict=True)))
    return rows


def _candidate_caption(page: str) -> str:
    m = re.search(r"<caption[^>]*>(Candidates judged in each step[^<]*)</caption>", page)
    assert m, "no candidate table in report.html"
    return html_mod.unescape(m.group(1))


def test_screen_json_and_reports_agree_on_each_candidate(tmp_path, monkeypatch, capsys):
    """`dtwin discover` end to end with the search replaced by the hand-written result: each
    refit candidate's "identified" and verdict are the same on the terminal, in
    discover.json, discover.md and report.html; the torque ripple, judged in both steps,
    keeps one verdict per step (the terminal printed one per name before)."""
    import importlib

    from dtwin.cli import main

    # the module, not the function that dtwin.identify exports under the same name
    disc = importlib.import_module("dtwin.identify.discover")
    result = _result()
    monkeypatch.setattr(disc, "discover", lambda *a, **k: result)
    rec = _record(tmp_path / "rec.wav")
    out = tmp_path / "out"
    main(["discover", str(rec), "--preset", "paper-bench", "--f-sun", "29.7", "--no-depth",
          "--out", str(out)])
    screen = capsys.readouterr().out
    rows = result.candidate_table()
    assert len(rows) == 7
    doc = json.loads((out / "discover.json").read_text())
    md = (out / "discover.md").read_text()
    page = (out / "report.html").read_text()
    html_rows = _html_rows(page, _candidate_caption(page))
    assert len(doc["candidate_table"]) == len(html_rows) == len(rows)
    for r, j, h in zip(rows, doc["candidate_table"], html_rows, strict=True):
        assert (j["step"], j["candidate"], j["identified"], j["outcome"], j["why"]) == (
            r["step"], r["candidate"], r["identified"], r["outcome"], r["why"])
        assert (h["candidate"], h["identified"], h["outcome"], h["why"]) == (
            r["candidate"], str(r["identified"]), r["outcome"], r["why"])
        # the candidate's own record in the JSON carries the same flag
        where = (doc["steps"][r["step"] - 1]["candidates"] if r["step"] <= len(doc["steps"])
                 else doc["last_candidates"])
        assert next(c for c in where if c["name"] == r["candidate"])["identified"] \
            == r["identified"]
        md_row = f"| {r['candidate']} | {r['group']} |"
        md_line = next(ln for ln in md.splitlines()
                       if ln.startswith(md_row) and f"| {r['outcome']}: {r['why']} |" in ln)
        assert f"| {r['identified']} |" in md_line
        if r["why"].startswith("screened out"):
            assert re.search(rf"step {r['step']}: screened out \(not refit\): .*"
                             rf"{r['candidate']}", screen)
        else:
            assert (f"step {r['step']} candidate {r['candidate']}: identified "
                    f"{r['identified']}; {r['outcome']}: {r['why']}") in screen
    by = {(r["step"], r["candidate"]): r for r in rows}
    assert by[1, "torque_ripple_6fe"]["why"] == "not significant: p = 0.2 > 0.0025"
    assert by[2, "torque_ripple_6fe"]["why"].startswith("amplitude not identified")
    assert by[1, "planet_local_fault"]["identified"] is True
    assert by[1, "planet_local_fault"]["why"].startswith("not kept: simulated in full")
    # the accepted out-of-range fit says it has no interval, not that its interval excludes 0
    acc = by[1, "sun_local_fault"]
    assert acc["outcome"] == "accepted" and acc["interval"] is None
    assert "no interval" in acc["why"] and "interval excludes zero" not in acc["why"]
    assert by[2, "load_fluctuation_2fc"]["why"].endswith("lower simulated in full")
    assert "interval excludes zero" in by[2, "load_fluctuation_2fc"]["why"]


def test_discover_html_holds_the_candidate_table():
    """report.html of discover: one row per candidate of each step with its name, group,
    screening score and rank, coverage, fitted value, out-of-range note and why."""
    from dtwin.cli.cmd_discover import discover_files
    from dtwin.report.html_report import html_report

    result = _result()
    rep = discover_files(result, {}, Path("rec.dtwin.h5"), "0", "m/s^2")["report.html"]
    page = html_report(rep.title, summary=rep.summary, tables=rep.tables,
                       frequencies=rep.frequencies)
    rows = _html_rows(page, _candidate_caption(page))
    assert [r["candidate"] for r in rows] == [
        "sun_local_fault", "planet_local_fault", "torque_ripple_6fe", "planet_bearing_outer",
        "load_fluctuation_2fc", "torque_ripple_6fe", "housing_resonance"]
    for col in ("group", "coverage", "score", "score df", "rank", "p-value", "identified",
                "main", "main unit", "interval", "out of range", "outcome", "why"):
        assert col in rows[0], col
    sun = rows[0]
    assert (sun["group"], sun["score"], sun["rank"], sun["coverage"], sun["main"]) == (
        "sun_rotation", "40", "1", "0.9", "0.55")
    assert sun["interval"] == "" and "refitted inside the range" in sun["out of range"]
    assert rows[1]["interval"] == "[0.2, 0.4]"
    assert rows[3]["why"] == "screened out, score 0.5 (2 df), rank 4"
    assert rows[6]["why"] == "refit failed: FloatingPointError: overflow"


#: A label's annotations (not frequency symbols) and its separators.
_NOTES = ("(comb)", "alias of")
_TERM = re.compile(r"^\d*(?P<sym>[A-Za-z]+(?:/\d+)?)$")


def _label_symbols(label: str) -> set[str]:
    """The symbols and annotations a line label uses, read by its grammar (terms joined by
    " + " and " − ", ties by " | ", a multiplier before a symbol), not by the legend's
    patterns."""
    out = set()
    for tie in label.split(" | "):
        for note in _NOTES:
            if note in tie:
                out.add(note)
                tie = tie.replace(note, " ")
        for term in re.split(r"\s[+−]\s|^−", tie.strip()):
            term = term.strip()
            if not term:
                continue
            m = _TERM.match(term)
            assert m, f"{term!r} of {label!r} is no term"
            out.add(m.group("sym"))
    return out


def _labels(result) -> list[str]:
    texts = [r.text for r in result.unexplained if r.descriptions or r.comb]
    for s in result.steps:
        texts += [r.text for r in s.matched_lines] + [lab for lab in s.matched_labels if lab]
    return texts


def test_every_label_symbol_in_the_reports_is_defined_there():
    """Each symbol of each line label that discover.md and report.html print is a row of the
    page's legend, with its meaning from dtwin.model.kinematics.SYMBOLS and, where the gearbox gives
    it, its value (fs/3 = fsr − fc; fe = 2 fsr for a two-pole-pair motor)."""
    from dtwin.cli.cmd_discover import discover_files, markdown_report
    from dtwin.model.kinematics import LABEL_NOTES, SYMBOLS
    from dtwin.report.html_report import LABEL_SYMBOLS, html_report

    result = _result()
    labels = _labels(result)
    used = set().union(*(_label_symbols(t) for t in labels))
    assert {"fm", "fc", "fsr", "fs/3", "fe", "fx", "fr", "BPFO", "fp", "BSF", "fcage",
            "(comb)", "alias of"} <= used
    md = markdown_report(result, "rec.dtwin.h5")
    legend_md = md.split("## Symbols of the line labels", 1)[1]
    md_rows = {ln.split(" | ")[0].lstrip("| "): ln.split(" | ")[1]
               for ln in legend_md.strip().splitlines()[2:]}
    rep = discover_files(result, {}, Path("rec.dtwin.h5"), "0", "m/s^2")["report.html"]
    page = html_report(rep.title, summary=rep.summary, tables=rep.tables,
                       frequencies=rep.frequencies)
    html_rows = {r["symbol"]: r for r in _html_rows(page, "Symbols of the line labels")}
    for t in labels:
        assert html_mod.escape(t) in page or html_mod.escape(t, quote=False) in page, t
    for sym in used:
        key = "fs/N" if sym.startswith("fs/") else sym
        meaning = SYMBOLS[key][0] if key in SYMBOLS else LABEL_NOTES[key]
        assert LABEL_SYMBOLS[key][1] == meaning
        assert md_rows.get(sym) == meaning, sym
        assert html_rows[sym]["meaning"] == meaning, sym
    kin = result.kinematics
    assert float(html_rows["fs/3"]["value (Hz)"]) == pytest.approx(
        kin.f_sun - kin.f_carrier, abs=0.01)
    assert float(html_rows["fe"]["value (Hz)"]) == pytest.approx(2 * kin.f_sun, abs=0.01)
    assert float(html_rows["fm"]["value (Hz)"]) == pytest.approx(kin.f_mesh, abs=0.005)


def test_a_label_symbol_needs_its_definition_and_the_docs_list_them_all():
    """combination_text refuses a symbol that dtwin.model.kinematics.SYMBOLS lacks; the effects'
    hand-made labels (torque ripple, load fluctuation) are written by it; the table of
    docs/signal_processing.md is the code's table."""
    from dtwin.identify.discover.effects.load_fluctuation import LoadFluctuationEffect
    from dtwin.identify.discover.effects.torque_ripple import TorqueRippleEffect
    from dtwin.model.kinematics import Kinematics, combination_text, symbol_of
    from dtwin.report.html_report import symbol_glossary_markdown

    with pytest.raises(ValueError, match="SYMBOLS"):
        combination_text((("fm", 1), ("fq", 2)))
    assert symbol_of("14fs/3") == "fs/N" and symbol_of("61fsr") == "fsr"
    kin = Kinematics.from_gears(21, 31, 84, 3, 29.7, pole_pairs=2)
    labels = [s.label for s in TorqueRippleEffect(harmonic=6).signature(kin, 2500.0)]
    labels += [s.label for s in LoadFluctuationEffect(order=2).signature(kin, 2500.0)]
    assert "6fe" in labels and "fm − 6fe + 3fc" in labels and "2fc" in labels
    assert not any("0fm" in t or "+ -" in t or "0fc" in t for t in labels)
    for t in labels:
        for sym in _label_symbols(t):
            symbol_of(sym)
    docs = (ROOT / "docs" / "signal_processing.md").read_text()
    assert "## Symbols of the line labels" in docs
    assert symbol_glossary_markdown() in docs


def test_html_frequencies_keep_a_hundredth_of_a_hertz():
    """Frequencies in report.html: the unexplained line at 2494.8 Hz reads 2494.8 (not 2495),
    510.75 Hz reads 510.75; a fitted parameter in Hz (a row whose unit column says Hz) keeps
    its digits too, while other quantities keep 4 significant digits."""
    from dtwin.cli.cmd_discover import discover_files
    from dtwin.report.html_report import html_report

    result = _result()
    rep = discover_files(result, {}, Path("rec.dtwin.h5"), "0", "m/s^2")["report.html"]
    page = html_report(rep.title, summary=rep.summary, tables=rep.tables,
                       frequencies=rep.frequencies)
    lines = _html_rows(page, "Unexplained lines")
    assert [r["frequency (Hz)"] for r in lines[:2]] == ["2494.8", "510.75"]
    assert ">2495<" not in page and ">510.8<" not in page
    fit = html_report("t", tables={"Fitted parameters": [
        {"parameter": "f_sun", "unit": "Hz", "initial": 30.0, "fitted": 29.6999,
         "lower_95": 29.61234, "upper_95": 29.78766},
        {"parameter": "k_sun_planet", "unit": "N/m", "initial": 1e8, "fitted": 1.234567e8,
         "lower_95": 1.1e8, "upper_95": 1.3e8}]})
    rows = _html_rows(fit, "Fitted parameters")
    assert (rows[0]["fitted"], rows[0]["lower_95"], rows[0]["upper_95"]) == (
        "29.6999", "29.6123", "29.7877")
    assert rows[1]["fitted"] == "1.235e+08"
