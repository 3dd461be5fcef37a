"""Tests of dtwin.signal.order on a synthetic run-up whose shaft angle is known in closed form."""

import numpy as np
import pytest

from dtwin.errors import RecordError
from dtwin.signal.order import (
    campbell,
    mesh_angle,
    order_spectrum,
    resample_to_angle,
    shaft_speed,
    tacho_angle,
    tacho_times,
    waterfall,
)
from dtwin.signal.spectrum import amplitude_spectrum, find_peaks

FS = 5000.0
T = 3.0
ZS, ZR, N = 21, 81, 3
MESH_ORDER = ZS * ZR / (ZS + ZR)  # orders of the sun (reference shaft), ring fixed
CARRIER_ORDER = ZS / (ZS + ZR)
SB = N * CARRIER_ORDER  # sideband spacing allowed by the planet-pass rule (docs/references.md §2)
F0, F1 = 10.0, 30.0  # sun speed ramps linearly from F0 to F1 Hz over T


def _true_angle(t):
    return 2 * np.pi * (F0 * t + 0.5 * (F1 - F0) / T * t**2)


@pytest.fixture(scope="module")
def runup():
    t = np.arange(int(FS * T)) / FS
    th = _true_angle(t)
    x = (1 + 0.5 * np.cos(SB * th)) * np.cos(MESH_ORDER * th) + 0.3 * np.cos(2 * MESH_ORDER * th + 1)
    x = x + np.random.default_rng(0).normal(scale=0.05, size=t.size)
    ppr = 4
    tacho = np.where(np.sin(ppr * th - 0.2) >= 0, 5.0, 0.0)  # 0/5 V square wave, 4 pulses/rev
    return t, th, x, tacho, ppr


SPR = 512  # >= 2.5 * highest order (33.4) * f_max / f_min (3): the anti-alias rule of order.py


def _expected_orders():
    return {MESH_ORDER - SB: 0.25, MESH_ORDER: 1.0, MESH_ORDER + SB: 0.25, 2 * MESH_ORDER: 0.3}


def _check_order_peaks(orders, amp):
    d_order = orders[1] - orders[0]
    peaks = find_peaks(orders, amp, threshold_db=20.0, width_bins=31, band=(5, 40))
    assert len(peaks) == 4
    for p, (o, a) in zip(peaks, sorted(_expected_orders().items()), strict=True):
        assert abs(p.frequency - o) <= d_order  # within one order bin
        assert p.amplitude == pytest.approx(a, rel=0.2)


def test_tacho_angle_and_speed_match_the_closed_form(runup):
    t, th, _, _, ppr = runup
    tacho = np.sin(ppr * th - 0.2)  # a magnetic pick-up: smooth, so crossings interpolate exactly
    times = tacho_times(tacho, FS)
    # rising edges where ppr*theta - 0.2 = 2 pi k: the angle at the first is 0.2/ppr
    np.testing.assert_allclose(_true_angle(times), (2 * np.pi * np.arange(times.size) + 0.2) / ppr,
                               atol=2e-3)
    ang = tacho_angle(tacho, FS, ppr) + 0.2 / ppr
    # a 0/5 V square wave: crossings are known to half a sample only
    square = tacho_angle(np.where(tacho >= 0, 5.0, 0.0), FS, ppr) + 0.2 / ppr
    inner = (t > times[1]) & (t < times[-2])
    assert np.max(np.abs(ang[inner] - th[inner])) < 5e-3
    assert np.max(np.abs(square[inner] - th[inner])) < 2 * np.pi * F1 / FS
    speed = shaft_speed(ang, FS)
    np.testing.assert_allclose(speed[inner], F0 + (F1 - F0) * t[inner] / T, rtol=2e-3)


def test_order_tracking_with_tachometer_holds_orders_constant(runup):
    t, th, x, tacho, ppr = runup
    _, xa = resample_to_angle(x, FS, tacho_angle(tacho, FS, ppr), SPR)
    orders, amp = order_spectrum(xa, SPR, "hann")
    _check_order_peaks(orders, amp)
    # independent contrast: the untracked spectrum smears the mesh tone over 167-500 Hz
    _, a_time = amplitude_spectrum(x, FS, "hann")
    assert a_time.max() < 0.2


