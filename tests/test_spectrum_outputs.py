"""`dtwin spectrum`'s outputs: arrays in CSV/NPZ with units, --units (g, mm/s by integration),
--welch against scipy.signal.welch, several channels of a triaxial sensor in one call, ISO 20816
evaluation, report.html."""

import json

import numpy as np
import pytest
import scipy.signal

from dtwin.cli import main
from dtwin.io.record import Record

FS, N = 5000.0, 20_000  # 4 s, 0.25 Hz bins


@pytest.fixture(scope="module")
def triax(tmp_path_factory):
    from dtwin.io.readers import write_record

    t = np.arange(N) / FS
    rng = np.random.default_rng(1)
    # 100 Hz tones of 2, 3 and 4 m/s² (x, y, z) in a little noise
    data = np.stack([a * np.sin(2 * np.pi * 100.0 * t) + 0.01 * rng.standard_normal(N)
                     for a in (2.0, 3.0, 4.0)])
    rec = Record(data, FS, ("acc_x", "acc_y", "acc_z"), ("m/s^2",) * 3,
                 groups={"acc": ("acc_x", "acc_y", "acc_z")})
    path = tmp_path_factory.mktemp("rec") / "triax.dtwin.h5"
    write_record(rec, path)
    return path, data


def _npz(path):
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def test_units_g_and_velocity(triax, tmp_path, capsys):
    path, _ = triax
    main(["spectrum", str(path), "--channel", "acc_x", "--units", "g", "--json",
          "--out", str(tmp_path / "g")])
    rep = json.loads(capsys.readouterr().out)
    assert rep["unit"] == "g"
    top = max(rep["peaks"], key=lambda p: p["amplitude"])
    assert top["frequency_hz"] == pytest.approx(100.0)
    assert top["amplitude"] == pytest.approx(2.0 / 9.80665, rel=1e-3)  # 1 g = 9.80665 m/s²
    main(["spectrum", str(path), "--channel", "acc_x", "--units", "mm/s", "--json"])
    rep = json.loads(capsys.readouterr().out)
    top = max(rep["peaks"], key=lambda p: p["amplitude"])
    # a / (2 pi f), behind the stated 10 Hz 4th-order high-pass (gain 1 - 5e-9 at 100 Hz)
    assert top["amplitude"] == pytest.approx(1e3 * 2.0 / (2 * np.pi * 100.0), rel=1e-3)
    assert rep["integration"]["highpass_hz"] == 10.0
    # ISO 20816: velocity RMS of the tone, 3.18 mm/s / sqrt 2 = 2.25 mm/s: zone B of group 2 rigid
    iso = rep["iso20816"]
    assert iso["velocity_rms_mm_s"] == pytest.approx(1e3 * 2.0 / (2 * np.pi * 100) / np.sqrt(2),
                                                     rel=0.01)
    assert iso["zone"] == "B" and iso["zones_mm_s"] == {"A/B": 1.4, "B/C": 2.8, "C/D": 4.5}
    arr = _npz(tmp_path / "g" / "spectrum.npz")
    assert list(arr["columns"]) == ["frequency", "amplitude", "noise_floor"]
    assert list(arr["units"]) == ["Hz", "g", "g"]
    header = (tmp_path / "g" / "spectrum.csv").read_text().splitlines()[0]
    assert header == "frequency [Hz],amplitude [g],noise_floor [g]"


def test_welch_matches_scipy(triax, tmp_path, capsys):
    path, data = triax
    main(["spectrum", str(path), "--channel", "1", "--welch", "--segment", "2048",
          "--overlap", "0.5", "--window", "hann", "--json", "--out", str(tmp_path / "w")])
    rep = json.loads(capsys.readouterr().out)
    assert rep["averaging"] == {"method": "welch", "segment_samples": 2048, "overlap": 0.5}
    f, p = scipy.signal.welch(data[1], fs=FS, window="hann", nperseg=2048, noverlap=1024,
                              scaling="spectrum")
    arr = _npz(tmp_path / "w" / "spectrum.npz")
    np.testing.assert_allclose(arr["frequency"], f)
    amp = np.sqrt(2 * p)
    amp[0] = np.sqrt(p[0])
    np.testing.assert_allclose(arr["amplitude"][1:-1], amp[1:-1], rtol=1e-9)


