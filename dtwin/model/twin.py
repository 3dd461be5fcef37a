"""The twin: parts assembled into one vector field. The state layout lives here only.

Coordinates (docs/conventions.md): per body two translations and a rotation. Central members
(sun, ring, carrier) translate in the carrier frame; planets translate relative to their pins
(radial `zeta`, tangential `eta`); every rotation is an absolute angle (rad). The torsional
reduction keeps only the rotations.

Integration coordinates. Absolute angles grow without bound (the sun turns ~750 rad in 4 s) and
an adaptive solver controls their error relative to their size, which would let the *difference*
of two angles — the mesh deflection — drift. The integrated coordinates `z` therefore keep only
the carrier angle absolute and store every other rotation as its deviation from the rigid
kinematics of a fixed ring::

    theta_s = (1 + Zr/Zs) theta_c + z_s,     theta_p_i = (1 - Zr/Zp) theta_c + z_p_i

(`q = A z` with a constant matrix `A`). With the mass matrix `M` of the coordinates `q` the
equations of motion are ``(A^T M A) z'' = A^T F(t, q, q')``; `M` is constant (planet translation
inertia couples to the carrier rotation through the pin radius `a`), so its inverse is computed
once. Rotating-frame (Coriolis and centripetal) forces on the translations are included; the
Euler force of translations is neglected (carrier angular acceleration × micrometre offsets).

Mesh forces act along the lines of action (deflections in docs/conventions.md) with one-sided
contact, smoothed over `contact_smoothing` metres::

    F = k(t) * s * softplus(delta / s) + c * delta' * sigmoid(delta / s)

and generalised forces ``-F * d(delta)/dq`` by automatic differentiation of the (linear)
deflection map, so every part's forces are consistent with virtual work.
"""

from __future__ import annotations

import functools as ft

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .coords import Coords as Coords
from .coords import MeshState as MeshState
from .coords import unit_radial as unit_radial
from .coords import unit_tangential as unit_tangential
from .faults import mesh_phases
from .lumped import LumpedParameters
from .parts.base import AbstractPart, Modulation
from .stiffness import mesh_stiffness_waveform

KINDS = ("translational", "torsional")


def _softplus_sigmoid(u):
    """``(softplus(u), sigmoid(u))`` from one exponential and one log1p (stable for any u)."""
    e = jnp.exp(-jnp.abs(u))
    sp = jnp.maximum(u, 0.0) + jnp.log1p(e)
    sg = jnp.where(u >= 0.0, 1.0, e) / (1.0 + e)
    return sp, sg


@ft.partial(jax.custom_jvp, nondiff_argnums=(4,))
def contact_force(d, dd, k, c, s: float):
    r"""Mesh contact force (N) with one-sided contact smoothed over `s` (m):
    ``k s softplus(d / s) + c d' sigmoid(d / s)`` for deflection `d` (m), its rate `dd` (m/s),
    stiffness `k` (N/m) and damping `c` (N·s/m). Its derivative rule reuses the primal's
    exponential (``softplus' = sigmoid``, ``sigmoid' = sigmoid (1 - sigmoid)``), where JAX's
    own rules would evaluate three more exponentials per mesh for every tangent."""
    sp, sg = _softplus_sigmoid(d / s)
    return k * s * sp + c * dd * sg


@contact_force.defjvp
def _contact_force_jvp(s, primals, tangents):
    d, dd, k, c = primals
    d_d, d_dd, d_k, d_c = tangents
    sp, sg = _softplus_sigmoid(d / s)
    out = k * s * sp + c * dd * sg
    slope_d = k * sg + c * dd * sg * (1.0 - sg) / s
    return out, slope_d * d_d + (c * sg) * d_dd + (s * sp) * d_k + (dd * sg) * d_c


