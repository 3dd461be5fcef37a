"""The part interface: every physical element of the twin is an `AbstractPart`.

The twin (`dtwin/model/twin.py`) evaluates its parts in two passes at every time step:

1. `modulation(twin, t, q, qdot)` — what a part does to the gear meshes: stiffness it removes
   (faults), mesh-phase shifts (planet position errors) and deflection excitations
   (transmission error, eccentricities). All parts' modulations are summed.
2. `forces(twin, t, q, qdot, aux, mesh)` — generalised forces on the coordinates `q` (a
   `Coords`), the time derivative of the part's own states `aux`, and named observables. `mesh`
   carries the mesh forces, deflections and phases computed from the summed modulation.

A part that models a further physical effect is a new final subclass; the assembly code in
`twin.py` never changes. Coordinates and sign conventions: docs/conventions.md.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..coords import Coords, MeshState

if TYPE_CHECKING:
    from ..twin import Twin  # annotations only: the twin imports the parts


class Modulation(eqx.Module):
    """Per-planet modulation of the two meshes, shape (N,) each.

    - `dk_sp`, `dk_rp`: stiffness removed from the sun-planet / ring-planet mesh (N/m).
    - `dphase_sp`, `dphase_rp`: shift of the mesh phase (cycles).
    - `e_sp`, `e_rp`: excitation subtracted from the mesh deflection (m), e.g. transmission error.
    """

    dk_sp: Float[Array, " N"]
    dk_rp: Float[Array, " N"]
    dphase_sp: Float[Array, " N"]
    dphase_rp: Float[Array, " N"]
    e_sp: Float[Array, " N"]
    e_rp: Float[Array, " N"]

    @classmethod
    def zeros(cls, n: int) -> Modulation:
        z = jnp.zeros(n)
        return cls(z, z, z, z, z, z)

    def __add__(self, other: Modulation) -> Modulation:
        return Modulation(
            self.dk_sp + other.dk_sp,
            self.dk_rp + other.dk_rp,
            self.dphase_sp + other.dphase_sp,
            self.dphase_rp + other.dphase_rp,
            self.e_sp + other.e_sp,
            self.e_rp + other.e_rp,
        )


class AbstractPart(eqx.Module):
    """A physical element of the twin (mesh, support, fault, imperfection, drive, load, sensor).

    Subclasses override what applies to them; the defaults contribute nothing. `aux_size`
    is the number of the part's own states (e.g. a motor's currents).
    """

    @property
    def aux_size(self) -> int:
        return 0

    def aux_init(self, twin: Twin, omega_sun: Float[Array, ""]) -> Float[Array, " n_aux"]:
        """Initial own states for a start with the sun at `omega_sun` (rad/s)."""
        return jnp.zeros(self.aux_size)

    def modulation(
        self, twin: Twin, t: Float[Array, ""], q: Coords, qdot: Coords
    ) -> Modulation | None:
        return None

    def forces(
        self,
        twin: Twin,
        t: Float[Array, ""],
        q: Coords,
        qdot: Coords,
        aux: Float[Array, " n_aux"],
        mesh: MeshState,
    ) -> tuple[Coords | None, Float[Array, " n_aux"], dict[str, Float[Array, "..."]]]:
        return None, jnp.zeros(self.aux_size), {}
