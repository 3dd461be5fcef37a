"""Spectrum-like figures: the level scale states its reference (ISO 1683), every peak lies inside
the axes, labels are lifted apart, the default band covers the mesh harmonics."""

import numpy as np
import pytest

from dtwin.plotting.levels import level_axis, levels, mesh_band, place_labels, set_level_limits
from dtwin.plotting.views import plot_cepstrum, plot_order_spectrum, plot_psd


def test_db_reference_is_stated():
    y, text = levels(np.array([1.0, 1e-6]), "m/s^2", "db")
    np.testing.assert_allclose(y, [120.0, 0.0])  # 1 m/s² = 120 dB re 1 µm/s²
    assert text == "dB re 1 µm/s²"
    assert level_axis("amplitude", "g", "db") == "amplitude (dB re 1 g)"
    assert level_axis("amplitude", "m/s^2", "linear") == "amplitude (m/s²)"
    assert level_axis("PSD", "m/s^2", "db", power=True) == "PSD (dB re (1 µm/s²)²/Hz)"
    with pytest.raises(ValueError):
        levels(np.ones(2), "g", "log")


def test_limits_keep_peaks_inside():
    from matplotlib.figure import Figure

    ax = Figure().add_subplot()
    y = np.array([1.0, 40.0, 3.0])
    for scale in ("linear", "db"):
        set_level_limits(ax, y if scale == "linear" else 20 * np.log10(y), scale)
        lo, hi = ax.get_ylim()
        top = 40.0 if scale == "linear" else 20 * np.log10(40.0)
        assert hi > top + 0.1 * (top - lo)  # room above the highest peak for its label


def test_close_labels_do_not_overlap():
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6, 3))
    ax = fig.add_subplot()
    ax.set_xlim(0, 100)
    ax.set_ylim(0, 10)
    place_labels(ax, [50.0, 50.2, 90.0], [1.0, 5.0, 1.0], ["2fm", "2fm'", "x"])
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    r = canvas.get_renderer()
    from matplotlib.text import Text

    boxes = {t.get_text(): Text.get_window_extent(t, r) for t in ax.texts}  # text, no leader
    assert not boxes["2fm"].overlaps(boxes["2fm'"])  # 0.2 % of the width apart: side by side
    assert ax.texts[0].xyann[1] == ax.texts[1].xyann[1] > 5.0  # one line above the higher point
    assert ax.texts[2].xyann[0] == 90.0  # a lone point keeps its label over it


def test_labels_after_a_pushed_cluster_keep_their_distance():
    # the discover figure's residual lines (Hz, 0–2500 Hz axis): a cluster pushed right must not
    # leave the next lone point's text against its last one ("11" "12" read as "1112")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.text import Text

    xs = [30.0, 41.5, 60.0, 101.5, 112.9, 131.5, 172.9, 184.4, 244.4, 255.9, 315.9, 327.4]
    ys = [-28.0, -28.0, -37.0, -29.0, -29.0, -37.0, -30.0, -31.0, -33.0, -34.0, -35.0, -36.0]
    for figsize, kw in (((9, 3), {}), ((10, 4.5), {"min_sep": 0.012, "fontsize": 7})):
        fig = Figure(figsize=figsize)
        ax = fig.add_subplot()
        ax.set_xlim(0, 2500)
        ax.set_ylim(-90, 10)
        place_labels(ax, xs, ys, [str(k) for k in range(1, len(xs) + 1)], **kw)
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        r = canvas.get_renderer()
        boxes = sorted((Text.get_window_extent(t, r) for t in ax.texts), key=lambda b: b.x0)
        gaps = [b.x0 - a.x1 for a, b in zip(boxes, boxes[1:], strict=False)]
        # white between neighbouring texts on one line: at least a fifth of the font size
        assert min(gaps) > 0.2 * kw.get("fontsize", 8) * fig.dpi / 72.0, (figsize, gaps)
        assert len(ax.texts) == len(xs)
        inside = ax.get_window_extent(r)
        assert all(inside.x0 <= b.x0 and b.x1 <= inside.x1 for b in boxes)  # none off the axes


def test_unstated_unit_reads_record_unit():
    assert level_axis("amplitude", None, "db") == "amplitude (dB re 1 record unit)"
    assert level_axis("amplitude", "-", "linear") == "amplitude (record unit)"


def test_mesh_band():
    # fm 499 Hz, fc 4.87 Hz, Nyquist 2500 Hz: fm - 12 fc ... 3 fm + 12 fc
    lo, hi = mesh_band(499.0, 4.87, 2500.0)
    assert lo == pytest.approx(499.0 - 12 * 4.87) and hi == pytest.approx(3 * 499.0 + 12 * 4.87)
    assert mesh_band(499.0, 4.87, 800.0)[1] == pytest.approx(499 + 12 * 4.87)


def test_view_figures_state_units():
    o = np.linspace(0, 40, 801)
    a = np.full(o.shape, 1e-3)
    a[334] = 1.0
    fig = plot_order_spectrum(o, a, unit="m/s^2", channel="acc_x")
    ax = fig.axes[0]
    assert "dB re 1 µm/s²" in ax.get_ylabel() and "[acc_x]" in ax.get_title()
    assert ax.get_ylim()[1] > 120.0
    fig = plot_psd(o, a, unit="m/s^2")
    assert "²/Hz" in fig.axes[0].get_ylabel() and "^2" not in fig.axes[0].get_ylabel()
    q = np.arange(2000) / 5000.0
    fig = plot_cepstrum(q, np.zeros(q.size), spacings={"fc": 6.0, "N fc": 18.0})
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert "1/fc" in texts and "3/N fc" in texts  # both shown where they coincide


def test_label_text_is_the_shortest_form():
    # issue #22: "fm − 3fs/3 + fp + fc" is fm − fs + fp + fc (3 · fs/3 = fs)
    from dtwin.model.kinematics import combination_text

    assert combination_text([("fm", 1), ("fs/3", -3), ("fp", 1), ("fc", 1)]) == "fm − fs + fp + fc"
    assert combination_text([("fm", 3), ("fs/3", 2), ("fc", 1)]) == "3fm + 2fs/3 + fc"
    assert combination_text([("fs", 1), ("fs/3", -3)]) == "DC"


def test_fit_and_discover_figures_name_an_unstated_unit():
    # a CSV record states no unit: its levels are not dB re 1 µm/s²
    from dtwin.identify.plotting.fit import plot_fit_spectrum

    f = np.linspace(400.0, 600.0, 201)
    a = np.full(f.shape, 1e-3)
    fig = plot_fit_spectrum(f, a, a, unit=None)
    assert fig.axes[0].get_ylabel() == "level (dB re 1 record unit)"
    fig = plot_fit_spectrum(f, a, a, unit="m/s^2")
    assert fig.axes[0].get_ylabel() == "level (dB re 1 µm/s²)"
