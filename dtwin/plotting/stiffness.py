"""Figure of the time-varying mesh stiffness of one planet's sun and ring meshes, healthy and faulty."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def plot_mesh_stiffness(
    mesh_cycles: ArrayLike,
    k_sun_planet: ArrayLike,
    k_ring_planet: ArrayLike,
    *,
    k_sun_planet_faulty: ArrayLike | None = None,
    k_ring_planet_faulty: ArrayLike | None = None,
    zoom: tuple[float, float] | None = None,
    fault_label: str = "faulty",
    planet: int = 0,
    title: str | None = None,
):
    """Mesh stiffness of planet `planet`'s sun–planet and ring–planet meshes over mesh cycles.

    Left column: the whole record; right column (when `zoom` is given): the interval `zoom`
    (mesh cycles), e.g. a few cycles around the faulty tooth's contact. Rows: sun–planet mesh,
    ring–planet mesh. Healthy curves solid, faulty ones (when given) dashed. Stiffness in
    ``1e8 N/m``.

    **Arguments:**

    - `mesh_cycles`: abscissa, mesh cycles (``Zr theta_c / 2 pi`` with the ring fixed), shape (T,).
    - `k_sun_planet`, `k_ring_planet`: healthy stiffness (N/m), shape (T,).
    - `k_sun_planet_faulty`, `k_ring_planet_faulty`: stiffness with the fault(s) (N/m), optional.
    - `zoom`: (start, stop) in mesh cycles for the right column, optional.
    - `fault_label`: legend entry of the faulty curves (e.g. ``sun missing tooth 0.5``).
    - `planet`: the planet shown (for the labels).
    - `title`: figure title.

    **Returns:** a matplotlib Figure.
    """
    import matplotlib.pyplot as plt

    x = np.asarray(mesh_cycles, dtype=np.float64)
    healthy = [np.asarray(k_sun_planet, dtype=np.float64), np.asarray(k_ring_planet, dtype=np.float64)]
    faulty = [None if k is None else np.asarray(k, dtype=np.float64)
              for k in (k_sun_planet_faulty, k_ring_planet_faulty)]
    ncols = 2 if zoom is not None else 1
    fig, axes = plt.subplots(2, ncols, figsize=(6 + 4 * (ncols - 1), 5.5), squeeze=False,
                             sharey="row", gridspec_kw={"width_ratios": [3, 2][:ncols]})
    names = (f"sun–planet mesh (planet {planet})", f"ring–planet mesh (planet {planet})")
    scale = 1e8
    for row in range(2):
        for col in range(ncols):
            ax = axes[row, col]
            ax.plot(x, healthy[row] / scale, color="tab:blue", lw=1.2, label="healthy")
            if faulty[row] is not None:
                ax.plot(x, faulty[row] / scale, color="tab:red", lw=1.2, ls="--",
                        label=fault_label)
            if col == 1 and zoom is not None:
                ax.set_xlim(*zoom)
                ax.set_title(f"zoom, cycles {zoom[0]:.1f}–{zoom[1]:.1f}", fontsize=9)
            else:
                ax.set_xlim(float(x[0]), float(x[-1]))
                ax.set_title(names[row], fontsize=10)
                ax.set_ylabel("mesh stiffness (1e8 N/m)")
            ax.grid(True, alpha=0.3)
            if row == 1:
                ax.set_xlabel("mesh cycles (Zr θc / 2π)")
            ax.set_ylim(bottom=0.0)
    axes[0, 0].legend(loc="lower right", fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig
