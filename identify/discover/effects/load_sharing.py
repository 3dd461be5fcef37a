"""Unequal load sharing: static clearances of the planets' meshes."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp

from dtwin.model.parts.imperfections import MeshOffsets

from .base import AbstractEffect, EffectParameter, carrier_grid, rms


class LoadSharingEffect(AbstractEffect):
    """Extra clearance (m) of both meshes of planets 1 … N−1 relative to planet 0.

    Part: :class:`dtwin.model.parts.imperfections.MeshOffsets` with the same offset on the sun and
    ring mesh of a planet (a planet with a larger clearance carries less load). Lines: the
    forbidden ``m fm + n fc`` of the sideband rule, like every planet-to-planet difference.
    """

    name: ClassVar[str] = "load_sharing"
    group: ClassVar[str] = "carrier_sidebands"
    description: ClassVar[str] = "unequal load sharing between the planets"
    main_name: ClassVar[str] = "mesh clearance differences (norm over planets 1 … N−1)"
    main_unit: ClassVar[str] = "m"
    typical_range: ClassVar[tuple[float, float]] = (1e-8, 1e-6)
    typical_note: ClassVar[str] = (
        "load-sharing factors Kγ of 1.05–1.5 (AGMA 6123 / ISO 6336-1 quote ~1.1–1.25 for three "
        "planets): clearance differences of a few per cent up to about the static mesh "
        "deflection, 10 nm – 1 µm for the paper's gearbox")

    def parameters(self, twin):
        return tuple(EffectParameter(f"load_sharing_offset_{i}", "m", 5e-8,
                                     f"extra mesh clearance of planet {i} relative to planet 0",
                                     (-1e-4, 1e-4))
                     for i in range(1, twin.n_planets))

    def parts(self, theta, twin, kin):
        e = jnp.concatenate([jnp.zeros(1), theta])
        return (MeshOffsets(e, e),)

    def signature(self, kin, f_max):
        return carrier_grid(kin, f_max)

    def main(self, theta):
        return rms(theta)
