"""An independent NumPy implementation of the twin's equations of motion (benchmark and check).

Written from docs/conventions.md and the docstrings of `dtwin/model/twin.py`, `dtwin/simulation/simulate.py`,
`dtwin/model/faults.py`, `dtwin/model/stiffness.py` and `dtwin/model/parts/*.py`, *not* by calling dtwin's JAX
functions: only the numbers are taken from a built twin (`tw.lp` converted to floats, the parts'
parameters), so that both sides solve the same problem. Supported parts — those of
``build_twin(preset("paper-sim"))`` plus sun faults:

- `Supports` (bearings, ring torsional support, ``c = 2 zeta_support sqrt(k m)``);
- `DrivePart(IdealSpeedSource)` with a constant speed set point and its `Shaft`;
- `LoadPart(ConstantLoad)` on the carrier (``T tanh(omega_c / engage_speed)``);
- `LocalFault(MissingTooth(location="sun"))`, any tooth and severity;
- `PlanetPassTransferPath` (sensor acceleration).

Any other part raises `NotImplementedError` rather than being silently ignored.

**Equations** (translational model, 3(N+3) DOF; the torsional reduction keeps the rotations):

- Generalised coordinates ``q`` (docs/conventions.md): central members ``x, y`` in the carrier
  frame and absolute rotation; planet ``zeta, eta`` relative to its pin and absolute rotation.
  Integration coordinates ``z`` with ``q = A z``: ``theta_s = (1 + Zr/Zs) theta_c + z_s``,
  ``theta_p = (1 - Zr/Zp) theta_c + z_p``, every other coordinate unchanged.
- Mass matrix ``M = B^T diag(m) B`` from the kinetic energy with the planet centre velocity
  ``(x_c', y_c') + zeta' e_r + (eta' + a theta_c') e_t``; torsional: ``diag(J_s, J_r,
  J_c + N m_p a^2, J_p...)``. ``(A^T M A) z'' = A^T F``.
- Mesh deflections ``delta = L q - e`` with ``L`` written out by hand from the deflection
  formulas of docs/conventions.md; forces ``F = k s softplus(delta/s) + c delta' sigmoid(delta/s)``
  along the lines of action, generalised forces ``-L^T F`` (virtual work).
- Stiffness: Lanczos-smoothed Fourier series of the single/double contact wave (``c'``,
  ``1.75 c'``), minus the sun fault's ``severity c' box(u)`` with ``u`` the cycles since the
  faulty tooth entered contact (sigmoid edges 0.05 cycles), floored at 0 as
  `dtwin.model.faults.mesh_stiffnesses` documents.
- Rotating-frame forces on translations: ``m (W^2 r + 2 W (v_y, -v_x))`` for the central members
  (their own mass), ``m_p (W^2 (a + zeta) + 2 W eta')`` radial and ``m_p (W^2 eta - 2 W zeta')``
  tangential for the planets, ``W = theta_c'`` (twin.py `frame_forces`).
- Drive: rotor angle ``theta_m' = omega_ref``, torque on the sun
  ``k_shaft (theta_m - theta_s) + c_shaft (omega_ref - theta_s')``.
- Sensor (m/s², along the sensor direction ``d``): the ring's fixed-frame acceleration
  ``R(theta_c) [r'' + 2 W J r' - W^2 r + W' J r] . d`` plus the high-passed windowed force
  ``s - z1``, ``s = sum_i w_i F_rp_i / m_ring``, ``w_i = ((1 + cos(theta_c + psi_i -
  sensor_angle)) / 2)^p``, with the path's own states ``z1' = z2``,
  ``z2' = wc^2 (s - z1) - sqrt(2) wc z2`` (second-order Butterworth low-pass at `highpass_hz`).

**State.** `rhs(t, y)` works on the flat *scaled* state of `dtwin.simulation.simulate._solve`,
``y = [z / sz, z' / sv, aux]`` (scales of `dtwin.simulation.simulate.state_scales`, recomputed here:
translations 1e-6 m, a gear's rotation deviation 1e-6 m / its base radius, carrier angle 1 rad;
rates ``2 pi RATE_SCALE_HZ`` times those, carrier rate 10 rad/s), for `scipy.integrate.solve_ivp`.
`rhs_unscaled(t, z, zd, aux)` returns ``(z', z'', aux')`` in the unscaled ``(z, z', aux)`` of
`dtwin.model.twin.Twin.vector_field`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import expit

RATE_SCALE_HZ = 10_000.0  # dtwin.simulation.simulate.SolverOptions.rate_scale_hz default
WINDOW_EDGE = 0.05  # mesh cycles, edge width of a fault's contact window (dtwin.model.faults)
DOUBLE_CONTACT_FACTOR = 1.75  # ISO 6336-1: double contact stiffness over single-pair c'


def _f(x) -> float:
    return float(np.asarray(x))


def _softplus(x):
    return np.logaddexp(0.0, x)


class ReferenceModel:
    """The twin's equations in NumPy, with the numbers of a built `dtwin.model.twin.Twin`.

    **Arguments:** `twin`: a `Twin` built from parts this module supports (module docstring).

    Attributes of interest: `n_dof`, `n_aux`, `n_state` (flat state size), `sz`, `sv` (state
    scales), `M` (mass matrix of `q`), `A` (kinematic map), `L` (deflection matrix, 2N × n_dof),
    `K`, `C` (support stiffness and damping matrices of `q`).
    """

    def __init__(self, twin):
        from dtwin.model.faults import MissingTooth
        from dtwin.model.motor.drive import DrivePart, LoadPart
        from dtwin.model.motor.loads import ConstantLoad
        from dtwin.model.motor.speed_source import IdealSpeedSource
        from dtwin.model.parts.local_fault import LocalFault
        from dtwin.model.parts.supports import Supports
        from dtwin.model.parts.transfer_path import PlanetPassTransferPath

        lp = twin.lp
        self.kind = twin.kind
        self.translational = twin.kind == "translational"
        self.n = int(lp.n_planets)
        self.zs, self.zp, self.zr = int(lp.z_sun), int(lp.z_planet), int(lp.z_ring)
        self.psi = np.asarray(lp.planet_angles, dtype=np.float64)
        for name in (
            "rb_sun", "rb_planet", "rb_ring", "centre_distance", "alpha_sp", "alpha_rp",
            "eps_sp", "eps_rp", "phase0_sp", "phase0_rp", "m_sun", "m_ring", "m_carrier",
            "m_planet", "J_sun", "J_ring", "J_carrier", "J_planet", "k_sun_planet",
            "k_ring_planet", "k_bearing_sun", "k_bearing_ring", "k_bearing_carrier",
            "k_bearing_planet", "k_torsion_ring", "zeta_sun_planet", "zeta_ring_planet",
            "zeta_support",
        ):
            setattr(self, name, _f(getattr(lp, name)))
        self.n_harmonics = int(twin.n_harmonics)
        self.smoothing = float(twin.contact_smoothing)

        # ---- parts
        self.has_supports = False
        self.drive = None  # (omega_ref, k_shaft, c_shaft)
        self.load = None  # (torque, engage_speed)
        self.sun_faults = []  # (tooth, severity)
        self.sensor = None  # (sensor_angle, direction_angle, exponent, ring_w, force_w)
        aux_sizes = []
        for p in twin.parts:
            if isinstance(p, Supports):
                self.has_supports = True
            elif isinstance(p, DrivePart) and isinstance(p.drive, IdealSpeedSource):
                sp = p.drive.speed
                if sp.kind != "constant":
                    raise NotImplementedError("reference model: only a constant speed set point")
                self.drive = (_f(sp.final), _f(p.drive.shaft.k_shaft), _f(p.drive.shaft.c_shaft))
            elif isinstance(p, LoadPart) and isinstance(p.load, ConstantLoad):
                self.load = (_f(p.load.torque_value), _f(p.load.engage_speed))
            elif (isinstance(p, LocalFault) and isinstance(p.fault, MissingTooth)
                  and p.fault.location == "sun"):
                self.sun_faults.append((int(p.fault.tooth), _f(p.fault.severity)))
            elif isinstance(p, PlanetPassTransferPath):
                if self.sensor is not None:
                    raise NotImplementedError("reference model: one transfer path only")
                self.sensor = tuple(_f(v) for v in (p.sensor_angle, p.direction_angle,
                                                    p.window_exponent, p.ring_weight,
                                                    p.force_weight))
                self.highpass_hz = _f(p.highpass_hz)
            else:
                raise NotImplementedError(f"reference model: part {type(p).__name__} "
                                          f"({getattr(p, 'drive', getattr(p, 'load', ''))!r:.60}) "
                                          "is not implemented")
            aux_sizes.append(p.aux_size)
        self.aux_sizes = aux_sizes
        self.n_aux = sum(aux_sizes)
        # index of the drive's rotor angle and of the transfer path's filter states in aux
        self.i_motor = self.i_path = None
        i = 0
        for p, s in zip(twin.parts, aux_sizes, strict=True):
            if isinstance(p, DrivePart):
                self.i_motor = i
            if isinstance(p, PlanetPassTransferPath):
                self.i_path = i
            i += s

        self._layout()
        self._operators()
        self._stiffness_coefficients()
        self._scales()

    # ------------------------------------------------------------------------ layout
    def _layout(self):
        n = self.n
        if self.translational:
            self.n_dof = 3 * (n + 3)
            self.i_sxy, self.i_ts = [0, 1], 2
            self.i_rxy, self.i_tr = [3, 4], 5
            self.i_cxy, self.i_tc = [6, 7], 8
            self.i_zeta = np.array([9 + 3 * i for i in range(n)])
            self.i_eta = self.i_zeta + 1
            self.i_tp = self.i_zeta + 2
        else:
            self.n_dof = n + 3
            self.i_ts, self.i_tr, self.i_tc = 0, 1, 2
            self.i_tp = np.arange(3, 3 + n)
        self.n_state = 2 * self.n_dof + self.n_aux

    # ------------------------------------------------------------------------ matrices
    def _operators(self):
        n, nd = self.n, self.n_dof
        psi, a = self.psi, self.centre_distance
        # kinematic map q = A z
        A = np.eye(nd)
        A[self.i_ts, self.i_tc] = 1.0 + self.zr / self.zs
        A[self.i_tp, self.i_tc] = 1.0 - self.zr / self.zp
        self.A = A

        # mass matrix from the kinetic energy
        if self.translational:
            rows, masses = [], []
            for ixy, it, m, J in ((self.i_sxy, self.i_ts, self.m_sun, self.J_sun),
                                  (self.i_rxy, self.i_tr, self.m_ring, self.J_ring),
                                  (self.i_cxy, self.i_tc, self.m_carrier, self.J_carrier)):
                for j, mass in ((ixy[0], m), (ixy[1], m), (it, J)):
                    r = np.zeros(nd)
                    r[j] = 1.0
                    rows.append(r)
                    masses.append(mass)
            for i in range(n):
                c, s = math.cos(psi[i]), math.sin(psi[i])
                # radial velocity: x_c' cos + y_c' sin + zeta'
                r = np.zeros(nd)
                r[self.i_cxy[0]], r[self.i_cxy[1]], r[self.i_zeta[i]] = c, s, 1.0
                rows.append(r)
                masses.append(self.m_planet)
                # tangential velocity: -x_c' sin + y_c' cos + eta' + a theta_c'
                r = np.zeros(nd)
                r[self.i_cxy[0]], r[self.i_cxy[1]] = -s, c
                r[self.i_eta[i]], r[self.i_tc] = 1.0, a
                rows.append(r)
                masses.append(self.m_planet)
                r = np.zeros(nd)
                r[self.i_tp[i]] = 1.0
                rows.append(r)
                masses.append(self.J_planet)
            B = np.array(rows)
            M = B.T @ (np.array(masses)[:, None] * B)
        else:
            M = np.diag([self.J_sun, self.J_ring, self.J_carrier + n * self.m_planet * a**2]
                        + [self.J_planet] * n)
        self.M = M

        # deflection matrix, written out from the deflection formulas
        L = np.zeros((2 * n, nd))
        rbs, rbp, rbr = self.rb_sun, self.rb_planet, self.rb_ring
        for i in range(n):
            er = np.array([math.cos(psi[i]), math.sin(psi[i])])
            et = np.array([-math.sin(psi[i]), math.cos(psi[i])])
            n_sp = np.array([-math.sin(psi[i] - self.alpha_sp), math.cos(psi[i] - self.alpha_sp)])
            n_rp = math.sin(self.alpha_rp) * er - math.cos(self.alpha_rp) * et
            # sun mesh: n_sp.(d_s - d_p) + rb_s (th_s - th_c) + rb_p (th_p - th_c)
            L[i, self.i_ts] += rbs
            L[i, self.i_tc] -= rbs + rbp
            L[i, self.i_tp[i]] += rbp
            # ring mesh: n_rp.(d_p - d_r) + rb_r (th_r - th_c) - rb_p (th_p - th_c)
            j = n + i
            L[j, self.i_tr] += rbr
            L[j, self.i_tc] += -rbr + rbp
            L[j, self.i_tp[i]] -= rbp
            if self.translational:
                L[i, self.i_sxy] += n_sp
                L[i, self.i_cxy] -= n_sp
                L[i, self.i_zeta[i]] -= n_sp @ er
                L[i, self.i_eta[i]] -= n_sp @ et
                # the planet pushes the ring along n_rp: n_rp.(d_p - d_r)
                L[j, self.i_rxy] -= n_rp
                L[j, self.i_cxy] += n_rp
                L[j, self.i_zeta[i]] += n_rp @ er
                L[j, self.i_eta[i]] += n_rp @ et
        self.L = L

        # supports (linear springs and dampers to the housing)
        K = np.zeros((nd, nd))
        C = np.zeros((nd, nd))
        if self.has_supports:
            zs = self.zeta_support

            def add(idx, k, m):
                K[idx, idx] += k
                C[idx, idx] += 2.0 * zs * math.sqrt(k * m)

            add(self.i_tr, self.k_torsion_ring, self.J_ring)
            if self.translational:
                mc_eff = self.m_carrier + n * self.m_planet
                for j in self.i_sxy:
                    add(j, self.k_bearing_sun, self.m_sun)
                for j in self.i_rxy:
                    add(j, self.k_bearing_ring, self.m_ring)
                for j in self.i_cxy:
                    add(j, self.k_bearing_carrier, mc_eff)
                for j in list(self.i_zeta) + list(self.i_eta):
                    add(j, self.k_bearing_planet, self.m_planet)
        self.K, self.C = K, C

        # mesh damping (docs/conventions.md "Damping")
        ms = self.J_sun / rbs**2
        mp = self.J_planet / rbp**2
        c_sp = 2.0 * self.zeta_sun_planet * math.sqrt(self.k_sun_planet * ms * mp / (ms + mp))
        c_rp = 2.0 * self.zeta_ring_planet * math.sqrt(self.k_ring_planet * mp)
        self.c_mesh = np.concatenate([np.full(n, c_sp), np.full(n, c_rp)])

        # z'' = P F with P = (A^T M A)^-1 A^T ; forces of the linear springs folded in z
        Mz = A.T @ M @ A
        self.P = np.linalg.solve(Mz, A.T)
        self.Kz = K @ A  # support force -K q = -K A z
        self.Cz = C @ A
        self.Lz = L @ A

    def _stiffness_coefficients(self):
        """Fourier coefficients of the single/double contact wave of every mesh."""
        n, M = self.n, self.n_harmonics
        h = np.arange(1, M + 1, dtype=np.float64)
        sigma = np.sinc(h / (M + 1))  # numpy's sinc is sin(pi x) / (pi x)
        self.harmonics = h
        k_mean = np.concatenate([np.full(n, self.k_sun_planet), np.full(n, self.k_ring_planet)])
        eps = np.concatenate([np.full(n, self.eps_sp), np.full(n, self.eps_rp)])
        c1 = k_mean / (0.75 * eps + 0.25)
        d = eps - 1.0
        # k = k_mean + (1.75 - 1) c' sum_n sigma_n 2 sin(n pi d)/(n pi) cos(2 pi n (phi - d/2))
        self.k_mean = k_mean
        self.c_single = c1
        self.wave_amp = ((DOUBLE_CONTACT_FACTOR - 1.0) * c1[:, None] * sigma[None, :]
                         * 2.0 * np.sin(np.pi * h[None, :] * d[:, None]) / (np.pi * h[None, :]))
        self.wave_shift = 0.5 * d  # cycles
        self.c1_sp = self.k_sun_planet / (0.75 * self.eps_sp + 0.25)

    def _scales(self):
        nd = self.n_dof
        sz = np.full(nd, 1e-6)
        sz[self.i_ts] = 1e-6 / self.rb_sun
        sz[self.i_tr] = 1e-6 / self.rb_ring
        for j in self.i_tp:
            sz[j] = 1e-6 / self.rb_planet
        sz[self.i_tc] = 1.0
        sv = sz * 2.0 * np.pi * RATE_SCALE_HZ
        sv[self.i_tc] = 10.0
        self.sz, self.sv = sz, sv

    # ------------------------------------------------------------------------ physics
    def mesh_phases(self, theta_s, theta_c, theta_r):
        """Sun and ring mesh phases of every planet (cycles), docs/conventions.md."""
        two_pi = 2.0 * np.pi
        ph_sp = self.zs * (theta_s - theta_c - self.psi) / two_pi + self.phase0_sp
        ph_rp = self.zr * (theta_c - theta_r + self.psi) / two_pi + self.phase0_rp
        return ph_sp, ph_rp

    def mesh_stiffness(self, ph_sp, ph_rp):
        """Stiffness of the 2N meshes (N/m): healthy wave minus the sun faults' loss, floored at 0."""
        ph = np.concatenate([ph_sp, ph_rp])
        arg = (2.0 * np.pi) * (ph - self.wave_shift)[:, None] * self.harmonics[None, :]
        k = self.k_mean + np.sum(self.wave_amp * np.cos(arg), axis=1)
        if self.sun_faults:
            eps = self.eps_sp
            half = 0.5 * self.zs
            dk = np.zeros(self.n)
            for tooth, severity in self.sun_faults:
                # cycles since sun tooth `tooth` entered contact with each planet
                u = np.mod(ph_sp - tooth - 0.5 * eps + half, self.zs) - half + 0.5 * eps
                box = expit(u / WINDOW_EDGE) * expit((eps - u) / WINDOW_EDGE)
                dk += self.c1_sp * box * severity
            k[: self.n] = np.maximum(k[: self.n] - dk, 0.0)
        return k

    def _forces(self, t, z, zd, aux):
        """Generalised force A^T-ready (coordinates q), aux', and the pieces the sensor needs."""
        q = self.A @ z
        qd = self.A @ zd
        ts, tr, tc = q[self.i_ts], q[self.i_tr], q[self.i_tc]
        ph_sp, ph_rp = self.mesh_phases(ts, tc, tr)
        k = self.mesh_stiffness(ph_sp, ph_rp)
        delta = self.Lz @ z
        ddelta = self.Lz @ zd
        s = self.smoothing
        x = delta / s
        f_mesh = k * s * _softplus(x) + self.c_mesh * ddelta * expit(x)
        F = -self.L.T @ f_mesh - self.Kz @ z - self.Cz @ zd
        w = qd[self.i_tc]
        if self.translational:
            w2 = w * w
            for ixy, m in ((self.i_sxy, self.m_sun), (self.i_rxy, self.m_ring),
                           (self.i_cxy, self.m_carrier)):
                r, v = q[ixy], qd[ixy]
                F[ixy[0]] += m * (w2 * r[0] + 2.0 * w * v[1])
                F[ixy[1]] += m * (w2 * r[1] - 2.0 * w * v[0])
            mp, a = self.m_planet, self.centre_distance
            zeta, eta = q[self.i_zeta], q[self.i_eta]
            dzeta, deta = qd[self.i_zeta], qd[self.i_eta]
            F[self.i_zeta] += mp * (w2 * (a + zeta) + 2.0 * w * deta)
            F[self.i_eta] += mp * (w2 * eta - 2.0 * w * dzeta)
        aux_dot = np.zeros(self.n_aux)
        if self.drive is not None:
            omega_ref, k_sh, c_sh = self.drive
            theta_m = aux[self.i_motor]
            F[self.i_ts] += k_sh * (theta_m - ts) + c_sh * (omega_ref - qd[self.i_ts])
            aux_dot[self.i_motor] = omega_ref
        if self.load is not None:
            torque, engage = self.load
            F[self.i_tc] -= torque * (np.tanh(w / engage) if engage > 0.0 else 1.0)
        if self.sensor is not None:
            # second-order Butterworth low-pass of the windowed force; the sensor sees s - z1
            wc = 2.0 * np.pi * self.highpass_hz
            z1, z2 = aux[self.i_path], aux[self.i_path + 1]
            s_force = self.windowed_force(tc, f_mesh)
            aux_dot[self.i_path] = z2
            aux_dot[self.i_path + 1] = wc * wc * (s_force - z1) - math.sqrt(2.0) * wc * z2
        return F, aux_dot, q, qd, f_mesh

    def windowed_force(self, theta_c, f_mesh):
        """``sum_i w_i F_rp_i / m_ring`` (m/s²), ``w_i = ((1 + cos phi_i)/2)^p``."""
        sensor_angle, _, p, _, _ = self.sensor
        window = (0.5 * (1.0 + np.cos(theta_c + self.psi - sensor_angle))) ** p
        return np.sum(window * f_mesh[self.n :]) / self.m_ring

    def rhs_unscaled(self, t, z, zd, aux):
        """``(z', z'', aux')`` of the unscaled state (as `Twin.vector_field`)."""
        F, aux_dot, *_ = self._forces(t, z, zd, aux)
        return zd, self.P @ F, aux_dot

    def _split(self, y):
        nd = self.n_dof
        return y[:nd] * self.sz, y[nd : 2 * nd] * self.sv, y[2 * nd :]

    def rhs(self, t, y):
        """Right-hand side of the flat scaled state ``[z/sz, z'/sv, aux]`` (module docstring)."""
        z, zd, aux = self._split(y)
        F, aux_dot, *_ = self._forces(t, z, zd, aux)
        return np.concatenate([zd / self.sz, (self.P @ F) / self.sv, aux_dot])

    def scale(self, z, zd, aux):
        """Unscaled ``(z, z', aux)`` → flat scaled state."""
        return np.concatenate([np.asarray(z) / self.sz, np.asarray(zd) / self.sv,
                               np.asarray(aux, dtype=np.float64).reshape(-1)])

    def sensor_acceleration(self, t, y):
        """Sensor signal (m/s²) at the flat scaled state `y` (module docstring)."""
        if self.sensor is None:
            raise ValueError("the twin has no PlanetPassTransferPath")
        z, zd, aux = self._split(y)
        F, _, q, qd, f_mesh = self._forces(t, z, zd, aux)
        qdd = self.A @ (self.P @ F)
        _, direction, _, w_ring, w_force = self.sensor
        d = np.array([math.cos(direction), math.sin(direction)])
        tc = q[self.i_tc]
        acc = 0.0
        if self.translational:
            w, wd = qd[self.i_tc], qdd[self.i_tc]
            r, rd, rdd = q[self.i_rxy], qd[self.i_rxy], qdd[self.i_rxy]
            perp_rd = np.array([-rd[1], rd[0]])
            perp_r = np.array([-r[1], r[0]])
            a_rot = rdd + 2.0 * w * perp_rd - w * w * r + wd * perp_r
            c, s = math.cos(tc), math.sin(tc)
            a_fix = np.array([c * a_rot[0] - s * a_rot[1], s * a_rot[0] + c * a_rot[1]])
            acc += w_ring * (a_fix @ d)
        acc += w_force * (self.windowed_force(tc, f_mesh) - aux[self.i_path])
        return acc

    def sensor_along(self, ts, ys):
        """Sensor signal at the columns of `ys` (flat scaled states, shape (n_state, len(ts)))."""
        return np.array([self.sensor_acceleration(t, ys[:, j]) for j, t in enumerate(ts)])

    # ------------------------------------------------------------------------ modes
    def natural_frequencies(self):
        """Undamped natural frequencies (Hz) of the coordinates ``q`` at mean mesh stiffness,
        linear contact, zero speed (supports as in the time simulation: no sun/carrier torsion)."""
        import scipy.linalg

        Km = np.concatenate([np.full(self.n, self.k_sun_planet),
                             np.full(self.n, self.k_ring_planet)])
        K = self.L.T @ (Km[:, None] * self.L) + self.K
        lam = scipy.linalg.eigh(K, self.M, eigvals_only=True)
        return np.sqrt(np.clip(lam, 0.0, None)) / (2.0 * np.pi)
