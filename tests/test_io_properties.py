"""Property tests: malformed, truncated and random-byte files never crash the readers.

Whatever bytes a file holds, :func:`read_record` either returns a record or raises one of the
documented error classes (:mod:`dtwin.errors`) with a non-empty message; never a bare
exception of a library, never a hang (hypothesis deadline). Valid files of every format are
made by the format's own tools, then truncated or corrupted byte-wise.
"""

from __future__ import annotations

import io
import os
import tempfile
import wave
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dtwin.errors import ChannelError, RecordError, UnreadableFileError
from dtwin.io.readers import read_record, write_record
from dtwin.io.record import Record

DOCUMENTED = (RecordError, ChannelError, UnreadableFileError)
SETTINGS = settings(max_examples=int(os.environ.get("DTWIN_FUZZ_EXAMPLES", "30")), deadline=3000,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
FS = 1000.0
SIG = np.stack([np.sin(np.arange(64) * 0.3), np.cos(np.arange(64) * 0.2)])


def _valid_files() -> dict[str, bytes]:
    """One small valid file per format, as bytes, written by each format's own tool."""
    from nptdms import ChannelObject, TdmsWriter

    out: dict[str, bytes] = {}
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        buf = io.StringIO()
        np.savetxt(buf, np.column_stack([np.arange(64) / FS, SIG.T]), delimiter=",",
                   header="time,a,b", comments="")
        out[".csv"] = buf.getvalue().encode()
        out[".tsv"] = out[".csv"].replace(b",", b"\t")
        with wave.open(str(d / "a.wav"), "wb") as w:
            w.setnchannels(2)
            w.setsampwidth(3)
            w.setframerate(int(FS))
            w.writeframes(bytes(range(256)) * 3)
        out[".wav"] = (d / "a.wav").read_bytes()
        np.save(d / "a.npy", SIG)
        out[".npy"] = (d / "a.npy").read_bytes()
        np.savez(d / "a.npz", a=SIG[0], b=SIG[1], sample_rate=FS)
        out[".npz"] = (d / "a.npz").read_bytes()
        scipy.io.savemat(d / "a.mat", {"fs": FS, "data": SIG.T}, do_compression=True)
        out[".mat"] = (d / "a.mat").read_bytes()
        with h5py.File(d / "a.h5", "w") as f:
            f.attrs["sample_rate"] = FS
            f["a"] = SIG[0]
            f["b"] = SIG[1]
        out[".h5"] = (d / "a.h5").read_bytes()
        with h5py.File(d / "a73.mat", "w", userblock_size=512) as f:  # MATLAB v7.3 layout
            ds = f.create_dataset("data", data=SIG)  # MATLAB 64 x 2, stored transposed
            ds.attrs["MATLAB_class"] = np.bytes_("double")
            ds = f.create_dataset("fs", data=np.array([[FS]]))
            ds.attrs["MATLAB_class"] = np.bytes_("double")
            refs = f.create_group("#refs#")
            names = []
            for k, nm in enumerate(("a", "b")):
                r = refs.create_dataset(f"n{k}", data=np.array([[ord(nm)]], dtype=np.uint16))
                r.attrs["MATLAB_class"] = np.bytes_("char")
                names.append(r.ref)
            ds = f.create_dataset("channels", data=np.array(names, dtype=h5py.ref_dtype)[:, None])
            ds.attrs["MATLAB_class"] = np.bytes_("cell")
        with open(d / "a73.mat", "r+b") as f:
            f.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 .".ljust(128))
        out[".v73.mat"] = (d / "a73.mat").read_bytes()
        with TdmsWriter(d / "a.tdms") as w:
            w.write_segment([ChannelObject("g", "a", SIG[0], properties={"wf_increment": 1e-3})])
        out[".tdms"] = (d / "a.tdms").read_bytes()
        import pyuff

        ds = pyuff.prepare_58(binary=0, id1="a", func_type=1, rsp_node=1, rsp_dir=1,
                              ref_node=0, ref_dir=0, data=SIG[0], x=np.arange(64) / FS,
                              abscissa_spacing=1, abscissa_spec_data_type=17,
                              ordinate_spec_data_type=12, orddenom_spec_data_type=0)
        pyuff.UFF(str(d / "a.uff")).write_sets([ds], mode="overwrite")
        out[".uff"] = (d / "a.uff").read_bytes()
        write_record(Record(data=SIG, sample_rate=FS, channels=("a", "b"), units=("g", "g")),
                     d / "a.dtwin.h5")
        out[".dtwin.h5"] = (d / "a.dtwin.h5").read_bytes()
    return out


VALID = _valid_files()
EXTS = sorted(VALID)


def _read_bytes(ext: str, data: bytes, **kw):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / f"rec{ext}"
        path.write_bytes(data)
        try:
            rec = read_record(path, **kw)
        except DOCUMENTED as e:
            assert str(e).strip(), f"{type(e).__name__} without a message"
            return None
        assert path.read_bytes() == data  # the input is never altered
        return rec


def _assert_refused_or_well_formed(rec) -> None:
    """A reader either refused the bytes with a documented error (`_read_bytes` returns None) or
    returned a well-formed record: float64 (channels, samples), one name and unit per channel,
    a positive finite sampling rate."""
    if rec is None:
        return
    data = np.asarray(rec.data)
    assert data.ndim == 2 and data.dtype == np.float64, (data.shape, data.dtype)
    assert len(rec.channels) == data.shape[0] == len(rec.units)
    assert np.isfinite(rec.sample_rate) and rec.sample_rate > 0


@pytest.mark.parametrize("ext", EXTS)
def test_valid_files_read(ext):
    rec = _read_bytes(ext, VALID[ext], sample_rate=None if ext != ".npy" else FS)
    assert rec is not None and rec.n_samples > 0


@pytest.mark.parametrize("ext", EXTS)
@SETTINGS
@given(data=st.binary(max_size=2048))
def test_random_bytes_give_documented_errors(ext, data):
    _assert_refused_or_well_formed(_read_bytes(ext, data))


@pytest.mark.parametrize("ext", EXTS)
@SETTINGS
@given(cut=st.floats(0.0, 1.0, exclude_max=True))
def test_truncated_files_give_documented_errors(ext, cut):
    blob = VALID[ext]
    _assert_refused_or_well_formed(_read_bytes(ext, blob[: int(cut * len(blob))]))


@pytest.mark.parametrize("ext", EXTS)
@SETTINGS
@given(edits=st.lists(st.tuples(st.floats(0.0, 1.0, exclude_max=True),
                                st.integers(0, 255)), min_size=1, max_size=8))
def test_corrupted_files_give_documented_errors(ext, edits):
    blob = bytearray(VALID[ext])
    for where, value in edits:
        blob[int(where * len(blob))] = value
    _assert_refused_or_well_formed(_read_bytes(ext, bytes(blob)))


@SETTINGS
@given(text=st.text(alphabet=st.sampled_from(list("0123456789.,;-+eE \t\nnaifNAIF#[]()xyt")),
                    max_size=400))
def test_malformed_csv_text(text):
    _assert_refused_or_well_formed(_read_bytes(".csv", text.encode()))


@SETTINGS
@given(
    n_ch=st.integers(1, 4),
    n=st.integers(0, 50),
    seed=st.integers(0, 2**32 - 1),
    names=st.lists(st.text(min_size=1, max_size=10), min_size=4, max_size=4, unique=True),
    unit=st.text(max_size=6),
    rate=st.floats(1e-3, 1e7, allow_nan=False),
    meta=st.dictionaries(st.text(max_size=5), st.one_of(st.integers(-10**6, 10**6),
                                                        st.text(max_size=5)), max_size=3),
)
def test_native_roundtrip_is_exact(n_ch, n, seed, names, unit, rate, meta):
    """Whatever the values (NaN and inf included), names and units: written then read back
    bit for bit, or refused with a documented error."""
    rng = np.random.default_rng(seed)
    data = rng.standard_normal((n_ch, n)) * 10.0 ** rng.integers(-300, 300, size=(n_ch, 1))
    if n:
        data[0, rng.integers(n)] = rng.choice([np.nan, np.inf, -np.inf])
    rec = Record(data=data, sample_rate=rate, channels=names[:n_ch], units=[unit] * n_ch,
                 metadata=meta)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "r.dtwin.h5"
        try:
            write_record(rec, path)
        except RecordError as e:  # NUL characters in a name: refused, nothing written
            assert "NUL" in str(e) and not any(Path(d).iterdir())
            return
        back = read_record(path)
    np.testing.assert_array_equal(back.data, rec.data)
    assert back.channels == rec.channels and back.units == rec.units
    assert back.sample_rate == rate
    assert {k: back.metadata[k] for k in meta} == meta
