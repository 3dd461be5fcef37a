"""Every command's --out also writes its arrays (CSV and NPZ, named columns with units): the
commands whose arrays are tables of the gearbox (freqs, modes, stiffness). The values are
checked against the closed forms and the JSON the same command writes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dtwin.cli import main


def _run(args):
    try:
        main(args)
    except SystemExit as e:  # typer's standalone mode ends with SystemExit(0)
        assert e.code in (0, None)


def test_freqs_arrays(tmp_path):
    out = tmp_path / "f"
    _run(["freqs", "--preset", "paper-sim", "--out", str(out)])
    header = (out / "freqs.csv").read_text().splitlines()[0]
    assert "frequency [Hz]" in header
    z = np.load(out / "freqs.npz", allow_pickle=False)
    names = list(z["name"])
    f = dict(zip(names, z["frequency"], strict=True))
    fc = 30.0 * 21 / (21 + 81)  # f_carrier = f_sun Zs / (Zs + Zr), ring fixed
    assert f["f_carrier"] == pytest.approx(fc)
    assert f["f_mesh"] == pytest.approx(81 * fc)


def test_modes_and_stiffness_arrays(tmp_path):
    _run(["modes", "--preset", "paper-sim", "--out", str(tmp_path / "m")])
    rep = json.loads((tmp_path / "m" / "modes.json").read_text())
    z = np.load(tmp_path / "m" / "modes.npz")
    np.testing.assert_allclose(z["frequency"], [r["frequency_hz"] for r in rep["modes"]])
    assert "frequency [Hz]" in (tmp_path / "m" / "modes.csv").read_text().splitlines()[0]
    _run(["stiffness", "--preset", "paper-sim", "--out", str(tmp_path / "s")])
    s = np.load(tmp_path / "s" / "stiffness.npz")
    rep = json.loads((tmp_path / "s" / "stiffness.json").read_text())
    np.testing.assert_allclose(s["k_sun_planet"], rep["curves"]["k_sun_planet"])
    assert "k_sun_planet [N/m]" in (tmp_path / "s" / "stiffness.csv").read_text()