def mesh_deflections(lp: LumpedParameters, q: Coords) -> tuple[Array, Array]:
    """Rigid-geometry mesh deflections (m) of every planet's sun and ring mesh.

    Linear in `q` (docs/conventions.md, "Mesh deflection"), excitations not included::

        delta_sp_i = n_sp_i . (d_s - d_p_i) + rb_s (theta_s - theta_c) + rb_p (theta_p_i - theta_c)
        delta_rp_i = n_rp_i . (d_p_i - d_r) + rb_r (theta_r - theta_c) - rb_p (theta_p_i - theta_c)

    **Returns:** `(delta_sp, delta_rp)`, each shape (N,).
    """
    psi = lp.planet_angles
    er, et = unit_radial(psi), unit_tangential(psi)
    n_sp = unit_tangential(psi - lp.alpha_sp)
    n_rp = jnp.sin(lp.alpha_rp) * er - jnp.cos(lp.alpha_rp) * et
    d_p = q.carrier_xy[None, :] + q.zeta[:, None] * er + q.eta[:, None] * et
    rot_p = lp.rb_planet * (q.theta_p - q.theta_c)
    d_sp = (
        jnp.sum(n_sp * (q.sun_xy[None, :] - d_p), axis=-1)
        + lp.rb_sun * (q.theta_s - q.theta_c)
        + rot_p
    )
    d_rp = (
        jnp.sum(n_rp * (d_p - q.ring_xy[None, :]), axis=-1)
        + lp.rb_ring * (q.theta_r - q.theta_c)
        - rot_p
    )
    return d_sp, d_rp


def mesh_damping(lp: LumpedParameters) -> tuple[Array, Array]:
    """Mesh damping coefficients (N·s/m) from the damping ratios (docs/conventions.md).

    ``c = 2 zeta sqrt(k_mean m_e)``, ``m_e = m1 m2 / (m1 + m2)`` with ``m = J / rb^2``; the ring
    mesh uses ``m_e = J_p / rb_p^2`` (the ring, held by its supports, is far heavier).
    """
    ms = lp.J_sun / lp.rb_sun**2
    mp = lp.J_planet / lp.rb_planet**2
    me_sp = ms * mp / (ms + mp)
    c_sp = 2.0 * lp.zeta_sun_planet * jnp.sqrt(lp.k_sun_planet * me_sp)
    c_rp = 2.0 * lp.zeta_ring_planet * jnp.sqrt(lp.k_ring_planet * mp)
    return c_sp, c_rp


class Operators(eqx.Module):
    """Constant matrices of a solve: kinematic map `A` (q = A z), inverse reduced mass matrix
    `Mz_inv`, mesh deflection matrix `L` (2N × n_dof), and the parts' linear springs `K` (N/m,
    N·m/rad) and dampers `C` (N·s/m, N·m·s/rad) in the coordinates `q`; `W` and `B` combine
    them for `Twin.vector_field`."""

    A: Float[Array, "n n"]
    Mz_inv: Float[Array, "n n"]
    L: Float[Array, "m n"]
    K: Float[Array, "n n"]
    C: Float[Array, "n n"]
    # the same, fused for the vector field (two matrix products per evaluation instead of nine):
    # W = [A; L A] maps z (or z') to q and the rigid-geometry deflections (or their rates);
    # B = Mz_inv A^T [-L^T, I, -K A, -C A] maps (mesh forces, other generalised forces, z, z')
    # to z''
    W: Float[Array, "n+m n"]
    B: Float[Array, "n m+3n"]


