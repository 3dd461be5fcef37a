"""The state types the twin and its parts share: generalised coordinates (:class:`Coords`) and
the meshes at one instant (:class:`MeshState`), with the unit vectors of the carrier frame.

Coordinates and signs: docs/conventions.md. The twin (:mod:`dtwin.model.twin`) lays them out in its
state vector; the parts (:mod:`dtwin.model.parts`) read them and return forces as :class:`Coords`.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

__all__ = ["Coords", "MeshState", "unit_radial", "unit_tangential"]


class Coords(eqx.Module):
    """Generalised coordinates (or velocities, accelerations, forces) of the gear set.

    Translations in metres (carrier frame), rotations in radians (absolute). For a force-like
    `Coords`, translation entries are forces (N) and rotation entries torques (N·m).
    """

    sun_xy: Float[Array, " 2"]
    theta_s: Float[Array, ""]
    ring_xy: Float[Array, " 2"]
    theta_r: Float[Array, ""]
    carrier_xy: Float[Array, " 2"]
    theta_c: Float[Array, ""]
    zeta: Float[Array, " N"]
    eta: Float[Array, " N"]
    theta_p: Float[Array, " N"]

    @classmethod
    def zeros(cls, n: int) -> Coords:
        z2, z0, zn = jnp.zeros(2), jnp.zeros(()), jnp.zeros(n)
        return cls(z2, z0, z2, z0, z2, z0, zn, zn, zn)

    def __add__(self, other: Coords) -> Coords:
        return jax.tree_util.tree_map(jnp.add, self, other)

    def __mul__(self, scale: Any) -> Coords:
        return jax.tree_util.tree_map(lambda a: a * scale, self)

    def set(self, **fields: Any) -> Coords:
        """A copy with the named fields replaced."""
        return dataclasses.replace(self, **fields)


class MeshState(eqx.Module):
    """The meshes at one instant, shape (N,) each (sun-planet `_sp`, ring-planet `_rp`).

    - `phase_*`: mesh phase (cycles); `k_*`: stiffness (N/m); `c_*`: damping (N·s/m);
    - `delta_*`: deflection (m, positive = compressed), `ddelta_*`: its rate (m/s);
    - `force_*`: contact force along the line of action (N), never negative.
    """

    phase_sp: Float[Array, " N"]
    phase_rp: Float[Array, " N"]
    k_sp: Float[Array, " N"]
    k_rp: Float[Array, " N"]
    c_sp: Float[Array, " N"]
    c_rp: Float[Array, " N"]
    delta_sp: Float[Array, " N"]
    delta_rp: Float[Array, " N"]
    ddelta_sp: Float[Array, " N"]
    ddelta_rp: Float[Array, " N"]
    force_sp: Float[Array, " N"]
    force_rp: Float[Array, " N"]


def unit_radial(psi):
    """Radial unit vector(s) ``(cos psi, sin psi)`` at angle(s) `psi` (rad), carrier frame."""
    return jnp.stack([jnp.cos(psi), jnp.sin(psi)], axis=-1)


def unit_tangential(psi):
    """Tangential unit vector(s) ``(−sin psi, cos psi)`` at angle(s) `psi` (rad)."""
    return jnp.stack([-jnp.sin(psi), jnp.cos(psi)], axis=-1)
