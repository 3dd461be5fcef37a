"""One self-contained HTML page per run (``report.html``): summary, figures embedded as base64
PNG, tables and the manifest, readable in any browser with no other file and no network.

Commands call :func:`write_html_report` with what they produced, on the same
:class:`~dtwin.io.output.OutputFolder` they write their other files into, before the folder is
committed (a staged folder publishes the page together with everything else, or nothing).

    from dtwin.report.html_report import write_html_report

    write_html_report(
        folder,                                   # the OutputFolder of the run
        title="Calibration of bench-1",
        summary={"record": "bench.h5", "f_sun (Hz)": 29.7},     # or a paragraph of text
        figures={"Measured vs fitted": fig, "Loss": "loss.png"},  # Figure, PNG bytes or a file
        tables={"Parameters": rows},              # list of dicts, DataFrame, or (header, rows)
        notes=["k_sun_planet is NOT DETERMINED by a 5 kHz record"],
    )

The page has no scripts and no external links; images are ``data:image/png;base64,…`` URIs.
"""

from __future__ import annotations

import base64
import dataclasses
import datetime as _dt
import html
import io
import json
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..io.output import to_jsonable
from ..model.kinematics import LABEL_NOTES, SYMBOLS

__all__ = ["LABEL_SYMBOLS", "HTMLReport", "figure_png", "frequency_text", "html_report",
           "symbol_glossary_markdown", "symbol_legend", "symbol_legend_markdown",
           "value_text", "write_html_report"]

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;
margin:0 auto;max-width:1150px;padding:1.2em 1.6em;color:#1d2430;line-height:1.45}
h1{font-size:1.55em;margin:.2em 0 .1em}h2{font-size:1.2em;margin-top:1.6em;
border-bottom:1px solid #d5dae1;padding-bottom:.2em}
.meta{color:#5b6572;font-size:.9em}
table{border-collapse:collapse;margin:.5em 0 1em;font-size:.88em}
th,td{border:1px solid #d5dae1;padding:.25em .6em;text-align:left;vertical-align:top}
th{background:#eef1f5}td.num{text-align:right;font-variant-numeric:tabular-nums}
tr:nth-child(even) td{background:#f8f9fb}
figure{margin:1em 0 1.6em}figure img{max-width:100%;height:auto;border:1px solid #e3e6ea}
figcaption{font-size:.9em;color:#39424e;margin-top:.3em}
ul.notes li{margin:.2em 0}
nav a{margin-right:1em}
details{margin:.6em 0}summary{cursor:pointer;font-weight:600}
pre{background:#f4f6f8;padding:.8em;overflow:auto;font-size:.8em;max-height:40em}
"""


def figure_png(fig: Any, dpi: int = 110) -> bytes:
    """PNG bytes of a matplotlib Figure (tight bounding box)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return buf.getvalue()


def _png_of(item: Any, folder_path: Path | None) -> bytes:
    if isinstance(item, (bytes, bytearray)):
        return bytes(item)
    if isinstance(item, (str, Path)):
        p = Path(item)
        if not p.is_absolute() and folder_path is not None:
            p = folder_path / p
        return p.read_bytes()
    if hasattr(item, "savefig"):
        return figure_png(item)
    raise TypeError(f"a figure must be a matplotlib Figure, PNG bytes or a PNG file, got "
                    f"{type(item).__name__}")


#: Words of a column header or summary key that mark its values as frequencies (Hz).
_FREQUENCY_KEY = re.compile(r"\bHz\b|_hz\b|frequenc|\bf_[a-z]|^f\b|^f \(", re.IGNORECASE)


def frequency_text(f: float) -> str:
    """A frequency (Hz) as text with at least six significant digits and at least 0.01 Hz
    resolution: 2494.8 Hz is ``2494.8``, 12345.678 Hz ``12345.68``, never rounded to four
    digits as other quantities are."""
    import numpy as np

    if not np.isfinite(f):
        return str(f)
    digits = 6 if f == 0 else max(6, int(np.floor(np.log10(abs(f)))) + 3)
    return f"{f:.{digits}g}"


def value_text(v: float, unit: str = "", digits: int = 4) -> str:
    """A value as report text: a frequency (`unit` ``"Hz"``) by :func:`frequency_text`, any
    other quantity with `digits` significant digits (a fitted housing resonance of 2494.8 Hz
    stays ``2494.8``; a severity of 0.61234 is ``0.6123``)."""
    if str(unit).strip() == "Hz":
        return frequency_text(float(v))
    return f"{float(v):.{digits}g}"


def is_frequency_key(key: str) -> bool:
    """Whether a column header or summary key names a frequency (``"f (Hz)"``,
    ``"frequency"``, ``"f_sun_hz"``, ``"band (Hz)"``)."""
    return bool(_FREQUENCY_KEY.search(str(key)))


def _fmt(v: Any, frequency: bool = False) -> tuple[str, bool]:
    """Cell text and whether it is numeric; floats with 4 significant digits, frequencies
    (`frequency`) by :func:`frequency_text`."""
    import numpy as np

    if isinstance(v, (bool, np.bool_)):
        return str(bool(v)), False
    if isinstance(v, (int, np.integer)):
        return str(int(v)), True
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if frequency:
            return frequency_text(f), True
        return (f"{f:.4g}" if np.isfinite(f) else str(f)), True
    if v is None:
        return "", False
    if isinstance(v, (list, tuple)) and all(isinstance(x, (int, float)) for x in v) and v:
        return "[" + ", ".join(_fmt(x, frequency)[0] for x in v) + "]", False
    return str(v), False


def _label_symbols() -> dict[str, tuple[str, str]]:
    """:data:`LABEL_SYMBOLS` from the one table of the symbols (:data:`dtwin.model.kinematics.SYMBOLS`)
    and of the labels' annotations (:data:`dtwin.model.kinematics.LABEL_NOTES`)."""

    out = {}
    for sym, (meaning, _) in SYMBOLS.items():
        # "fs/N" stands for fs/<integer>; "N fc" is written as such
        pattern = (re.escape(sym[:-2]) + r"/\d+" if sym.endswith("/N") else re.escape(sym))
        out[sym] = (pattern, meaning)
    out.update({note: (re.escape(note), meaning) for note, meaning in LABEL_NOTES.items()})
    return out


#: Symbols of the line labels (``"fm − 7fc"``, ``"61fsr (comb)"``, ``"2fm + fs/3 − fc"``,
#: ``"BPFO + fp"``) and their annotations, each with the pattern that finds it as a token in a
#: page's tables, notes and captions and what it stands for: symbol → (pattern, meaning).
#: Written from :data:`dtwin.model.kinematics.SYMBOLS` and :data:`dtwin.model.kinematics.LABEL_NOTES`, the
#: one table that :func:`dtwin.model.kinematics.combination_text` checks every label against.
LABEL_SYMBOLS: dict[str, tuple[str, str]] = _label_symbols()


def _symbol_keys() -> dict[str, str]:

    return {sym: key for sym, (_, key) in SYMBOLS.items() if key is not None}


#: Symbol of LABEL_SYMBOLS → key of the `frequencies` mapping that gives its value (Hz).
_SYMBOL_KEYS = _symbol_keys()


def _symbol_pattern(pattern: str) -> re.Pattern:
    # a symbol is a token: not inside a word ("offset", "fcage" holds no "fc"), not the whole
    # of a fraction ("fs/3" holds no "fs"); a multiplier may precede it ("61fsr")
    return re.compile(r"(?<![A-Za-z_])" + pattern + r"(?![A-Za-z_/])")


_SYMBOL_PATTERNS = {k: _symbol_pattern(p) for k, (p, _) in LABEL_SYMBOLS.items()}


def symbol_legend(texts: Sequence[str], frequencies: Mapping[str, Any] | None = None
                  ) -> list[dict[str, Any]]:
    """The legend of the line-label symbols used in `texts`: one row per symbol found, with
    its meaning and, where `frequencies` gives it, its value (Hz).

    **Arguments:**

    - `texts`: the label texts of a page (cells, notes, captions).
    - `frequencies`: characteristic frequencies by name (Hz), as
      :func:`dtwin.model.gears.characteristic_frequencies` (``f_mesh``, ``f_carrier``, ``f_sun``,
      …); ``n_planets`` adds ``fs/N``'s value.

    **Returns:** rows ``{"symbol", "meaning", "value (Hz)"}`` in the order of
    :data:`LABEL_SYMBOLS`; empty when no symbol occurs.
    """
    joined = "\n".join(str(t) for t in texts)
    freqs = dict(frequencies or {})
    rows = []
    for sym, (_, meaning) in LABEL_SYMBOLS.items():
        found = _SYMBOL_PATTERNS[sym].findall(joined)
        if not found:
            continue
        shown = sorted(set(found))[0] if sym == "fs/N" else sym
        value = freqs.get(_SYMBOL_KEYS.get(sym, ""))
        if sym == "fs/N" and freqs.get("f_sun_fault") is not None:
            n = int(shown.split("/")[1])
            value = float(freqs["f_sun_fault"]) / n
        rows.append({"symbol": shown, "meaning": meaning,
                     "value (Hz)": None if value is None else float(value)})
    return rows


def symbol_legend_markdown(texts: Sequence[str], frequencies: Mapping[str, Any] | None = None
                           ) -> str:
    """:func:`symbol_legend` as a Markdown table (an empty string when no symbol occurs)."""
    rows = symbol_legend(texts, frequencies)
    if not rows:
        return ""
    out = ["| symbol | meaning | value (Hz) |", "|---|---|---|"]
    out += [f"| {r['symbol']} | {r['meaning']} | "
            f"{'' if r['value (Hz)'] is None else frequency_text(r['value (Hz)'])} |"
            for r in rows]
    return "\n".join(out)


def symbol_glossary_markdown() -> str:
    """Every symbol and annotation a line label may use, with what it stands for, as a Markdown
    table (:data:`LABEL_SYMBOLS`, from :data:`dtwin.model.kinematics.SYMBOLS` and
    :data:`dtwin.model.kinematics.LABEL_NOTES`): the table of docs/signal_processing.md ("Symbols of
    the line labels"), which the tests compare with this text."""
    out = ["| symbol | meaning |", "|---|---|"]
    out += [f"| `{sym}` | {meaning} |" for sym, (_, meaning) in LABEL_SYMBOLS.items()]
    return "\n".join(out)


def _texts_of(tables: Mapping[str, Any], notes: Sequence[str], captions: Sequence[str]
              ) -> list[str]:
    texts = [str(n) for n in notes] + [str(c) for c in captions]
    for t in tables.values():
        header, rows = _table_rows(t)
        texts += [str(v) for r in rows for v in r if isinstance(v, str)]
    return texts


def _table_rows(table: Any) -> tuple[list[str], list[list[Any]]]:
    if hasattr(table, "to_dict") and hasattr(table, "columns"):  # a pandas DataFrame
        header = [str(c) for c in table.columns]
        return header, table.to_numpy().tolist()
    if isinstance(table, tuple) and len(table) == 2:
        return [str(h) for h in table[0]], [list(r) for r in table[1]]
    if isinstance(table, Mapping):  # name -> value: a two-column table
        return ["quantity", "value"], [[k, v] for k, v in table.items()]
    rows = list(table)
    header: list[str] = []
    for r in rows:
        header += [str(k) for k in r if str(k) not in header]
    return header, [[r.get(h) for h in header] for r in rows]


#: Columns of a table with a unit column (``unit``, ``main unit``) that hold values in the
#: row's unit: where that unit is Hz they are frequencies (:func:`frequency_text`).
_IN_ROW_UNIT = re.compile(r"^(value|initial|fitted|estimate|main|interval|sd|sigma|"
                          r"(lower|upper)[_ ]?\w*)$", re.IGNORECASE)


def _row_frequency_columns(header: list[str], row: list[Any]) -> set[int]:
    """The columns of `row` that hold a frequency because the row's unit column says Hz (a
    fitted ``f_sun`` of 29.6999 Hz is not shown as 29.7)."""
    units = [j for j, h in enumerate(header) if h == "unit" or h.endswith(" unit")]
    if not any(str(row[j]).strip() == "Hz" for j in units):
        return set()
    return {j for j, h in enumerate(header) if _IN_ROW_UNIT.match(h)}


def _table_html(caption: str, table: Any) -> str:
    header, rows = _table_rows(table)
    two_column = header == ["quantity", "value"]
    out = [f"<table><caption style='text-align:left;font-weight:600'>{html.escape(caption)}"
           "</caption><thead><tr>"]
    out += [f"<th>{html.escape(h)}</th>" for h in header]
    out.append("</tr></thead><tbody>")
    for r in rows:
        out.append("<tr>")
        in_hz = _row_frequency_columns(header, r)
        for j, v in enumerate(r):
            key = str(r[0]) if two_column and j == 1 else header[j]
            text, num = _fmt(v, is_frequency_key(key) or j in in_hz)
            out.append(f"<td class='num'>{html.escape(text)}</td>" if num
                       else f"<td>{html.escape(text)}</td>")
        out.append("</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def html_report(
    title: str,
    *,
    summary: str | Mapping[str, Any] | None = None,
    figures: Mapping[str, Any] | None = None,
    tables: Mapping[str, Any] | None = None,
    notes: Sequence[str] = (),
    manifest: Mapping[str, Any] | None = None,
    folder_path: Path | None = None,
    frequencies: Mapping[str, Any] | None = None,
) -> str:
    """The HTML text of a report (arguments as :func:`write_html_report`)."""

    figures = dict(figures or {})
    tables = dict(tables or {})
    legend = symbol_legend(_texts_of(tables, notes, list(figures)), frequencies)
    if legend:
        tables["Symbols of the line labels"] = legend
    parts = ["<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
             "<meta name='viewport' content='width=device-width,initial-scale=1'>",
             f"<title>{html.escape(title)}</title><style>{_CSS}</style></head><body>",
             f"<h1>{html.escape(title)}</h1>"]
    created = (manifest or {}).get("created") or _dt.datetime.now(_dt.UTC).isoformat(
        timespec="seconds")
    version = ((manifest or {}).get("versions") or {}).get("dtwin", "")
    parts.append(f"<p class='meta'>written {html.escape(str(created))}"
                 + (f" by dtwin {html.escape(str(version))}" if version else "") + "</p>")
    nav = [("summary", "Summary")] if summary else []
    nav += [("figures", "Figures")] if figures else []
    nav += [("tables", "Tables")] if tables else []
    nav += [("manifest", "Manifest")] if manifest is not None else []
    parts.append("<nav>" + "".join(f"<a href='#{a}'>{t}</a>" for a, t in nav) + "</nav>")
    if summary:
        parts.append("<h2 id='summary'>Summary</h2>")
        if isinstance(summary, Mapping):
            parts.append(_table_html("", summary))
        else:
            parts += [f"<p>{html.escape(p)}</p>" for p in str(summary).split("\n\n")]
    if notes:
        parts.append("<ul class='notes'>" + "".join(f"<li>{html.escape(n)}</li>" for n in notes)
                     + "</ul>")
    if figures:
        parts.append("<h2 id='figures'>Figures</h2>")
        for cap, item in figures.items():
            b64 = base64.b64encode(_png_of(item, folder_path)).decode("ascii")
            parts.append(f"<figure><img alt='{html.escape(cap, quote=True)}' "
                         f"src='data:image/png;base64,{b64}'><figcaption>{html.escape(cap)}"
                         "</figcaption></figure>")
    if tables:
        parts.append("<h2 id='tables'>Tables</h2>")
        parts += [_table_html(cap, t) for cap, t in tables.items()]
    if manifest is not None:
        m = to_jsonable(manifest)
        parts.append("<h2 id='manifest'>Manifest</h2>")
        brief = {k: m.get(k) for k in ("created", "command", "seed") if k in m}
        if isinstance(m.get("command"), list):
            brief["command"] = " ".join(m["command"])
        for name, info in (m.get("inputs") or {}).items():
            brief[f"input {name}"] = f"sha256 {info.get('sha256', '')[:16]}…, {info.get('bytes')} bytes"
        parts.append(_table_html("Run", brief))
        parts.append("<details><summary>manifest.json (full)</summary><pre id='manifest-json'>"
                     + html.escape(json.dumps(m, indent=2)) + "</pre></details>")
    parts.append("</body></html>\n")
    return "\n".join(parts)


def write_html_report(
    folder: Any,
    *,
    title: str,
    summary: str | Mapping[str, Any] | None = None,
    figures: Mapping[str, Any] | None = None,
    tables: Mapping[str, Any] | None = None,
    notes: Sequence[str] = (),
    manifest: Mapping[str, Any] | None = None,
    name: str = "report.html",
    frequencies: Mapping[str, Any] | None = None,
) -> Path:
    """Write one self-contained HTML report into an output folder.

    **Arguments:**

    - `folder`: the :class:`~dtwin.io.output.OutputFolder` of the run (staged or not); the page
      is written with its atomic writer and listed in its manifest.
    - `title`: the page's heading (e.g. ``"dtwin identify: bench_sun_fault.dtwin.h5"``).
    - `summary`: a paragraph of text (blank lines separate paragraphs) or a mapping
      quantity → value shown as a two-column table.
    - `figures`: caption → a matplotlib ``Figure``, PNG ``bytes``, or the name of a PNG already
      written into `folder` (or any path); each is embedded as a base64 PNG.
    - `tables`: caption → a list of dicts (columns in first-seen order), a pandas DataFrame,
      a ``(header, rows)`` tuple, or a mapping (two columns).
    - `notes`: short lines shown as a list under the summary (flags, warnings).
    - `manifest`: the manifest shown at the end; default ``folder.manifest`` (command, inputs
      with SHA-256, versions, parameters, files), in full inside a collapsible block.
    - `name`: file name in `folder` (``report.html``).
    - `frequencies`: the gearbox's characteristic frequencies (Hz, by name as
      :func:`dtwin.model.gears.characteristic_frequencies`), shown beside the symbols of the line
      labels; a table of every symbol the page's labels use ("fm", "fsr", "(comb)", …) is added
      whether or not they are given.

    Floats show 4 significant digits, except frequencies (a column or key naming Hz or a
    frequency, or a value column of a row whose unit column says Hz), which keep at least six
    digits and 0.01 Hz (:func:`frequency_text`).

    **Returns:** the path written (inside the staging folder until a staged folder commits).
    """
    text = html_report(title, summary=summary, figures=figures, tables=tables, notes=notes,
                       manifest=folder.manifest if manifest is None else manifest,
                       folder_path=Path(folder.path), frequencies=frequencies)
    return folder.write_text(name, text)


@dataclasses.dataclass
class HTMLReport:
    """A report to write later, into the folder of a run: ``files["report.html"] =
    HTMLReport(...)`` in a command's output mapping (:func:`dtwin.cli.options.emit` calls
    :meth:`write_into` after the files listed before it, so figures can be named by file).
    Fields as :func:`write_html_report`."""

    title: str
    summary: str | Mapping[str, Any] | None = None
    figures: Mapping[str, Any] | None = None
    tables: Mapping[str, Any] | None = None
    notes: Sequence[str] = ()
    frequencies: Mapping[str, Any] | None = None

    def write_into(self, folder: Any, name: str) -> Path:
        return write_html_report(folder, title=self.title, summary=self.summary,
                                 figures=self.figures, tables=self.tables, notes=self.notes,
                                 name=name, frequencies=self.frequencies)
