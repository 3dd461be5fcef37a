"""Every record format read from files written by that format's own tools.

Values, rate, channel names and units are compared with what was written: exactly where the
format stores float64, within the format's quantisation or printed precision otherwise.
"""

from __future__ import annotations

import csv
import wave

import h5py
import numpy as np
import pytest
import scipy.io
from scipy.io import wavfile

from dtwin.errors import ChannelError, OutputExistsError, RecordError, UnreadableFileError
from dtwin.io.readers import STANDARD_GRAVITY, read_record, write_record
from dtwin.io.record import Record

FS = 5000.0
N = 400


@pytest.fixture(scope="module")
def signals():
    rng = np.random.default_rng(4)
    t = np.arange(N) / FS
    x = 0.6 * np.sin(2 * np.pi * 497.0 * t) + 0.05 * rng.standard_normal(N)
    y = 0.4 * np.cos(2 * np.pi * 150.0 * t)
    z = -0.3 * np.sin(2 * np.pi * 61.0 * t + 0.4)
    return t, np.stack([x, y, z])


# ------------------------------------------------------------------------------------- WAV


def _write_wave_int(path, codes, sampwidth, rate):
    """Write integer PCM with the standard library's ``wave`` module (independent of scipy)."""
    codes = np.asarray(codes, dtype=np.int64)
    n, nch = codes.shape
    if sampwidth == 1:
        raw = (codes + 128).astype(np.uint8).tobytes()
    else:
        u = np.ascontiguousarray(codes, dtype="<i8").view(np.uint8).reshape(n, nch, 8)[:, :, :sampwidth]
        raw = u.tobytes()
    with wave.open(str(path), "wb") as w:
        w.setnchannels(nch)
        w.setsampwidth(sampwidth)
        w.setframerate(int(rate))
        w.writeframes(raw)


