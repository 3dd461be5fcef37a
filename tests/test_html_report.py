"""The self-contained HTML report: parsed with html.parser, the embedded images decode as PNG,
the tables and the manifest are there, nothing is fetched from outside."""

import base64
import json
from html.parser import HTMLParser

import numpy as np
from matplotlib.figure import Figure

from dtwin.io.html_report import write_html_report
from dtwin.io.output import OutputFolder

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