class Twin(eqx.Module):
    """A planetary gearbox twin: lumped parameters plus parts, as one ODE.

    **Fields:**

    - `lp`: `LumpedParameters` (geometry, inertias, mean stiffness, damping ratios).
    - `parts`: tuple of `AbstractPart` (supports, faults, imperfections, drive, load, sensor…).
    - `kind`: ``"translational"`` (Lin & Parker, 3(N+3) DOF) or ``"torsional"`` (N+3 DOF).
    - `n_harmonics`: Fourier harmonics of the mesh-stiffness waveform.
    - `contact_smoothing`: length (m) over which one-sided contact is smoothed.
    """

    lp: LumpedParameters
    parts: tuple[AbstractPart, ...]
    kind: str = eqx.field(static=True, default="translational")
    n_harmonics: int = eqx.field(static=True, default=12)
    contact_smoothing: float = eqx.field(static=True, default=2e-8)

    def __check_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {self.kind!r}")

    # ----------------------------------------------------------------------------- layout
    @property
    def n_planets(self) -> int:
        return self.lp.n_planets

    @property
    def n_dof(self) -> int:
        n = self.n_planets
        return 3 * (n + 3) if self.kind == "translational" else n + 3

    @property
    def aux_sizes(self) -> tuple[int, ...]:
        return tuple(p.aux_size for p in self.parts)

    def pack(self, q: Coords) -> Float[Array, " n_dof"]:
        """Coordinates → flat vector (layout of this twin's `kind`)."""
        if self.kind == "torsional":
            return jnp.concatenate([jnp.stack([q.theta_s, q.theta_r, q.theta_c]), q.theta_p])
        per_planet = jnp.stack([q.zeta, q.eta, q.theta_p], axis=1).reshape(-1)
        return jnp.concatenate(
            [
                q.sun_xy, q.theta_s[None], q.ring_xy, q.theta_r[None],
                q.carrier_xy, q.theta_c[None], per_planet,
            ]
        )

    def unpack(self, v: Float[Array, " n_dof"]) -> Coords:
        """Flat vector → coordinates (translations zero in the torsional model)."""
        n = self.n_planets
        if self.kind == "torsional":
            z2 = jnp.zeros(2, dtype=v.dtype)
            zn = jnp.zeros(n, dtype=v.dtype)
            return Coords(z2, v[0], z2, v[1], z2, v[2], zn, zn, v[3:])
        pp = v[9:].reshape(n, 3)
        return Coords(v[0:2], v[2], v[3:5], v[5], v[6:8], v[8], pp[:, 0], pp[:, 1], pp[:, 2])

    def _index(self, name: str, i: int = 0) -> int:
        if self.kind == "torsional":
            return {"theta_s": 0, "theta_r": 1, "theta_c": 2}.get(name, 3 + i)
        return {"theta_s": 2, "theta_r": 5, "theta_c": 8}.get(name, 9 + 3 * i + 2)

    @property
    def kinematic_ratios(self) -> tuple[float, float]:
        """(sun, planet) absolute speed over carrier speed with the ring fixed."""
        lp = self.lp
        return 1.0 + lp.z_ring / lp.z_sun, 1.0 - lp.z_ring / lp.z_planet

    def kinematic_map(self) -> np.ndarray:
        """The constant matrix `A` with `q = A z` (integration coordinates, module docstring)."""
        a = np.eye(self.n_dof)
        rs, rp = self.kinematic_ratios
        ic = self._index("theta_c")
        a[self._index("theta_s"), ic] = rs
        for i in range(self.n_planets):
            a[self._index("theta_p", i), ic] = rp
        return a

    # ----------------------------------------------------------------------------- inertia
    def mass_matrix(self) -> Float[Array, "n_dof n_dof"]:
        """Mass matrix of the coordinates `q` (kg, kg·m², and kg·m couplings).

        Kinetic energy: central members ``m (x'^2 + y'^2)/2 + J theta'^2/2``; planet i
        ``m_p |v_i|^2 / 2 + J_p theta_p'^2/2`` with the carrier-frame velocity of its centre
        ``v_i = (x_c', y_c') + zeta_i' e_r + (eta_i' + a theta_c') e_t``.
        """
        lp, n = self.lp, self.n_planets
        psi = lp.planet_angles
        if self.kind == "torsional":
            diag = jnp.concatenate(
                [
                    jnp.stack([lp.J_sun, lp.J_ring, lp.J_carrier + n * lp.m_planet * lp.centre_distance**2]),
                    jnp.full((n,), lp.J_planet),
                ]
            )
            return jnp.diag(diag)
        nd = self.n_dof
        # B maps q' to "absolute" velocity components; M = B^T diag(masses) B.
        rows, masses = [], []

        def row(entries):
            r = jnp.zeros(nd)
            for idx, val in entries:
                r = r.at[idx].add(val)
            return r

        for base, m, J in ((0, lp.m_sun, lp.J_sun), (3, lp.m_ring, lp.J_ring), (6, lp.m_carrier, lp.J_carrier)):
            rows += [row([(base, 1.0)]), row([(base + 1, 1.0)]), row([(base + 2, 1.0)])]
            masses += [m, m, J]
        for i in range(n):
            b = 9 + 3 * i
            c, s = jnp.cos(psi[i]), jnp.sin(psi[i])
            rows.append(row([(6, c), (7, s), (b, 1.0)]))
            rows.append(row([(6, -s), (7, c), (b + 1, 1.0), (8, lp.centre_distance)]))
            rows.append(row([(b + 2, 1.0)]))
            masses += [lp.m_planet, lp.m_planet, lp.J_planet]
        B = jnp.stack(rows)
        return B.T @ (jnp.stack(masses)[:, None] * B)

    # ----------------------------------------------------------------------------- meshes
    def deflection_matrix(self) -> Float[Array, "2N n_dof"]:
        """The constant matrix `L` with ``[delta_sp; delta_rp] = L q`` (rigid-geometry part)."""
        n = self.n_planets

        def f(v):
            d_sp, d_rp = mesh_deflections(self.lp, self.unpack(v))
            return jnp.concatenate([d_sp, d_rp])

        return jax.jacfwd(f)(jnp.zeros(self.n_dof))[: 2 * n]

    def mesh_state(self, t, q: Coords, qdot: Coords, mod: Modulation, ops=None) -> MeshState:
        """Mesh phases, stiffness, deflections and contact forces (see `MeshState`).

        `ops` (from `operators()`) supplies the deflection matrix; without it, it is built.
        """
        L = self.deflection_matrix() if ops is None else ops.L
        return self._mesh_from_deflections(q, mod, L @ self.pack(q), L @ self.pack(qdot))

    def _mesh_from_deflections(self, q: Coords, mod: Modulation, d_rigid, dd_rigid) -> MeshState:
        """`mesh_state` from the rigid-geometry deflections ``L q`` and rates ``L q'`` (2N,)."""
        lp, n = self.lp, self.n_planets
        ph_sp, ph_rp = mesh_phases(lp, q.theta_s, q.theta_c, q.theta_r)
        ph = jnp.concatenate([ph_sp + mod.dphase_sp, ph_rp + mod.dphase_rp])
        k_mean = jnp.concatenate([jnp.full((n,), lp.k_sun_planet), jnp.full((n,), lp.k_ring_planet)])
        eps = jnp.concatenate([jnp.full((n,), lp.eps_sp), jnp.full((n,), lp.eps_rp)])
        k = mesh_stiffness_waveform(ph, k_mean, eps, n_harmonics=self.n_harmonics)
        # faults remove stiffness; a whole missing tooth in single contact can take the
        # Fourier-smoothed waveform slightly below zero: floor at 0 (no-op when healthy)
        k = jnp.maximum(k - jnp.concatenate([mod.dk_sp, mod.dk_rp]), 0.0)
        d = d_rigid - jnp.concatenate([mod.e_sp, mod.e_rp])
        dd = dd_rigid
        c_sp, c_rp = mesh_damping(lp)
        c = jnp.concatenate([jnp.full((n,), c_sp), jnp.full((n,), c_rp)])
        s = self.contact_smoothing
        force = contact_force(d, dd, k, c, s)
        return MeshState(
            ph[:n], ph[n:], k[:n], k[n:], c[:n], c[n:], d[:n], d[n:], dd[:n], dd[n:],
            force[:n], force[n:],
        )

    def mesh_forces(self, q: Coords, mesh: MeshState, ops=None) -> Float[Array, " n_dof"]:
        """Generalised forces of the mesh contact forces, ``-L^T F`` (virtual work), flat."""
        L = self.deflection_matrix() if ops is None else ops.L
        return -L.T @ jnp.concatenate([mesh.force_sp, mesh.force_rp])

    def frame_forces(self, q: Coords, qdot: Coords) -> Coords:
        """Coriolis and centripetal forces of translations in the carrier frame (N).

        ``-2 m Omega x (r')`` and ``m Omega^2 r`` with ``Omega = theta_c'``; planets' radius is
        ``a + zeta``. Zero in the torsional model.
        """
        lp = self.lp
        if self.kind == "torsional":
            return Coords.zeros(self.n_planets)
        w = qdot.theta_c

        def fict(m, r, v):
            return m * (w**2 * r + 2.0 * w * jnp.stack([v[1], -v[0]]))

        z0, zn = jnp.zeros(()), jnp.zeros(self.n_planets)
        mp = lp.m_planet
        f_zeta = mp * (w**2 * (lp.centre_distance + q.zeta) + 2.0 * w * qdot.eta)
        f_eta = mp * (w**2 * q.eta - 2.0 * w * qdot.zeta)
        return Coords(
            fict(lp.m_sun, q.sun_xy, qdot.sun_xy), z0, fict(lp.m_ring, q.ring_xy, qdot.ring_xy), z0,
            fict(lp.m_carrier, q.carrier_xy, qdot.carrier_xy), z0, f_zeta, f_eta, zn,
        )

    # ----------------------------------------------------------------------------- assembly
    def modulation(self, t, q: Coords, qdot: Coords) -> Modulation:
        mod = Modulation.zeros(self.n_planets)
        for p in self.parts:
            m = p.modulation(self, t, q, qdot)
            if m is not None:
                mod = mod + m
        return mod

    def split_aux(self, aux: Float[Array, " n_aux"]) -> list[Float[Array, " k"]]:
        out, i = [], 0
        for n in self.aux_sizes:
            out.append(aux[i : i + n])
            i += n
        return out

    def evaluate(self, t, q: Coords, qdot: Coords, aux: Float[Array, " n_aux"], ops=None):
        """All forces at one instant.

        **Returns:** `(F, aux_dot, mesh, outputs)`: total generalised force (flat, coordinates
        `q`), the parts' state derivatives, the `MeshState`, and named observables: the parts'
        plus the dissipated powers ``power_mesh_damping`` and ``power_support_damping`` (W).
        Linear springs and dampers of parts (`linear_springs`) are included.
        """
        ops = self.operators() if ops is None else ops
        mod = self.modulation(t, q, qdot)
        mesh = self.mesh_state(t, q, qdot, mod, ops)
        qv, qdv = self.pack(q), self.pack(qdot)
        F = self.mesh_forces(q, mesh, ops) - ops.K @ qv - ops.C @ qdv
        G, aux_dot, outputs = self.part_forces(t, q, qdot, aux, mesh, self.frame_forces(q, qdot))
        # dissipated power (W): mesh damping (contact-gated) and the linear support dampers
        s = self.contact_smoothing
        sig = jax.nn.sigmoid(jnp.concatenate([mesh.delta_sp, mesh.delta_rp]) / s)
        dd = jnp.concatenate([mesh.ddelta_sp, mesh.ddelta_rp])
        cc = jnp.concatenate([mesh.c_sp, mesh.c_rp])
        outputs["power_mesh_damping"] = jnp.sum(cc * sig * dd**2)
        outputs["power_support_damping"] = qdv @ (ops.C @ qdv)
        return F + self.pack(G), aux_dot, mesh, outputs

    def operators(self) -> Operators:
        """Constant matrices of one solve (see `Operators`), computed once."""
        A = jnp.asarray(self.kinematic_map())
        Mz = A.T @ self.mass_matrix() @ A
        K = jnp.zeros((self.n_dof, self.n_dof))
        C = jnp.zeros((self.n_dof, self.n_dof))
        for p in self.parts:
            springs = getattr(p, "linear_springs", None)
            if springs is not None:
                k, c = springs(self)
                K, C = K + k, C + c
        Mz_inv = jnp.linalg.inv(Mz)
        L = self.deflection_matrix()
        W = jnp.concatenate([A, L @ A])
        B = Mz_inv @ A.T @ jnp.concatenate([-L.T, jnp.eye(self.n_dof), -K @ A, -C @ A], axis=1)
        return Operators(A, Mz_inv, L, K, C, W, B)

    def accelerations(self, t, y, ops):
        """State derivative pieces: `(zdot, zddot, aux_dot, q, qdot, qddot, mesh, outputs)`
        with `y = (z, z', aux)`."""
        z, zdot, aux = y
        q, qdot = self.unpack(ops.A @ z), self.unpack(ops.A @ zdot)
        F, aux_dot, mesh, outputs = self.evaluate(t, q, qdot, aux, ops)
        zdd = ops.Mz_inv @ (ops.A.T @ F)
        return zdot, zdd, aux_dot, q, qdot, self.unpack(ops.A @ zdd), mesh, outputs

    def vector_field(self, t, y, ops):
        """Vector field of `y = (z, z', aux)`: `(z', z'', aux')`.

        The same forces as `accelerations` (to rounding), with the constant matrices fused
        (`Operators.W`, `Operators.B`): on a CPU the cost of an evaluation is mostly the number
        of separate operations, not arithmetic.
        """
        z, zdot, aux = y
        n = self.n_dof
        X = ops.W @ jnp.stack([z, zdot], axis=1)
        F, aux_dot = self.generalised_forces(t, X[:n, 0], X[:n, 1], X[n:, 0], X[n:, 1], aux)
        zdd = ops.B @ jnp.concatenate([F, z, zdot])
        return zdot, zdd, aux_dot

    def generalised_forces(self, t, qv, qdv, d_rigid, dd_rigid, aux):
        """The nonlinear forces of `vector_field`, from flat coordinates `qv`, velocities `qdv`
        and the rigid-geometry mesh deflections ``L q`` and their rates ``L q'`` (2N,).

        **Returns:** `(F, aux_dot)`: ``F = [mesh contact forces (2N, N); parts' and
        rotating-frame generalised forces (flat, coordinates q)]`` (the parts' linear springs and
        dampers are not included: `Operators.B` applies them) and the parts' state derivatives.
        """
        q, qdot = self.unpack(qv), self.unpack(qdv)
        mod = self.modulation(t, q, qdot)
        mesh = self._mesh_from_deflections(q, mod, d_rigid, dd_rigid)
        G, aux_dot, _ = self.part_forces(t, q, qdot, aux, mesh)
        Gv = self.pack(G) + self._frame_forces_flat(qv, qdv)
        return jnp.concatenate([mesh.force_sp, mesh.force_rp, Gv]), aux_dot

    def part_forces(self, t, q, qdot, aux, mesh, G=None):
        """The parts' generalised forces (`Coords`, N and N·m) added to `G` (default zero) in
        the parts' order, their state derivatives (flat) and their named outputs, at `t` (s)
        with coordinates `q`, velocities `qdot`, the parts' states `aux` and the `MeshState`.

        **Returns:** `(G, aux_dot, outputs)`."""
        G = Coords.zeros(self.n_planets) if G is None else G
        aux_dots, outputs = [], {}
        for p, a in zip(self.parts, self.split_aux(aux), strict=True):
            f, ad, out = p.forces(self, t, q, qdot, a, mesh)
            if f is not None:
                G = G + f
            aux_dots.append(jnp.asarray(ad).reshape(p.aux_size))
            outputs.update(out)
        return G, (jnp.concatenate(aux_dots) if aux_dots else jnp.zeros(0)), outputs

    def _frame_forces_flat(self, qv, qdv):
        """`frame_forces` on flat vectors, vectorised over the bodies (one fused operation
        instead of one per body): ``m (W^2 r + 2 W J r')`` per body, ``J (x, y) = (y, -x)``, and
        ``m_p W^2 a`` on every planet's zeta."""
        if self.kind == "torsional":
            return jnp.zeros_like(qv)
        lp, n = self.lp, self.n_planets
        w = qdv[self._index("theta_c")]
        v = qdv.reshape(-1, 3)  # (body, [x or zeta, y or eta, rotation])
        perp = jnp.stack([v[:, 1], -v[:, 0], jnp.zeros_like(v[:, 0])], axis=1).reshape(-1)
        zn, z0 = jnp.zeros(n), jnp.zeros(())
        mass = self.pack(Coords(jnp.full(2, lp.m_sun), z0, jnp.full(2, lp.m_ring), z0,
                                jnp.full(2, lp.m_carrier), z0, jnp.full(n, lp.m_planet),
                                jnp.full(n, lp.m_planet), zn))
        pin = self.pack(Coords.zeros(n).set(zeta=jnp.full(n, lp.m_planet * lp.centre_distance)))
        return mass * (w**2 * qv + 2.0 * w * perp) + w**2 * pin

    # ----------------------------------------------------------------------------- helpers
    def with_parts(self, *parts: AbstractPart) -> Twin:
        """A twin with further parts appended (no edit of the assembly code)."""
        return eqx.tree_at(lambda tw: tw.parts, self, self.parts + tuple(parts))

    def find(self, cls: type) -> list[AbstractPart]:
        """The parts that are instances of `cls`."""
        return [p for p in self.parts if isinstance(p, cls)]

    def linear_stiffness(self, modal: bool = True) -> Float[Array, "n_dof n_dof"]:
        """Stiffness matrix of the coordinates `q` at mean mesh stiffness, no load, linear contact.

        The Jacobian of minus the generalised forces of the meshes (at their mean stiffness,
        contact taken as linear) and of the parts' springs, at rest. With `modal=True` the
        torsional supports of sun and carrier (shafts to ground) are included. The modal analysis of this
        matrix with `mass_matrix()` is the twin's own; it must agree with `dtwin.model.modal`.
        """
        lp = self.lp
        zero = Coords.zeros(self.n_planets)

        def forces(v):
            q = self.unpack(v)
            d_sp, d_rp = mesh_deflections(lp, q)
            _, vjp = jax.vjp(lambda x: mesh_deflections(lp, x), q)
            (f,) = vjp((-lp.k_sun_planet * d_sp, -lp.k_ring_planet * d_rp))
            return self.pack(f)

        K = -jax.jacfwd(forces)(self.pack(zero))
        for p in self.parts:
            springs = getattr(p, "linear_springs", None)
            if modal:
                springs = getattr(p, "modal_springs", None) or springs
            if springs is not None:
                K = K + springs(self)[0]
        return K