@pytest.mark.parametrize("bits", [8, 16, 24, 32])
def test_wav_integer_pcm_written_by_wave_module(tmp_path, signals, bits):
    _, sig = signals
    full = 2 ** (bits - 1)
    codes = np.clip(np.round(sig[:2].T * full), -full, full - 1).astype(np.int64)
    path = tmp_path / f"rec{bits}.wav"
    _write_wave_int(path, codes, bits // 8, FS)
    rec = read_record(path)
    assert rec.sample_rate == FS
    assert rec.channels == ("ch0", "ch1")
    assert rec.metadata["bits_per_sample"] == bits
    # exact: code / 2^(b-1) is a float64 without rounding for b <= 32
    np.testing.assert_array_equal(rec.data, codes.T / full)
    # and within one quantisation step of the analogue signal written
    assert np.max(np.abs(rec.data - sig[:2])) <= 1.0 / full


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_wav_float_pcm_written_by_scipy(tmp_path, signals, dtype):
    _, sig = signals
    path = tmp_path / "float.wav"
    wavfile.write(path, int(FS), sig.T.astype(dtype))
    rec = read_record(path)
    assert rec.sample_rate == FS and rec.data.shape == (3, N)
    assert rec.metadata["format_tag"] == "IEEE float"
    np.testing.assert_array_equal(rec.data, sig.astype(dtype).astype(np.float64))


def test_wav_sensitivity_with_full_scale(tmp_path, signals):
    """A 16-bit recorder with 5 V full scale and a 100 mV/g sensor: g = x·5 V / 0.1 V/g."""
    _, sig = signals
    codes = np.round(sig[:1].T * 32768).astype(np.int64)
    path = tmp_path / "acc.wav"
    _write_wave_int(path, codes, 2, FS)
    rec = read_record(path, sensitivity={"ch0": (100.0 / 5.0, "mV/g")})
    np.testing.assert_allclose(rec.data[0], codes[:, 0] / 32768 * 5.0 / 0.1, rtol=1e-15)
    assert rec.units == ("g",)
    assert rec.metadata["sensitivity"]["ch0"]["volts_per_unit"] == pytest.approx(0.02)


# ------------------------------------------------------------------------------- CSV / TSV


def test_csv_header_units_time_column(tmp_path, signals):
    t, sig = signals
    path = tmp_path / "rec.csv"
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time [ms]", "acc1_x [m/s²]", "acc1_y [m/s^2]", "acc1_z [m/s^2]", "tach [V]"])
        tach = (np.sin(2 * np.pi * 29.7 * t) > 0).astype(float)
        for k in range(N):
            w.writerow([repr(float(1e3 * t[k]))] + [repr(float(v)) for v in sig[:, k]]
                       + [repr(float(tach[k]))])
    rec = read_record(path, tacho="tach", tacho_ppr=1, tacho_shaft="sun")
    assert rec.sample_rate == pytest.approx(FS, rel=1e-12)
    assert rec.channels == ("acc1_x", "acc1_y", "acc1_z")
    assert rec.units == ("m/s^2",) * 3
    assert rec.groups == {"acc1": ("acc1_x", "acc1_y", "acc1_z")}
    np.testing.assert_array_equal(rec.data, sig)  # repr() round-trips float64 exactly
    np.testing.assert_array_equal(rec.tacho, tach)
    assert rec.tacho_ppr == 1 and rec.tacho_shaft == "sun"
    # a group selected by its name, sensitivity applied to the group, converted to m/s^2
    acc = read_record(path, channels=["acc1"], units="mV",
                      sensitivity={"acc1": (10.0 * STANDARD_GRAVITY, "mV/g")})
    np.testing.assert_allclose(acc.data, sig / (10.0 * STANDARD_GRAVITY), rtol=1e-15)
    assert acc.units == ("g",) * 3


def test_tsv_without_time_column_needs_rate(tmp_path, signals):
    _, sig = signals
    path = tmp_path / "rec.tsv"
    np.savetxt(path, sig.T, delimiter="\t", header="a\tb\tc", comments="")
    with pytest.raises(RecordError, match="sample_rate"):
        read_record(path)
    rec = read_record(path, sample_rate=FS, channels=[2, "a"])
    assert rec.channels == ("c", "a") and rec.sample_rate == FS
    np.testing.assert_allclose(rec.data, sig[[2, 0]], rtol=1e-15, atol=0)


def test_txt_whitespace_no_header(tmp_path, signals):
    _, sig = signals
    path = tmp_path / "rec.txt"
    np.savetxt(path, sig.T, fmt="%.17g")
    rec = read_record(path, sample_rate=FS, units=["g", "g", "V"])
    assert rec.channels == ("ch0", "ch1", "ch2") and rec.units == ("g", "g", "V")
    np.testing.assert_array_equal(rec.data, sig)


# ---------------------------------------------------------------------------------- NumPy


def test_npy_channels_on_the_short_axis(tmp_path, signals):
    _, sig = signals
    np.save(tmp_path / "rec.npy", sig.T)  # (samples, channels) as DAQ software saves it
    rec = read_record(tmp_path / "rec.npy", sample_rate=FS)
    np.testing.assert_array_equal(rec.data, sig)


def test_npz_named_arrays_and_data_matrix(tmp_path, signals):
    t, sig = signals
    np.savez(tmp_path / "a.npz", acc=sig[0], mic=sig[1], sample_rate=FS)
    rec = read_record(tmp_path / "a.npz")
    assert rec.channels == ("acc", "mic") and rec.sample_rate == FS
    np.testing.assert_array_equal(rec.data, sig[:2])
    np.savez_compressed(tmp_path / "b.npz", data=sig, channels=np.array(["x", "y", "z"]),
                        units=np.array(["g", "g", "g"]), time=t)
    rec = read_record(tmp_path / "b.npz")
    assert rec.channels == ("x", "y", "z") and rec.units == ("g",) * 3
    assert rec.sample_rate == pytest.approx(FS, rel=1e-12)
    np.testing.assert_array_equal(rec.data, sig)


# --------------------------------------------------------------------------------- MATLAB


def test_matlab_v5_written_by_savemat(tmp_path, signals):
    _, sig = signals
    path = tmp_path / "bench.mat"
    scipy.io.savemat(path, {"fs": FS, "acc1": sig.T, "tach": sig[0][:, None].copy()})
    rec = read_record(path, channels=["acc1"], tacho="tach")
    assert rec.sample_rate == FS
    assert rec.channels == ("acc1_x", "acc1_y", "acc1_z")
    np.testing.assert_array_equal(rec.data, sig)
    np.testing.assert_array_equal(rec.tacho, sig[0])
    # a struct selected with group=, cell array of names
    scipy.io.savemat(path, {"rec": {"Fs": FS, "data": sig.T,
                                    "channels": np.array(["u", "v", "w"], dtype=object)}})
    rec = read_record(path, group="rec")
    assert rec.channels == ("u", "v", "w") and rec.sample_rate == FS
    np.testing.assert_array_equal(rec.data, sig)


def _write_mat73(path, variables):
    """Write a MATLAB v7.3 file the way MATLAB lays it out: 512-byte text header (userblock),
    datasets transposed (column-major), ``MATLAB_class`` attributes, chars as uint16 codes and
    cell arrays as object references into ``#refs#``."""
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Sat Nov 21 10:00:00 2026 HDF5 schema 1.00 ."
    with h5py.File(path, "w", userblock_size=512) as f:
        refs = f.create_group("#refs#")
        for name, value in variables.items():
            if isinstance(value, list):  # cell array of char (1 x n)
                ref_list = []
                for k, s in enumerate(value):
                    ds = refs.create_dataset(f"{name}{k}", data=np.array(
                        [[ord(c)] for c in s], dtype=np.uint16))
                    ds.attrs["MATLAB_class"] = np.bytes_("char")
                    ds.attrs["MATLAB_int_decode"] = np.int32(2)
                    ref_list.append(ds.ref)
                ds = f.create_dataset(name, data=np.array(ref_list, dtype=h5py.ref_dtype)[:, None])
                ds.attrs["MATLAB_class"] = np.bytes_("cell")
            else:
                arr = np.atleast_2d(np.asarray(value, dtype=np.float64))
                ds = f.create_dataset(name, data=arr.T)  # MATLAB m x n → HDF5 (n, m)
                ds.attrs["MATLAB_class"] = np.bytes_("double")
    with open(path, "r+b") as f:
        f.write(header.ljust(128, b" "))


def test_matlab_v73_in_matlab_hdf5_layout(tmp_path, signals):
    t, sig = signals
    path = tmp_path / "bench73.mat"
    # MATLAB: data is N x 3 (samples down the columns), t an N x 1 column, fs a scalar
    _write_mat73(path, {"data": sig.T, "t": t[:, None], "fs": FS,
                        "channels": ["acc_x", "acc_y", "acc_z"]})
    with open(path, "rb") as f:
        assert f.read(19) == b"MATLAB 7.3 MAT-file"
    rec = read_record(path)
    assert rec.metadata["matlab_version"] == "7.3"
    assert rec.channels == ("acc_x", "acc_y", "acc_z")
    assert rec.sample_rate == FS
    np.testing.assert_array_equal(rec.data, sig)
    assert rec.groups == {"acc": ("acc_x", "acc_y", "acc_z")}


# ----------------------------------------------------------------------------------- HDF5


def test_hdf5_datasets_with_attributes(tmp_path, signals):
    _, sig = signals
    path = tmp_path / "rec.h5"
    with h5py.File(path, "w") as f:
        g = f.create_group("run1")
        g.attrs["sample_rate"] = FS
        for name, row in zip(("ax", "ay"), sig[:2], strict=True):
            g.create_dataset(name, data=row.astype(np.float32))
            g[name].attrs["units"] = "m/s^2"
    rec = read_record(path)
    assert rec.channels == ("ax", "ay") and rec.units == ("m/s^2", "m/s^2")
    assert rec.sample_rate == FS
    np.testing.assert_array_equal(rec.data, sig[:2].astype(np.float32))
    with pytest.raises(RecordError, match="group"):
        read_record(path, group="run2")
    # a (samples, channels) matrix with names and units as attributes, the rate as a dataset
    with h5py.File(tmp_path / "m.hdf5", "w") as f:
        f["data"] = sig.T
        f["data"].attrs["channels"] = ["u", "v", "w"]
        f["data"].attrs["units"] = ["g", "g", "V"]
        f["fs"] = FS
    rec = read_record(tmp_path / "m.hdf5")
    assert rec.channels == ("u", "v", "w") and rec.units == ("g", "g", "V")
    assert rec.sample_rate == FS
    np.testing.assert_array_equal(rec.data, sig)


# ----------------------------------------------------------------------------------- TDMS


def test_tdms_written_by_nptdms(tmp_path, signals):
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    _, sig = signals
    path = tmp_path / "bench.tdms"
    with TdmsWriter(path) as w:
        w.write_segment([
            RootObject(properties={"operator": "bench"}),
            GroupObject("Vibration"),
            *[ChannelObject("Vibration", f"acc1_{a}", sig[i],
                            properties={"wf_increment": 1.0 / FS, "unit_string": "g"})
              for i, a in enumerate("xyz")],
            ChannelObject("Vibration", "stamp", np.datetime64("2026-11-21T10:00:00", "us")
                          + np.arange(N) * np.timedelta64(200, "us")),
            ChannelObject("Speed", "tacho", sig[0].astype(np.float32),
                          properties={"wf_increment": 1.0 / FS, "unit_string": "V"}),
        ])
    rec = read_record(path, group="Vibration")
    assert rec.channels == ("acc1_x", "acc1_y", "acc1_z") and rec.units == ("g",) * 3
    assert rec.sample_rate == pytest.approx(FS, rel=1e-15)
    np.testing.assert_array_equal(rec.data, sig)
    assert rec.metadata["tdms_properties"]["operator"] == "bench"
    assert rec.metadata["skipped_channels"] == ["stamp"]  # timestamps are not a signal
    both = read_record(path, tacho="tacho", channels=["acc1_x"])
    np.testing.assert_array_equal(both.tacho, sig[0].astype(np.float32))
    with pytest.raises(RecordError, match="Vibration"):
        read_record(path, group="Nope")


# ------------------------------------------------------------------------------------ UFF


def _uff58(name, data, node, direction, binary):
    import pyuff

    t = np.arange(data.size) / FS
    return pyuff.prepare_58(
        binary=binary, id1=name, func_type=1, rsp_node=node, rsp_dir=direction, ref_node=0,
        ref_dir=0, data=data, x=t, abscissa_spacing=1, abscissa_spec_data_type=17,
        ordinate_spec_data_type=12, orddenom_spec_data_type=0,
        ordinate_axis_units_lab="m/s^2", abscissa_axis_units_lab="s")


def test_uff58_written_by_pyuff(tmp_path, signals):
    import pyuff

    _, sig = signals
    path = tmp_path / "bench.uff"
    # ASCII sets (pyuff 2.5's binary 58b writer leaves an empty block, so it is not used)
    sets = [_uff58(f"acc1_{a}", sig[i], 1, i + 1, 0) for i, a in enumerate("xyz")]
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
    rec = read_record(path)
    assert rec.channels == ("acc1_x", "acc1_y", "acc1_z")
    assert rec.units == ("m/s^2",) * 3
    # the increment is printed with 13 characters (E13.5) in the ASCII header
    assert rec.sample_rate == pytest.approx(FS, rel=1e-5)
    # ASCII data: E20.12, 12 significant digits: relative rounding error ≤ 5e-12
    np.testing.assert_allclose(rec.data, sig, rtol=5e-12, atol=0)


# --------------------------------------------------------------------- our own format


def test_native_roundtrip_atomic_no_overwrite(tmp_path, signals):
    _, sig = signals
    rec = Record(data=sig, sample_rate=FS, channels=("acc1_x", "acc1_y", "acc/odd name"),
                 units=("m/s^2", "m/s^2", "V"), tacho=sig[0] > 0, tacho_ppr=2,
                 tacho_shaft="carrier", groups={"acc1": ("acc1_x", "acc1_y")},
                 metadata={"seed": 3, "spec": {"Zs": 28}, "source": "twin"})
    path = tmp_path / "sim.dtwin.h5"
    write_record(rec, path)
    back = read_record(path)
    np.testing.assert_array_equal(back.data, rec.data)
    np.testing.assert_array_equal(back.tacho, rec.tacho.astype(float))
    assert (back.channels, back.units, back.sample_rate) == (rec.channels, rec.units, FS)
    assert (back.tacho_ppr, back.tacho_shaft) == (2, "carrier")
    assert back.groups == {"acc1": ("acc1_x", "acc1_y")}
    assert back.metadata["seed"] == 3 and back.metadata["spec"] == {"Zs": 28}
    assert back.metadata["derived_from"]["source"] == "twin"
    # any HDF5 tool reads it: datasets per channel, attributes
    with h5py.File(path, "r") as f:
        assert f.attrs["dtwin_format"] == "dtwin-record" and f.attrs["format_version"] == 1
        np.testing.assert_array_equal(f["channels/002"][()], sig[2])
        assert f["channels/002"].attrs["name"] == "acc/odd name"
    before = path.read_bytes()
    with pytest.raises(OutputExistsError, match="force"):
        write_record(rec, path)
    assert path.read_bytes() == before
    write_record(dataclasses_replace(rec, sample_rate=2 * FS), path, force=True)
    assert read_record(path).sample_rate == 2 * FS
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sim.dtwin.h5"]  # no temporaries


def dataclasses_replace(rec, **kw):
    import dataclasses

    return dataclasses.replace(rec, **kw)


# ------------------------------------------------------------------ errors at the boundary


def test_boundary_errors(tmp_path, signals):
    _, sig = signals
    np.savez(tmp_path / "a.npz", acc=sig[0], sample_rate=FS)
    with pytest.raises(ChannelError, match="acc"):
        read_record(tmp_path / "a.npz", channels=["acx"])
    with pytest.raises(UnreadableFileError, match="no such file"):
        read_record(tmp_path / "missing.csv")
    (tmp_path / "a.xyz").write_bytes(b"1,2\n")
    with pytest.raises(UnreadableFileError, match="extension"):
        read_record(tmp_path / "a.xyz")
    with pytest.raises(RecordError, match="mV/g"):
        read_record(tmp_path / "a.npz", sensitivity={"acc": (100.0, "mV per g")})
    with pytest.raises(RecordError, match="tacho_shaft"):
        read_record(tmp_path / "a.npz", tacho_shaft="planet")
    np.savez(tmp_path / "g.npz", acc=sig[0], sample_rate=FS)
    rec = read_record(tmp_path / "g.npz", units="g")
    with pytest.raises(RecordError, match="already in 'g'"):
        read_record(tmp_path / "g.npz", units="g", sensitivity={"acc": (100.0, "mV/g")})
    assert rec.units == ("g",)


def test_sensitivity_to_si(tmp_path, signals):
    """10.2 mV/(m/s²) on a channel stored in mV: a = v[mV] / 10.2."""
    _, sig = signals
    np.savez(tmp_path / "v.npz", acc=sig[0], sample_rate=FS)
    rec = read_record(tmp_path / "v.npz", units={"acc": "mV"},
                      sensitivity={"acc": (10.2, "mV/(m/s²)")})
    np.testing.assert_allclose(rec.data[0], sig[0] / 10.2, rtol=1e-15)
    assert rec.units == ("m/s^2",)
    # a datasheet in mV/g, results wanted in m/s^2: a = v / 0.1 V/g * 9.80665 (m/s^2)/g
    rec = read_record(tmp_path / "v.npz", sensitivity={"acc": (100.0, "mV/g", "m/s²")})
    np.testing.assert_allclose(rec.data[0], sig[0] / 0.1 * 9.80665, rtol=1e-14)
    assert rec.units == ("m/s^2",)
    assert rec.metadata["sensitivity"]["acc"]["input_unit"].startswith("V (assumed")
    with pytest.raises(RecordError, match="acceleration"):
        read_record(tmp_path / "v.npz", sensitivity={"acc": (100.0, "mV/g", "mm/s")})
    with pytest.raises(RecordError, match="keys"):
        read_record(tmp_path / "v.npz", sensitivity={1.5: (100.0, "mV/g")})
