"""The self-contained HTML report: parsed with html.parser, the embedded images decode as PNG,
the tables and the manifest are there, nothing is fetched from outside."""

import base64
import json
from html.parser import HTMLParser

import numpy as np
from matplotlib.figure import Figure

from dtwin.io.output import OutputFolder
from dtwin.report.html_report import write_html_report

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"  # PNG signature, ISO/IEC 15948 §5.2


class _Collect(HTMLParser):
    def __init__(self):
        super().__init__()
        self.imgs, self.tables, self.cells, self.ids, self.links = [], 0, [], {}, []
        self._cell, self._id = None, None
        self.text = {}

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.imgs.append(a)
        if tag == "table":
            self.tables += 1
        if tag in ("td", "th"):
            self._cell = ""
        if "id" in a:
            self._id = a["id"]
            self.text[self._id] = ""
        for k in ("href", "src"):
            if k in a and not a[k].startswith(("#", "data:")):
                self.links.append(a[k])

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self.cells.append(self._cell)
            self._cell = None
        if tag == "pre":
            self._id = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data
        if self._id is not None:
            self.text[self._id] += data


def test_report_parses(tmp_path):
    folder = OutputFolder(tmp_path / "run", command=["dtwin", "test"], parameters={"a": 1.5})
    fig = Figure(figsize=(3, 2))
    fig.add_subplot().plot(np.arange(5))
    folder.savefig("saved.png", fig)
    rows = [{"parameter": "sun_fault", "value": 0.3, "unit": "1"},
            {"parameter": "zeta_mesh", "value": 0.05, "unit": "1"}]
    path = write_html_report(folder, title="Test <report>", summary={"f_sun (Hz)": 29.7},
                             figures={"drawn": fig, "from file": "saved.png"},
                             tables={"Parameters": rows}, notes=["a note"])
    assert path.name == "report.html" and "report.html" in folder.manifest["files"]
    p = _Collect()
    p.feed(path.read_text())
    assert len(p.imgs) == 2
    for img in p.imgs:
        assert img["src"].startswith("data:image/png;base64,")
        png = base64.b64decode(img["src"].split(",", 1)[1], validate=True)
        assert png[:8] == PNG_MAGIC
    assert p.tables >= 3  # summary, parameters, manifest's run table
    assert "sun_fault" in p.cells and "0.3" in p.cells and "29.7" in p.cells
    manifest = json.loads(p.text["manifest-json"])
    assert manifest["parameters"] == {"a": 1.5} and manifest["command"] == ["dtwin", "test"]
    assert p.links == []  # self-contained: no external resource
    assert "Test &lt;report&gt;" in path.read_text()  # escaped


def test_report_in_staged_folder(tmp_path):
    # written into the staging folder, published with the rest
    try:
        folder = OutputFolder(tmp_path / "run", command=["x"], staged=True)
    except TypeError:  # OutputFolder without staging
        return
    with folder:
        write_html_report(folder, title="t", tables={"t": ([ "a", "b"], [[1, 2]])})
    assert (tmp_path / "run" / "report.html").exists()
    assert "report.html" in json.loads((tmp_path / "run" / "manifest.json").read_text())["files"]


def test_fleet_trends_report_and_arrays(tmp_path):
    # `dtwin fleet trends` writes report.html and trends.csv/.npz next to its figures
    from dtwin.cli.cmd_fleet import _trend_extras
    from dtwin.identify.plotting.fleet import plot_fleet_overview, plot_machine_trend
    from dtwin.identify.trends import machine_trends

    rows = [{"status": "ok", "machine": m, "record": f"{m}/d{d}",
             "timestamp": f"2026-02-{1 + d:02d}T00:00:00+00:00", "names": ["sun_fault"],
             "values": {"sun_fault": 0.1 + slope * d},
             "intervals_95": {"sun_fault": [0.07 + slope * d, 0.13 + slope * d]}}
            for m, slope in (("rising", 0.08), ("flat", 0.0)) for d in range(5)]
    trends = machine_trends(rows, {"sun_fault": (0.4, "above")}, horizon_days=30)
    folder = OutputFolder(tmp_path / "trends", command=["dtwin", "fleet", "trends"])
    for m, t in trends.items():
        folder.savefig(f"trend_{m}.png", plot_machine_trend(t))
    folder.savefig("overview.png", plot_fleet_overview(trends))
    _trend_extras(folder, tmp_path, trends, {"sun_fault": (0.4, "above")}, 30.0)
    p = _Collect()
    p.feed((tmp_path / "trends" / "report.html").read_text())
    assert len(p.imgs) == 3 and all(
        base64.b64decode(i["src"].split(",", 1)[1])[:8] == PNG_MAGIC for i in p.imgs)
    assert "rising" in p.cells and "crossed" in p.cells
    cols, units = read_columns_csv_text(tmp_path / "trends" / "trends.csv")
    assert units["days"] == "d" and len(cols["value"]) == 10
    np.testing.assert_allclose(sorted(cols["value"])[-1], 0.1 + 0.08 * 4)


def read_columns_csv_text(path):
    # trends.csv mixes text (machine, record, state) and numbers: read it with the csv module
    import csv

    with open(path) as f:
        r = list(csv.reader(f))
    names = [h.split(" [")[0] for h in r[0]]
    units = {n: h.split(" [")[1].rstrip("]") for n, h in zip(names, r[0], strict=True)}
    cols = {n: [row[i] for row in r[1:]] for i, n in enumerate(names)}
    cols["value"] = [float(v) for v in cols["value"]]
    return cols, units
