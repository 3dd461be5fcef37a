"""Figure of a modal analysis: natural frequencies by mode type and where each mode's energy sits."""

from __future__ import annotations

import numpy as np

from ..model.modal import MODE_TYPES, ModalResult

_COLOURS = {
    "rotational": "tab:blue",
    "translational": "tab:orange",
    "planet": "tab:green",
    "mixed": "tab:red",
}


def plot_modes(
    result: ModalResult,
    *,
    f_mesh: float | None = None,
    sample_rate: float | None = None,
    title: str | None = None,
):
    """Natural frequencies by mode type (top) and kinetic-energy shares per mode (bottom).

    Top: one stem per distinct natural frequency (Hz), on the row of its Lin & Parker type,
    labelled with its multiplicity when above 1. Optional vertical lines: the mesh frequency's
    harmonics ``m f_mesh`` (Hz) and the Nyquist frequency ``sample_rate / 2`` (Hz), to see which
    modes mesh harmonics can reach in a record. Bottom: for each distinct frequency, the fraction
    of the mode's kinetic energy in the central members' translations, their rotations and the
    planets (stacked, sums to 1).

    **Arguments:**

    - `result`: a :class:`~dtwin.model.modal.ModalResult`.
    - `f_mesh`: mesh frequency (Hz), optional.
    - `sample_rate`: sampling rate (Hz), optional.
    - `title`: figure title (default names the model and N).

    **Returns:** a matplotlib Figure.
    """
    import matplotlib.pyplot as plt

    groups = result.groups()
    t_frac = np.asarray(result.central_translation)
    r_frac = np.asarray(result.central_rotation)
    freqs = np.array([g["frequency"] for g in groups])
    types = [t for t in MODE_TYPES if any(g["type"] == t for g in groups)]
    fig, (ax, ax_e) = plt.subplots(2, 1, figsize=(9, 6), sharex=True,
                                   gridspec_kw={"height_ratios": [1.2, 1]})
    f_top = 1.08 * max(float(freqs.max()) if freqs.size else 1.0, 1.0)
    if sample_rate is not None:
        f_top = max(f_top, 0.55 * sample_rate)
    for g in groups:
        row = types.index(g["type"])
        colour = _COLOURS[g["type"]]
        ax.vlines(g["frequency"], row - 0.35, row + 0.35, color=colour, lw=2)
        if g["multiplicity"] > 1:
            ax.annotate(f"×{g['multiplicity']}", (g["frequency"], row + 0.38), ha="center",
                        va="bottom", fontsize=7, color=colour)
    if f_mesh is not None and f_mesh > 0:
        harmonics = np.arange(1, int(f_top // f_mesh) + 1) * f_mesh
        for h in harmonics:
            ax.axvline(h, color="0.75", lw=0.6, ls=":", zorder=0)
        if harmonics.size:
            ax.plot([], [], color="0.75", lw=0.6, ls=":",
                    label=f"mesh harmonics m·{f_mesh:.1f} Hz")
    if sample_rate is not None:
        ax.axvline(sample_rate / 2, color="k", lw=1.0, ls="--",
                   label=f"Nyquist {sample_rate / 2:.0f} Hz")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    ax.set_yticks(range(len(types)), types)
    ax.set_ylim(-0.7, len(types) - 0.2)
    ax.set_xlim(-0.01 * f_top, f_top)
    ax.set_ylabel("mode type")
    ax.set_title(title or f"Natural frequencies, {result.model} model, N = {result.n_planets}")
    ax.grid(axis="x", alpha=0.3)

    first = [g["modes"][0] for g in groups]
    # per group: mean shares of its modes (equal-frequency modes share the energy split)
    tg = np.array([t_frac[g["modes"]].mean() for g in groups])
    rg = np.array([r_frac[g["modes"]].mean() for g in groups])
    pg = np.clip(1.0 - tg - rg, 0.0, 1.0)
    width = 0.006 * f_top
    x = freqs if len(first) else np.zeros(0)
    ax_e.bar(x, tg, width=width, color="tab:orange", label="central translation")
    ax_e.bar(x, rg, width=width, bottom=tg, color="tab:blue", label="central rotation")
    ax_e.bar(x, pg, width=width, bottom=tg + rg, color="tab:green", label="planets")
    ax_e.set_ylim(0, 1.3)
    ax_e.set_yticks([0, 0.25, 0.5, 0.75, 1.0])
    ax_e.set_xlabel("frequency (Hz)")
    ax_e.set_ylabel("kinetic energy share (1)")
    ax_e.legend(loc="upper right", fontsize=8, ncol=3)
    ax_e.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    return fig


__all__ = ["plot_modes"]