def test_all_channels_of_a_triaxial_sensor(triax, tmp_path, capsys):
    path, _ = triax
    for token in ("all", "acc"):
        out = tmp_path / token
        main(["spectrum", str(path), "--channel", token, "--json", "--out", str(out)])
        rep = json.loads(capsys.readouterr().out)
        assert [c["channel"] for c in rep["channels"]] == ["acc_x", "acc_y", "acc_z"]
        tops = [max(c["peaks"], key=lambda p: p["amplitude"])["amplitude"] for c in rep["channels"]]
        np.testing.assert_allclose(tops, [2.0, 3.0, 4.0], rtol=1e-3)
        files = set(json.loads((out / "manifest.json").read_text())["files"])
        for c in ("acc_x", "acc_y", "acc_z"):
            assert {f"spectrum_{c}.png", f"spectrum_{c}.csv", f"spectrum_{c}.npz"} <= files
        assert {"iso20816.png", "report.html"} <= files
    html = (tmp_path / "all" / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 7  # 3 spectra, 3 waveforms, ISO figure


def test_view_all_channels_psd_matches_scipy(triax, tmp_path, capsys):
    path, data = triax
    out = tmp_path / "psd"
    main(["view", str(path), "--kind", "psd", "--channel", "all", "--segment", "1024", "--json",
          "--out", str(out)])
    rep = json.loads(capsys.readouterr().out)
    assert [c["channel"] for c in rep["channels"]] == ["acc_x", "acc_y", "acc_z"]
    for k, c in enumerate(("acc_x", "acc_y", "acc_z")):
        arr = _npz(out / f"psd_{c}.npz")
        f, p = scipy.signal.welch(data[k], fs=FS, window="hann", nperseg=1024, noverlap=512)
        np.testing.assert_allclose(arr["frequency"], f)
        np.testing.assert_allclose(arr["psd"], p, rtol=1e-9)
        assert list(arr["units"]) == ["Hz", "(m/s^2)^2/Hz"]
    files = set(json.loads((out / "manifest.json").read_text())["files"])
    assert {"psd_acc_x.png", "psd_acc_y.png", "psd_acc_z.png"} <= files


def test_view_units_g(triax, capsys):
    path, data = triax
    main(["view", str(path), "--kind", "psd", "--channel", "acc_y", "--units", "g", "--json"])
    rep = json.loads(capsys.readouterr().out)
    assert rep["unit"] == "g"
    # Parseval: the PSD's total power is the variance; 3 m/s² / sqrt 2 = 0.2163 g RMS
    assert rep["rms_total"] == pytest.approx(np.std(data[1]) / 9.80665, rel=0.01)


def test_long_waveform_is_thinned_for_drawing_only():
    """A figure of a million samples draws at most MAX_DRAWN points, among them the minimum and
    the maximum of every run of samples (checked run by run with a plain loop)."""
    from dtwin.plotting.spectrum import MAX_DRAWN, drawn_points, plot_waveform

    rng = np.random.default_rng(2)
    n = 1_000_003
    t = np.arange(n) / 25600.0
    x = np.sin(2 * np.pi * 3.0 * t) + rng.standard_normal(n)
    x[123_457] = 40.0  # one impulse: it must show
    fig = plot_waveform(t, x)
    line = fig.axes[0].lines[0]
    xd, yd = line.get_xdata(), line.get_ydata()
    assert len(xd) <= MAX_DRAWN
    assert np.all(np.diff(xd) > 0) and yd.max() == 40.0 and yd.min() == x.min()
    k = -(-n // (MAX_DRAWN // 2))
    for start in range(0, n, k):
        run = x[start:start + k]
        inside = (xd >= t[start]) & (xd <= t[min(start + k, n) - 1])
        assert yd[inside].min() == run.min() and yd[inside].max() == run.max()
    # short curves are drawn whole
    xs, ys = drawn_points(t[:500], x[:500])
    np.testing.assert_array_equal(ys, x[:500])
