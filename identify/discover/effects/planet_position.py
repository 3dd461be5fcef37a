"""Planet position (spacing) errors: planet i sits at ``psi_i + dpsi_i`` on the carrier."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp

from dtwin.model.parts.imperfections import PlanetPositionErrors

from .base import AbstractEffect, EffectParameter, carrier_grid, rms


class PlanetPositionEffect(AbstractEffect):
    """Angular position errors of planets 1 … N−1 relative to planet 0 (rad).

    Part: :class:`dtwin.model.parts.imperfections.PlanetPositionErrors` with ``pin_offset=False``:
    the planets' mesh phases shift with their angles while the load stays shared equally, as
    in a gearbox whose floating sun or ring takes up the pins' offsets (for three planets all
    of them). These are the planets of a spec's ``imperfections.planet_position_errors``, so a
    fitted value can be written there and means the same. The pins' offsets against a sun and
    ring held on their centres (the same errors in a gearbox with no floating member) load the
    meshes unequally: that is the ``load_sharing`` member (a clearance ``a dpsi cos(alpha)``
    on both meshes of a planet), which a rigid torsional twin turns into contact loss at
    errors of ~1e-5 rad. Breaks the sideband cancellation of equally spaced planets: lines
    ``m fm + n fc`` the sideband rule forbids, growing with the mesh harmonic m.
    """

    name: ClassVar[str] = "planet_position_errors"
    group: ClassVar[str] = "carrier_sidebands"
    description: ClassVar[str] = "planet position (spacing) errors on the carrier"
    main_name: ClassVar[str] = "planet position errors (norm over planets 1 … N−1)"
    main_unit: ClassVar[str] = "rad"
    typical_range: ClassVar[tuple[float, float]] = (1e-5, 1e-3)
    typical_note: ClassVar[str] = (
        "0.5–50 µm at a 50 mm pin radius: carrier pin-hole position tolerances of industrial "
        "planetary sets are ~10–30 µm (AGMA 6123, ISO 1328 grades 5–8); read as mesh phase "
        "errors with the load shared equally (a floating sun or ring)")

    def parameters(self, twin):
        return tuple(EffectParameter(f"planet_position_error_{i}", "rad", 1e-4,
                                     f"angular position error of planet {i} relative to planet 0",
                                     (-0.1, 0.1))
                     for i in range(1, twin.n_planets))

    def parts(self, theta, twin, kin):
        return (PlanetPositionErrors(jnp.concatenate([jnp.zeros(1), theta]), pin_offset=False),)

    def signature(self, kin, f_max):
        return carrier_grid(kin, f_max)

    def main(self, theta):
        return rms(theta)
