"""``dtwin record info`` and ``dtwin record convert`` on small files written by numpy/csv.

The numbers in the report are compared with numpy computed on the written arrays; the rate and
duration checks with the paper's bench (f_sun = 29.7 Hz and the tooth counts of its preset, with
f_carrier = f_sun Zs/(Zs + Zr), f_mesh = f_carrier Zr, docs/references.md §1).
"""

from __future__ import annotations

import hashlib
import json
import tomllib

import numpy as np
import pytest

from dtwin.cli import main
from dtwin.io.readers import read_record
from dtwin.io.validate import MIN_CARRIER_PERIODS

FS = 5000.0


@pytest.fixture()
def csv_file(tmp_path):
    t = np.arange(2000) / FS
    x = np.sin(2 * np.pi * 499.0 * t)
    volts = 0.1 * np.stack([x, 0.5 * x, -x])  # 100 mV/g sensor → 1 g amplitude
    tach = (np.sin(2 * np.pi * 29.7 * t) > 0).astype(float)
    path = tmp_path / "bench.csv"
    np.savetxt(path, np.column_stack([t, volts.T, tach]), delimiter=",",
               header="time [s],acc_x [V],acc_y [V],acc_z [V],tach [V]", comments="")
    return path, volts, tach


def test_info_json(csv_file, capsys):
    path, volts, _ = csv_file
    main(["record", "info", str(path), "--tacho", "tach", "--tacho-ppr", "1", "--tacho-shaft",
          "sun", "--sensitivity", "acc=100 mV/g", "--preset", "paper-bench", "--json"])
    rep = json.loads(capsys.readouterr().out)
    assert rep["sample_rate_hz"] == pytest.approx(FS, rel=1e-12)
    assert rep["duration_s"] == pytest.approx(2000 / FS)
    assert [c["name"] for c in rep["channels"]] == ["acc_x", "acc_y", "acc_z"]
    assert [c["unit"] for c in rep["channels"]] == ["g", "g", "g"]
    g = volts / 0.1
    for c, row in zip(rep["channels"], g, strict=True):
        assert c["rms"] == pytest.approx(float(np.sqrt(np.mean(row**2))), rel=1e-12)
        assert c["max"] == pytest.approx(float(row.max()), rel=1e-12)
    assert rep["groups"] == {"acc": ["acc_x", "acc_y", "acc_z"]}
    assert rep["tacho"] == {"channel": "tach", "ppr": 1, "shaft": "sun"}
    from dtwin.spec import SPECS_DIR

    gears = tomllib.loads((SPECS_DIR / "paper-bench.toml").read_text())["gears"]
    f_carrier = 29.7 * gears["z_sun"] / (gears["z_sun"] + gears["z_ring"])
    assert rep["frequencies_hz"]["f_carrier"] == pytest.approx(f_carrier)
    assert rep["frequencies_hz"]["f_mesh"] == pytest.approx(f_carrier * gears["z_ring"])
    # 0.4 s is shorter than MIN_CARRIER_PERIODS carrier periods: the one problem, with the
    # length needed
    (p,) = rep["problems"]
    assert p["kind"] == "too_short" and p["value"] == pytest.approx(MIN_CARRIER_PERIODS / f_carrier)


def test_info_strict_exit_code_and_table(csv_file, capsys):
    path, _, _ = csv_file
    # fine at 5 kHz: exit 0 (the tacho, a square wave, is not a signal to check for clipping)
    main(["record", "info", str(path), "--f-mesh", "1000", "--tacho", "tach"])
    assert "no problems found" in capsys.readouterr().out
    with pytest.raises(SystemExit) as ex:
        main(["record", "info", str(path), "--f-mesh", "2400", "--strict"])
    assert ex.value.code == 2
    out = capsys.readouterr().out
    assert "6000 Hz" in out and "acc_x" in out


def test_info_out_folder_and_bad_options(csv_file, tmp_path, capsys):
    path, _, _ = csv_file
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    main(["record", "info", str(path), "--json", "--out", str(tmp_path / "res")])
    man = json.loads((tmp_path / "res" / "manifest.json").read_text())
    assert man["inputs"][str(path)]["sha256"] == digest and man["files"] == ["record_info.json"]
    capsys.readouterr()
    with pytest.raises(SystemExit) as ex:  # existing result, no --force
        main(["record", "info", str(path), "--out", str(tmp_path / "res")])
    assert ex.value.code == 2
    with pytest.raises(SystemExit) as ex:
        main(["record", "info", str(path), "--channels", "acc_w"])
    assert ex.value.code == 2
    assert "acc_w" in capsys.readouterr().err
    main(["record", "info", str(path), "--json", "--channels", "acc_x",
          "--sensitivity", "acc_x=100 mV/g -> m/s^2"])
    rep = json.loads(capsys.readouterr().out)
    x = np.loadtxt(path, delimiter=",", skiprows=1)[:, 1]
    assert rep["channels"][0]["unit"] == "m/s^2"
    assert rep["channels"][0]["max"] == pytest.approx(x.max() / 0.1 * 9.80665, rel=1e-12)
    with pytest.raises(SystemExit) as ex:
        main(["record", "info", str(path), "--sensitivity", "acc=lots"])
    assert ex.value.code == 2
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest


def test_convert_to_native(csv_file, tmp_path):
    path, volts, tach = csv_file
    target = tmp_path / "bench.dtwin.h5"
    main(["record", "convert", str(path), str(target), "--channels", "acc_x,2", "--tacho", "tach"])
    rec = read_record(target)
    assert rec.channels == ("acc_x", "acc_z") and rec.units == ("V", "V")
    np.testing.assert_allclose(rec.data, volts[[0, 2]], rtol=1e-15, atol=0)
    np.testing.assert_array_equal(rec.tacho, tach)
    assert rec.metadata["source_sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    with pytest.raises(SystemExit) as ex:
        main(["record", "convert", str(path), str(target)])
    assert ex.value.code == 2
