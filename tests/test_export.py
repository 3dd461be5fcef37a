"""Arrays out (CSV/NPZ with named columns and units), Record.to_xarray / to_dataframe, channel
selection tokens."""

import numpy as np
import pytest

from dtwin.io.export import columns_dataframe, read_columns_csv, write_columns, write_grid
from dtwin.io.output import OutputFolder
from dtwin.io.record import Record


def _folder(tmp_path):
    return OutputFolder(tmp_path / "out", command=["test"])


def test_columns_round_trip_csv_and_npz(tmp_path):
    f = np.linspace(0.0, 10.0, 11)
    a = np.sqrt(2.0) * f  # full precision must survive the CSV
    folder = _folder(tmp_path)
    csv, npz = write_columns(folder, "spectrum", {"frequency": f, "amplitude": a},
                             {"frequency": "Hz", "amplitude": "m/s^2"})
    header = csv.read_text().splitlines()[0]
    assert header == "frequency [Hz],amplitude [m/s^2]"
    cols, u = read_columns_csv(csv)
    np.testing.assert_array_equal(cols["amplitude"], a)
    assert u == {"frequency": "Hz", "amplitude": "m/s^2"}
    with np.load(npz) as z:  # no pickle needed
        np.testing.assert_array_equal(z["frequency"], f)
        assert list(z["units"]) == ["Hz", "m/s^2"] and list(z["columns"]) == ["frequency", "amplitude"]
    pd = pytest.importorskip("pandas")
    df = pd.read_csv(csv)
    assert list(df.columns) == ["frequency [Hz]", "amplitude [m/s^2]"]
    np.testing.assert_array_equal(df["amplitude [m/s^2]"].to_numpy(), a)
    assert {"spectrum.csv", "spectrum.npz"} <= set(folder.manifest["files"])


def test_grid_long_form(tmp_path):
    x, y = np.array([1.0, 2.0, 3.0]), np.array([10.0, 20.0])
    z = np.arange(6.0).reshape(2, 3)
    csv, npz = write_grid(_folder(tmp_path), "map", ("rpm", x, "1/min"), ("order", y, "1"),
                          ("amplitude", z, "m/s^2"))
    cols, _ = read_columns_csv(csv)
    assert cols["amplitude"].size == 6
    # the cell (order 20, rpm 2) is z[1, 1]
    i = np.flatnonzero((cols["rpm"] == 2.0) & (cols["order"] == 20.0))[0]
    assert cols["amplitude"][i] == z[1, 1]
    with np.load(npz) as g:
        np.testing.assert_array_equal(g["amplitude"], z)
    with pytest.raises(ValueError, match="shape"):
        write_grid(_folder(tmp_path / "b"), "bad", ("x", x, ""), ("y", y, ""), ("z", z.T, ""))


def _record():
    rng = np.random.default_rng(0)
    return Record(rng.normal(size=(3, 100)), 1000.0, ("acc_x", "acc_y", "acc_z"),
                  ("m/s^2", "m/s^2", "g"), tacho=np.sin(np.arange(100.0)), tacho_ppr=1,
                  tacho_shaft="sun", groups={"acc": ("acc_x", "acc_y", "acc_z")},
                  metadata={"machine": "m1"})


def test_record_to_xarray():
    pytest.importorskip("xarray")
    r = _record()
    da = r.to_xarray()
    assert da.dims == ("channel", "time")
    np.testing.assert_array_equal(da.sel(channel="acc_y").values, r.data[1])
    assert da.coords["unit"].sel(channel="acc_z").item() == "g"
    assert da.time.values[1] == pytest.approx(1e-3)  # 1 / sample rate
    np.testing.assert_array_equal(da.coords["tacho"].values, r.tacho)
    assert da.attrs["sample_rate_hz"] == 1000.0 and da.attrs["metadata"]["machine"] == "m1"


def test_record_to_dataframe():
    pytest.importorskip("pandas")
    r = _record()
    df = r.to_dataframe()
    assert list(df.columns) == ["acc_x", "acc_y", "acc_z", "tacho"]
    np.testing.assert_array_equal(df["acc_x"].to_numpy(), r.data[0])
    assert df.attrs["units"]["acc_z"] == "g" and df.index.name == "time"
    d2 = columns_dataframe({"f": [1.0, 2.0]}, {"f": "Hz"})
    assert d2.attrs["units"] == {"f": "Hz"}


def test_channel_tokens():
    r = _record()
    assert r.channel_list("all") == [0, 1, 2]
    assert r.channel_list("acc") == [0, 1, 2]  # a triaxial group
    assert r.channel_list("acc_z,0") == [2, 0]
    assert r.channel_list(1) == [1]


def test_pandas_and_xarray_are_declared():
    # `fleet table`'s Parquet opens with to_pandas() wherever the fleet extra is installed;
    # the test extra brings pandas and xarray (Record.to_xarray)
    import re
    from importlib.metadata import requires

    reqs = requires("dtwin") or []

    def extra(name):
        return {re.split(r"[<>=;\[ ]", r)[0].lower() for r in reqs
                if re.search(rf"extra\s*==\s*['\"]{name}['\"]", r)}

    assert "pandas" in extra("fleet") and "pyarrow" in extra("fleet")
    assert {"pandas", "xarray"} <= extra("test")


def test_parquet_table_opens_in_pandas(tmp_path):
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    pytest.importorskip("pandas")
    import datetime as dt

    # the fleet table's column types (identify/fleet/table.py): UTC timestamps, floats, strings
    t = pa.table({"timestamp": pa.array([dt.datetime(2026, 2, 1, tzinfo=dt.UTC)],
                                        type=pa.timestamp("us", tz="UTC")),
                  "sun_fault": pa.array([0.3]), "machine": pa.array(["m0"])})
    pq.write_table(t, tmp_path / "table.parquet")
    df = pq.read_table(tmp_path / "table.parquet").to_pandas()
    assert df["sun_fault"].iloc[0] == 0.3 and str(df["timestamp"].dt.tz) == "UTC"


@pytest.mark.parametrize("chunk", [7, 1 << 16])
def test_csv_cells_are_the_shortest_round_trip_text_of_each_value(chunk, monkeypatch):
    """Columns are written many rows at once; each cell must still read ``repr`` of the value as a
    Python float (float32 values widened exactly), ``str`` of an integer, and parse back bit
    for bit, over magnitudes from subnormal to huge and the special values."""
    from dtwin.io import export
    from dtwin.io.export import columns_csv

    monkeypatch.setattr(export, "_CHUNK", chunk)  # rows formatted at once: 7 crosses chunks
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.standard_normal(500) * 10.0 ** rng.integers(-300, 300, 500),
                        [0.0, -0.0, np.nan, np.inf, -np.inf, 1e16, 1e-5, 5e-324]])
    x32 = rng.standard_normal(x.size).astype(np.float32)
    k = rng.integers(-10**12, 10**12, x.size)
    text = columns_csv({"x": x, "x32": x32, "k": k}, {"x": "m", "x32": "m", "k": None})
    lines = text.splitlines()
    assert lines[0] == "x [m],x32 [m],k [1]"
    expected = [f"{float(a)!r},{float(b)!r},{int(c)}" for a, b, c in zip(x, x32, k, strict=True)]
    assert lines[1:] == expected
    back = np.array([[float(c) for c in line.split(",")] for line in lines[1:]])
    np.testing.assert_array_equal(back[:, 0], x)
    np.testing.assert_array_equal(back[:, 1], x32.astype(np.float64))