def test_order_tracking_without_tachometer_from_mesh_phase(runup):
    t, th, x, _, _ = runup
    ang = mesh_angle(x, FS, MESH_ORDER, (8.0, 32.0), bandwidth=0.3)
    # the angle is known up to a multiple of 2pi/mesh_order plus the start offset
    err = ang - (th - th[0])
    inner = slice(int(0.2 * FS), int((T - 0.2) * FS))
    offset = np.median(err[inner])
    assert np.max(np.abs(err[inner] - offset)) < 2 * np.pi / MESH_ORDER * 0.05
    _, xa = resample_to_angle(x, FS, ang, SPR)
    _check_order_peaks(*order_spectrum(xa, SPR, "hann"))


def test_waterfall_tracks_the_mesh_ridge_and_campbell_lines(runup):
    t, th, x, _, _ = runup
    wf = waterfall(x, FS, segment_length=512, overlap=0.5, angle=th)
    true_speed = F0 + (F1 - F0) * wf.times / T
    np.testing.assert_allclose(wf.speed, true_speed, rtol=1e-3)
    band = (wf.freqs > 100) & (wf.freqs < 600)
    ridge = wf.freqs[band][np.argmax(wf.amplitude[band], axis=0)]
    df = wf.freqs[1] - wf.freqs[0]
    assert np.all(np.abs(ridge - MESH_ORDER * true_speed) <= 1.5 * df)
    cd = campbell(wf, {"fm": MESH_ORDER}, [250.0])
    np.testing.assert_allclose(cd.order_lines["fm"], MESH_ORDER * np.sort(wf.speed))
    assert cd.natural_frequencies == {"f1": 250.0}


def test_waterfall_amplitude_of_a_steady_tone():
    t = np.arange(8192) / 1024.0
    wf = waterfall(2.5 * np.sin(2 * np.pi * 64.0 * t), 1024.0, segment_length=256)
    k = np.argmin(np.abs(wf.freqs - 64.0))
    np.testing.assert_allclose(wf.amplitude[k], 2.5, rtol=1e-9)


def test_errors_name_the_fix():
    with pytest.raises(RecordError, match="increase strictly"):
        resample_to_angle(np.ones(10), 10.0, np.zeros(10), 16)
    with pytest.raises(RecordError, match="pulses"):
        tacho_angle(np.r_[np.zeros(50), np.ones(50)], 100.0, 1)
    with pytest.raises(RecordError, match="Campbell"):
        campbell(waterfall(np.random.default_rng(0).normal(size=256), 100.0, segment_length=64), {})


def test_cli_view_order_without_tacho_labels_mesh_orders(tmp_path, capsys):
    readers = pytest.importorskip("dtwin.io.readers", reason="record readers not available yet")
    pytest.importorskip("dtwin.spec", reason="dtwin.spec not available yet")
    import json

    from dtwin.cli import main
    from dtwin.io import Record

    # the paper's simulation gearbox (Zs 21, Zr 81, N 3) at about 30 Hz with a slow speed drift
    t = np.arange(int(FS * 2.0)) / FS
    th = 2 * np.pi * (30.0 * t + 0.2 * np.sin(2 * np.pi * 0.5 * t))
    x = (1 + 0.5 * np.cos(SB * th)) * np.cos(MESH_ORDER * th)
    x = x + np.random.default_rng(8).normal(scale=0.02, size=t.size)
    path = tmp_path / "run.dtwin.h5"
    readers.write_record(Record(x[None, :], FS, ("acc",), ("m/s^2",)), path)
    main(["view", str(path), "--kind", "order", "--preset", "paper-sim", "--f-sun", "30",
          "--json", "--out", str(tmp_path / "o")])
    rep = json.loads(capsys.readouterr().out)
    assert rep["angle_source"].startswith("mesh phase")
    by_label = {p["labels"][0]: p for p in rep["peaks"] if p["labels"]}
    for label, order in (("fm", MESH_ORDER), ("fm − 3fc", MESH_ORDER - SB),
                         ("fm + 3fc", MESH_ORDER + SB)):
        assert abs(by_label[label]["order"] - order) <= rep["order_resolution"]
    assert by_label["fm"]["amplitude"] == pytest.approx(1.0, rel=0.2)
    assert (tmp_path / "o" / "order.png").exists()
    # waterfall + Campbell with the tacho-less angle and a natural frequency overlay
    main(["view", str(path), "--kind", "waterfall", "--preset", "paper-sim", "--f-sun", "30",
          "--nat", "1475.7", "--segment", "512", "--json", "--out", str(tmp_path / "w")])
    rep = json.loads(capsys.readouterr().out)
    assert rep["natural_frequencies_hz"] == {"f1": 1475.7}
    assert 29.0 < rep["speed_hz"]["min"] < rep["speed_hz"]["max"] < 31.0
    assert (tmp_path / "w" / "waterfall.png").exists() and (tmp_path / "w" / "campbell.png").exists()
