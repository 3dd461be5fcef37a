"""Result folders: atomic writes, no overwriting without force, manifests; failures half-way
leave no partial output and the inputs untouched (checked by SHA-256 computed with hashlib)."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from dtwin.errors import OutputExistsError
from dtwin.io import fmt_native
from dtwin.io.output import OutputFolder, atomic_write_bytes, sha256_file
from dtwin.io.readers import read_record, write_record
from dtwin.io.record import Record


class WriterFailed(RuntimeError):
    """Raised by the test writers half-way through a file."""


def _input(tmp_path):
    path = tmp_path / "input.csv"
    t = np.arange(100) / 1000.0
    np.savetxt(path, np.column_stack([t, np.sin(2 * np.pi * 50 * t)]), delimiter=",",
               header="time,acc", comments="")
    return path, hashlib.sha256(path.read_bytes()).hexdigest()


def test_sha256_matches_hashlib(tmp_path):
    path, digest = _input(tmp_path)
    assert sha256_file(path) == digest
    assert sha256_file(path, chunk=7) == digest  # chunked reading gives the same digest


def test_manifest_lists_inputs_files_and_versions(tmp_path):
    path, digest = _input(tmp_path)
    out = OutputFolder(tmp_path / "out", inputs=[path], spec={"gears": {"z_sun": 13}}, seed=7,
                       command=["dtwin", "record", "info"], parameters={"f_mesh": np.float64(5)})
    out.write_json("a.json", {"x": np.arange(3), "nan": float("nan")})
    man = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert man["inputs"][str(path)] == {"sha256": digest, "bytes": path.stat().st_size}
    assert man["files"] == ["a.json"] and man["seed"] == 7
    assert man["spec"] == {"gears": {"z_sun": 13}} and man["parameters"] == {"f_mesh": 5.0}
    assert {"numpy", "jax", "diffrax", "dtwin"} <= set(man["versions"])
    assert json.loads((tmp_path / "out" / "a.json").read_text()) == {"x": [0, 1, 2],
                                                                     "nan": "nan"}


def test_refuses_to_overwrite_without_force(tmp_path):
    out = OutputFolder(tmp_path / "out")
    out.write_text("r.txt", "first")
    with pytest.raises(OutputExistsError, match="force"):
        out.write_text("r.txt", "second")
    assert (tmp_path / "out" / "r.txt").read_text() == "first"
    with pytest.raises(OutputExistsError, match="--force"):
        OutputFolder(tmp_path / "out")  # a folder holding a result (manifest.json)
    again = OutputFolder(tmp_path / "out", force=True)
    again.write_text("r.txt", "second")
    assert (tmp_path / "out" / "r.txt").read_text() == "second"
    with pytest.raises(OutputExistsError):
        atomic_write_bytes(tmp_path / "out" / "r.txt", b"third")


def test_failure_inside_a_writer_leaves_nothing_and_input_untouched(tmp_path):
    """Read an input, write one result, then fail half-way through a record file."""
    path, digest = _input(tmp_path)
    out = OutputFolder(tmp_path / "out", inputs=[path])
    rec = read_record(path)
    out.write_json("summary.json", {"rms": float(np.sqrt(np.mean(rec.data**2)))})

    def half_then_fail(tmp):
        with open(tmp, "wb") as f:
            f.write(b"\x89HDF\r\n\x1a\n" + b"\0" * 1000)  # a partial file ...
        raise WriterFailed("disk full")  # ... then the writer dies

    with pytest.raises(WriterFailed):
        out.write_with("result.dtwin.h5", half_then_fail)
    names = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert names == ["manifest.json", "summary.json"]  # no partial file, no temporary
    man = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert man["files"] == ["summary.json"]
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest


def test_failure_inside_the_record_writer(tmp_path, monkeypatch):
    """The native record writer fails after creating its datasets: no file appears, an existing
    result stays as it was even with force=True."""
    rec = Record(data=np.ones((2, 10)), sample_rate=100.0, channels=("a", "b"), units=("", ""))
    target = tmp_path / "sim.dtwin.h5"
    fmt_native.write(rec, target)
    before = hashlib.sha256(target.read_bytes()).hexdigest()
    real = fmt_native.write_into

    def failing(record, p):
        real(record, p)
        raise WriterFailed("killed after writing")

    monkeypatch.setattr(fmt_native, "write_into", failing)
    with pytest.raises(WriterFailed):
        fmt_native.write(rec, target, force=True)
    with pytest.raises(WriterFailed):
        fmt_native.write(rec, tmp_path / "new.dtwin.h5")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sim.dtwin.h5"]
    assert hashlib.sha256(target.read_bytes()).hexdigest() == before
    monkeypatch.undo()
    folder = OutputFolder(tmp_path / "out")
    folder.write_record("sim.dtwin.h5", rec)
    np.testing.assert_array_equal(read_record(tmp_path / "out" / "sim.dtwin.h5").data, rec.data)
    # the pattern `dtwin simulate` uses: our writer inside OutputFolder.write_with
    folder.write_with("b.dtwin.h5", lambda p: write_record(rec, p, force=True))
    np.testing.assert_array_equal(read_record(tmp_path / "out" / "b.dtwin.h5").data, rec.data)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        "b.dtwin.h5", "manifest.json", "sim.dtwin.h5"]
