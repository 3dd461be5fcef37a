"""`dtwin view`: the run-up order map and order cuts (tachometer, or the speed estimated from the
mesh phase), and the arrays behind every view as CSV/NPZ with units."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from dtwin.cli import main

RUNUP = Path(__file__).parent.parent / "data" / "samples" / "bench_runup.dtwin.h5"


def _npz(path):
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


@pytest.fixture(scope="module")
def maps(tmp_path_factory):
    from dtwin.io.readers import read_record, write_record

    tmp = tmp_path_factory.mktemp("view")
    rec = read_record(RUNUP)
    bare = tmp / "runup_no_tacho.dtwin.h5"  # the same run-up without its tachometer
    write_record(dataclasses.replace(rec, tacho=None, tacho_ppr=None, tacho_shaft=None), bare)
    out = {}
    for name, path, extra in (("tacho", RUNUP, []),
                              ("mesh", bare, ["--f-sun", "27.5", "--speed-range", "18", "38"])):
        main(["view", str(path), "--kind", "ordermap", "--preset", "paper-bench", "--revs", "9",
              *extra, "--out", str(tmp / name), "--json"])
        out[name] = tmp / name
    return rec, out


def test_order_map_from_tachometer(maps, capsys):
    rec, out = maps
    m = _npz(out["tacho"] / "ordermap.npz")
    assert list(m["columns"]) == ["rpm", "order", "amplitude"]
    assert list(m["units"]) == ["1/min", "1/rev", "m/s^2"]
    assert m["amplitude"].shape == (m["order"].size, m["rpm"].size)
    # the run-up sweeps 20 -> 35 Hz (the record's metadata): 1200 -> 2100 rpm
    lo, hi = rec.metadata["ramp_hz"]
    assert 60 * lo < m["rpm"].min() < m["rpm"].max() < 60 * hi
    # the mesh order Zs Zr / (Zs + Zr) = 21 * 84 / 105 = 16.8 dominates the orders above 5
    sel = m["order"] > 5
    peak = m["order"][sel][np.argmax(m["amplitude"][sel].mean(axis=1))]
    assert peak in (pytest.approx(16.8, abs=0.12), pytest.approx(33.6, abs=0.12))
    cuts = _npz(out["tacho"] / "ordercuts.npz")
    assert {"rpm", "order fm", "order 2fm"} <= set(cuts["columns"])
    files = set(json.loads((out["tacho"] / "manifest.json").read_text())["files"])
    assert {"ordermap.png", "ordercuts.png", "ordermap.csv", "ordercuts.csv"} <= files


def test_order_map_from_estimated_speed(maps):
    _, out = maps
    a = _npz(out["tacho"] / "ordercuts.npz")
    b = _npz(out["mesh"] / "ordercuts.npz")
    # the speed tracked from the mesh phase gives the same rpm at each stretch's time (2 %; the
    # stretches start at another angle origin) and the same fm order cut (within 1.5 dB)
    inner = (a["time"] > b["time"][0]) & (a["time"] < b["time"][-1])
    np.testing.assert_allclose(np.interp(a["time"], b["time"], b["rpm"])[inner],
                               a["rpm"][inner], rtol=0.02)  # measured: up to 1.3 %
    fm_b = np.interp(a["time"], b["time"], b["order fm"])[inner]
    np.testing.assert_allclose(20 * np.log10(fm_b / a["order fm"][inner]), 0, atol=1.5)
    rep = json.loads((out["mesh"] / "view_ordermap.json").read_text())
    assert rep["angle_source"].startswith("mesh phase")
