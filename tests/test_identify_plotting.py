"""Identification figures: one panel per fitted band (no empty half-page), one label per line,
levels in dB re the ISO 1683 reference."""

import numpy as np

from dtwin.identify.plotting.fit import plot_fit_spectrum


def test_fit_spectrum_panels_and_labels():
    df = 0.25
    bands = [np.arange(430, 570, df), np.arange(930, 1070, df)]
    f = np.concatenate(bands)
    m = np.full(f.size, 1e-2)
    m[np.argmin(np.abs(f - 998.0))] = 1.0
    labels = [(997.75, "2fm"), (998.0, "2fm"), (500.0, "fm")]  # two bins of one line
    fig = plot_fit_spectrum(f, m, 0.9 * m, labels=labels)
    panels = [ax for ax in fig.axes if ax.get_lines()]
    assert len(panels) == 2
    for ax, b in zip(panels, bands, strict=True):
        lo, hi = ax.get_xlim()
        assert lo >= b[0] - 1 and hi <= b[-1] + 1  # each panel spans its band only
    assert "dB re 1 µm/s²" in panels[0].get_ylabel()
    numbers = [t.get_text() for ax in panels for t in ax.texts]
    assert sorted(numbers) == ["1", "2"]  # 2fm once
    listing = "".join(t.get_text() for ax in fig.axes for t in ax.texts if "Hz" in t.get_text())
    assert listing.count("2fm") == 1
    assert panels[0].get_ylim()[1] > 120.0  # 1 m/s² = 120 dB: inside, with room for labels
