"""Lumped parameters of a planetary gear set: everything the dynamics and modal analysis need.

A flat, frozen `equinox.Module` in SI units. Parameter fields carry the registry's names
(`dtwin.model.registry`) so that a fit can replace them by name with ``eqx.tree_at`` or
:func:`replace`. Build one from a spec with :func:`dtwin.spec.lumped_from_spec` (geometry gives
masses, inertias and ISO 6336 stiffness unless the spec gives them directly), or directly (as for
Lin & Parker's example).
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..errors import SpecError


class LumpedParameters(eqx.Module):
    """Lumped model of a single-stage planetary set (ring fixed by supports, sun in, carrier out).

    Geometry (static integers and geometric constants):

    - `z_sun`, `z_planet`, `z_ring`, `n_planets`: tooth counts and number of planets.
    - `planet_angles`: carrier-frame angle `psi_i` of each planet (rad), spacing errors included.
    - `rb_sun`, `rb_planet`, `rb_ring`: base radii (m).
    - `centre_distance`: operating centre distance a (m) (carrier radius).
    - `alpha_sp`, `alpha_rp`: operating pressure angles of the sun-planet and ring-planet meshes (rad).
    - `eps_sp`, `eps_rp`: transverse contact ratios.
    - `phase0_sp`, `phase0_rp`: mesh phase offsets (cycles) of planet 0's two meshes
      (docs/conventions.md, "Mesh phase").

    Inertias: `m_sun`, `m_ring`, `m_carrier`, `m_planet` (kg); `J_sun`, `J_ring`, `J_carrier`,
    `J_planet` (kg·m²) — the carrier's `J` excludes the planets' translational inertia, which the
    model adds as `N m_planet a²`.

    Stiffness (N/m, N·m/rad) and damping (ratios): `k_sun_planet`, `k_ring_planet` (mean mesh),
    `k_bearing_sun`, `k_bearing_ring`, `k_bearing_carrier`, `k_bearing_planet` (translational),
    `k_torsion_sun`, `k_torsion_ring`, `k_torsion_carrier` (torsional supports to ground; sun and
    carrier normally 0), `zeta_sun_planet`, `zeta_ring_planet`, `zeta_support`.
    """

    z_sun: int = eqx.field(static=True)
    z_planet: int = eqx.field(static=True)
    z_ring: int = eqx.field(static=True)
    n_planets: int = eqx.field(static=True)
    planet_angles: Float[Array, " N"]
    rb_sun: Float[Array, ""]
    rb_planet: Float[Array, ""]
    rb_ring: Float[Array, ""]
    centre_distance: Float[Array, ""]
    alpha_sp: Float[Array, ""]
    alpha_rp: Float[Array, ""]
    eps_sp: Float[Array, ""]
    eps_rp: Float[Array, ""]
    phase0_sp: Float[Array, ""]
    phase0_rp: Float[Array, ""]
    m_sun: Float[Array, ""]
    m_ring: Float[Array, ""]
    m_carrier: Float[Array, ""]
    m_planet: Float[Array, ""]
    J_sun: Float[Array, ""]
    J_ring: Float[Array, ""]
    J_carrier: Float[Array, ""]
    J_planet: Float[Array, ""]
    k_sun_planet: Float[Array, ""]
    k_ring_planet: Float[Array, ""]
    k_bearing_sun: Float[Array, ""]
    k_bearing_ring: Float[Array, ""]
    k_bearing_carrier: Float[Array, ""]
    k_bearing_planet: Float[Array, ""]
    k_torsion_sun: Float[Array, ""]
    k_torsion_ring: Float[Array, ""]
    k_torsion_carrier: Float[Array, ""]
    zeta_sun_planet: Float[Array, ""]
    zeta_ring_planet: Float[Array, ""]
    zeta_support: Float[Array, ""]

    def __check_init__(self):
        if self.n_planets < 1:
            raise SpecError([("gears.n_planets", f"must be >= 1, got {self.n_planets}")])
        if jnp.shape(self.planet_angles) != (self.n_planets,):
            raise SpecError(
                [("gears.planet_angles", f"needs {self.n_planets} angles, got "
                  f"{jnp.shape(self.planet_angles)}")]
            )

    @property
    def gear_ratio(self) -> float:
        """Sun-to-carrier speed ratio with the ring fixed, 1 + Zr/Zs."""
        return 1.0 + self.z_ring / self.z_sun


_FLOAT_FIELDS = tuple(
    f for f in LumpedParameters.__dataclass_fields__
    if f not in ("z_sun", "z_planet", "z_ring", "n_planets")
)


def make_lumped(**values: Any) -> LumpedParameters:
    """Build `LumpedParameters`, converting every float field to a float64 JAX array."""
    out = dict(values)
    for f in _FLOAT_FIELDS:
        if f in out:
            out[f] = jnp.asarray(out[f], dtype=jnp.float64)
    return LumpedParameters(**out)


def replace(lp: LumpedParameters, **values: Any) -> LumpedParameters:
    """A copy of `lp` with the named float fields replaced (differentiable w.r.t. the values)."""
    names = list(values)
    return eqx.tree_at(
        lambda m: [getattr(m, n) for n in names],
        lp,
        [jnp.asarray(values[n], dtype=jnp.float64) for n in names],
    )
