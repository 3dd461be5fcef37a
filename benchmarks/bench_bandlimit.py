"""Benchmark: a band-limited twin (modal truncation with static correction) and an implicit
solver against the full twin, for a 5 kHz record (issue #21, lever 1). Measured, not adopted.

The record: the paper's gearbox (``build_twin(preset("paper-sim"))``, torsional twin as the
fits use it, sun missing tooth 0.5, ideal speed source 30 Hz, acceleration sensor through the
planet-pass transfer path), `--duration` s at 5 kHz, no noise, `rtol = atol = --rtol` (the
fit benchmark's 1e-4). Three models:

- **full**: `dtwin.simulate`'s solve (unrolled Tsit5, PI control), as every command runs it.
- **condensed, n kept** (`--kept`; with every mode kept, 6 for the torsional twin, it is the
  full twin in modal coordinates: the control of the code): the modes of the linearised twin (mean mesh stiffness,
  `Twin.linear_stiffness(modal=False)` plus the drive shaft's stiffness, coordinates `z` of
  `dtwin.model.twin`) split into the `n` lowest, integrated (Tsit5, same controller), and the others,
  given their quasi-static response (modal truncation with a static correction: Craig, Structural
  Dynamics, 1981; the "mode-acceleration" idea of Cornwell, Craig & Johnson 1983)::

      z = z_ref(t) + Φ_k η + Φ_t ξ,   η'' = M_kk⁻¹ Φ_kᵀ F_z(t, z, z', aux),   0 = Φ_tᵀ F_z(...)

  with ``z_ref = z_static + e_c (θ0 + ω_c t)`` (rigid rotation at the nominal carrier speed
  plus the static deflection: a change of coordinates, ``z_ref'' = 0``). The mesh forces stay
  nonlinear and time-varying: per evaluation the stiffness ``k(t)`` is computed once, ξ comes
  from one Newton step of the static balance with the contact slope ``k σ(δ/s)`` (exact while
  the contact is closed), and the contact forces, parts' forces and the sensor are evaluated on
  the reconstructed displacement. The basis is stop-gradient (a choice of coordinates).
- **implicit** (`--implicit-span` s): ``diffrax.Kvaerno5`` on the full twin, its default root
  finder (chord iterations at the controller's tolerances), same controller settings.

Figures: compile time (first − second call, cache off unless `--cache`), CPU and wall time of
the compiled run, accepted steps per simulated second, the rms difference of the sensor signal
to the full twin's (of its rms), and per line family the largest level difference (dB) to the
full twin over the lines within 40 dB and within 40–60 dB of the strongest line below 2 kHz:
``h fm + k fc`` (h = 1…4, |k| ≤ 8), the sun fault's sidebands ``h fm + k fc + m f_sf``
(h = 0…4, k ∈ {0, ±3}, 0 < |m| ≤ 4, f_sf = 3 (f_sun − fc)), and ``m · 3 fc`` (m = 1…12).
Amplitudes by a Hann-windowed DFT at the exact line frequencies. `--diagnose` also integrates
the full twin tightly (rtol 1e-8, 0.2 s) and reconstructs the ring-mesh forces from its exact
states through the static correction: the error of the condensation alone, without the
integration of the kept modes.

Usage: ``python benchmarks/bench_bandlimit.py [--duration 4] [--rtol 1e-4] [--kept 2 4 5 6]
[--implicit-span 0.25] [--diagnose] [--cache] [--quick] [--json]``
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np
from _timing import load_average, timed  # noqa: E402


def say(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


# ------------------------------------------------------------------ the condensed twin
def _condensation_code():
    """The prototype, defined after JAX is configured (float64)."""
    import diffrax
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from dtwin.model.twin import contact_force
    from dtwin.simulation.simulate import _observe, state_scales

    def parts_forces(twin, t, q, qdot, aux, mesh):
        G, aux_dot, _ = twin.part_forces(t, q, qdot, aux, mesh)
        return twin.pack(G), aux_dot

    def stiffness_z(twin, z0, zd0, aux0):
        """Aᵀ (K_mesh,mean + K_springs + K_parts) A, K_parts = −∂(parts' forces)/∂q at y0."""
        A = jnp.asarray(twin.kinematic_map())
        ops = twin.operators()
        qd = twin.unpack(A @ zd0)

        def g(qv):
            q = twin.unpack(qv)
            t = jnp.zeros(())
            mesh = twin.mesh_state(t, q, qd, twin.modulation(t, q, qd), ops)
            return parts_forces(twin, t, q, qd, aux0, mesh)[0] + twin._frame_forces_flat(qv, A @ zd0)

        Kz = A.T @ (twin.linear_stiffness(modal=False) - jax.jacfwd(g)(A @ z0)) @ A
        return 0.5 * (Kz + Kz.T)

    def modes(twin, z0, zd0, aux0):
        """Frequencies (Hz) and mass-normalised modes (columns) in the coordinates z."""
        A = jnp.asarray(twin.kinematic_map())
        Mz = A.T @ twin.mass_matrix() @ A
        Kz = stiffness_z(twin, z0, zd0, aux0)
        Li = jax.scipy.linalg.solve_triangular(jnp.linalg.cholesky(Mz), jnp.eye(Mz.shape[0]),
                                               lower=True)
        w2, V = jnp.linalg.eigh(Li @ Kz @ Li.T)
        return jnp.sqrt(jnp.maximum(w2, 0.0)) / (2 * jnp.pi), Li.T @ V

    class Condensation(eqx.Module):
        Phi_k: jax.Array
        Phi_t: jax.Array
        Bk: jax.Array  # M_kk⁻¹ Φ_kᵀ Aᵀ [−Lᵀ, I, −K A, −C A]
        Bt: jax.Array  # Φ_tᵀ Aᵀ [−Lᵀ, I, −K A, −C A]
        P: jax.Array  # L A Φ_t
        Kt_o: jax.Array  # non-mesh stiffness on ξ
        z_static: jax.Array
        theta0: jax.Array
        omega_c: jax.Array
        e_c: jax.Array
        scale: jax.Array

        def z_ref(self, t):
            return self.z_static + self.e_c * (self.theta0 + self.omega_c * t)

        def reduce(self, Mz, z, zd, t):
            Mk = self.Phi_k.T @ Mz
            Mkk = Mk @ self.Phi_k
            return (jnp.linalg.solve(Mkk, Mk @ (z - self.z_ref(t))),
                    jnp.linalg.solve(Mkk, Mk @ (zd - self.e_c * self.omega_c)))

    def condense(twin, y0, t0, f_sun, n_kept):
        z0, zd0, aux0 = y0
        n = twin.n_dof
        A = jnp.asarray(twin.kinematic_map())
        ops = twin.operators()
        Mz = A.T @ twin.mass_matrix() @ A
        sg = jax.lax.stop_gradient
        _, Phi = modes(sg(twin), sg(z0), sg(zd0), sg(aux0))
        Phi_k, Phi_t = Phi[:, :n_kept], Phi[:, n_kept:]
        Bz = A.T @ jnp.concatenate([-ops.L.T, jnp.eye(n), -ops.K @ A, -ops.C @ A], axis=1)
        Bk = jnp.linalg.solve(Phi_k.T @ Mz @ Phi_k, Phi_k.T @ Bz)
        P = ops.L @ A @ Phi_t
        N = twin.n_planets
        k_mean = jnp.concatenate([jnp.full((N,), twin.lp.k_sun_planet),
                                  jnp.full((N,), twin.lp.k_ring_planet)])
        Kt_o = Phi_t.T @ stiffness_z(twin, z0, zd0, aux0) @ Phi_t - P.T @ (k_mean[:, None] * P)
        ic = twin._index("theta_c")
        e_c = jnp.zeros(n).at[ic].set(1.0)
        rs, _ = twin.kinematic_ratios
        omega_c = 2 * jnp.pi * jnp.asarray(f_sun, dtype=jnp.float64) / rs
        sz, _ = state_scales(twin)
        scale = 1.0 / jnp.max(jnp.abs(Phi_k) / sz[:, None], axis=0)
        return Condensation(Phi_k, Phi_t, Bk, Phi_t.T @ Bz, P, Kt_o, z0 - e_c * z0[ic],
                            z0[ic] - omega_c * t0, omega_c, e_c, sg(scale))

    def static_part(twin, cond, t, eta, etad, aux):
        """(z, z', F, aux') on the reconstructed displacement, F = [mesh forces; parts']."""
        A = jnp.asarray(twin.kinematic_map())
        L = twin.deflection_matrix()
        zk = cond.z_ref(t) + cond.Phi_k @ eta
        zd = cond.e_c * cond.omega_c + cond.Phi_k @ etad
        qv, qdv = A @ zk, A @ zd
        q, qdot = twin.unpack(qv), twin.unpack(qdv)
        mesh0 = twin._mesh_from_deflections(q, twin.modulation(t, q, qdot), L @ qv, L @ qdv)
        k = jnp.concatenate([mesh0.k_sp, mesh0.k_rp])
        c = jnp.concatenate([mesh0.c_sp, mesh0.c_rp])
        d0 = jnp.concatenate([mesh0.delta_sp, mesh0.delta_rp])
        dd = jnp.concatenate([mesh0.ddelta_sp, mesh0.ddelta_rp])
        f0 = jnp.concatenate([mesh0.force_sp, mesh0.force_rp])
        s = twin.contact_smoothing
        G0 = parts_forces(twin, t, q, qdot, aux, mesh0)[0] + twin._frame_forces_flat(qv, qdv)
        r = cond.Bt @ jnp.concatenate([f0, G0, zk, zd])
        slope = k * jax.nn.sigmoid(d0 / s)
        if r.shape[0]:
            xi = jnp.linalg.solve(cond.Kt_o + cond.P.T @ (slope[:, None] * cond.P), r)
        else:  # every mode kept: the full twin in modal coordinates (a check of the code)
            xi = r
        z = zk + cond.Phi_t @ xi
        d = d0 + cond.P @ xi
        f = contact_force(d, dd, k, c, s)
        N = twin.n_planets
        mesh = eqx.tree_at(lambda m: (m.delta_sp, m.delta_rp, m.force_sp, m.force_rp), mesh0,
                           (d[:N], d[N:], f[:N], f[N:]))
        qv1 = A @ z
        G, aux_dot = parts_forces(twin, t, twin.unpack(qv1), qdot, aux, mesh)
        G = G + twin._frame_forces_flat(qv1, qdv)
        return z, zd, jnp.concatenate([f, G]), aux_dot

    @eqx.filter_jit
    def solve_condensed(twin, y0, f_sun, t0, t1, ts, rtol, atol, dtmax, max_steps, n_kept):
        cond = condense(twin, y0, t0, f_sun, n_kept)
        ops = twin.operators()
        A = jnp.asarray(twin.kinematic_map())
        z0, zd0, aux0 = y0
        eta0, etad0 = cond.reduce(A.T @ twin.mass_matrix() @ A, z0, zd0, t0)
        se, sv = cond.scale, cond.scale * 2 * jnp.pi * 1e4

        def split(y):
            return y[:n_kept] * se, y[n_kept:2 * n_kept] * sv, y[2 * n_kept:]

        def vf(t, y, args):
            eta, etad, aux = split(y)
            z, zd, F, aux_dot = static_part(twin, cond, t, eta, etad, aux)
            return jnp.concatenate([etad / se, cond.Bk @ jnp.concatenate([F, z, zd]) / sv, aux_dot])

        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(vf), diffrax.Tsit5(), t0=t0, t1=t1, dt0=None,
            y0=jnp.concatenate([eta0 / se, etad0 / sv, aux0]), saveat=diffrax.SaveAt(ts=ts),
            stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol, dtmax=dtmax,
                                                      pcoeff=0.3, icoeff=0.3),
            max_steps=max_steps, throw=False)

        def obs(t, y):
            eta, etad, aux = split(y)
            z, zd, _, _ = static_part(twin, cond, t, eta, etad, aux)
            return _observe(twin, ops, "acceleration", t, (z, zd, aux))

        return jax.vmap(obs)(ts, sol.ys), sol.result, sol.stats["num_accepted_steps"]

    return dict(modes=modes, condense=condense, static_part=static_part,
                solve_condensed=solve_condensed)


# ------------------------------------------------------------------ line families
def line_families(f_sun: float, zs: int, zr: int) -> dict[str, np.ndarray]:
    fc = f_sun / (1 + zr / zs)
    fm, fsf = fc * zr, 3 * (f_sun - fc)
    fam = {"h fm + k fc": [h * fm + k * fc for h in range(1, 5) for k in range(-8, 9)],
           "fault sidebands h fm + k fc + m f_sf": [
               h * fm + k * fc + m * fsf for h in range(5) for k in (-3, 0, 3)
               for m in range(-4, 5) if m != 0 and h * fm + k * fc + m * fsf > 5],
           "m 3fc": [m * 3 * fc for m in range(1, 13)]}
    return {k: np.array([f for f in v if f < 2000.0]) for k, v in fam.items()}


def amplitudes(x: np.ndarray, fs: float, f: np.ndarray) -> np.ndarray:
    n = len(x)
    t = np.arange(n) / fs
    w = np.hanning(n)
    return np.abs(np.exp(-2j * np.pi * np.outer(f, t)) @ ((x - x.mean()) * w)) / w.sum() * 2


def compare_lines(ref: np.ndarray, sig: np.ndarray, fs: float, fam: dict) -> dict:
    top = max(amplitudes(ref, fs, f).max() for f in fam.values())
    out = {"rms_difference": float(np.sqrt(np.mean((sig - ref) ** 2)) / np.std(ref))}
    for name, f in fam.items():
        a0, a = amplitudes(ref, fs, f), amplitudes(sig, fs, f)
        lvl, dd = 20 * np.log10(a0 / top), 20 * np.log10(a / a0)
        for lo, hi, tag in ((-40, 1, "within 40 dB"), (-60, -40, "40-60 dB")):
            m = (lvl > lo) & (lvl <= hi)
            if m.any():
                out[f"{name}, {tag}"] = dict(lines=int(m.sum()),
                                             max_abs_db=float(np.abs(dd[m]).max()),
                                             median_abs_db=float(np.median(np.abs(dd[m]))))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=4.0)
    p.add_argument("--rtol", type=float, default=1e-4)
    p.add_argument("--kept", type=int, nargs="*", default=None, help="default 2 4 5 6 (6 = every mode of the torsional twin: the control)")
    p.add_argument("--implicit-span", type=float, default=None, help="default 0.25 s")
    p.add_argument("--diagnose", action="store_true")
    p.add_argument("--cache", action="store_true")
    p.add_argument("--quick", action="store_true",
                   help="0.5 s record; defaults 2 kept, 0.05 s implicit span")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    if not args.cache:
        os.environ["DTWIN_JAX_CACHE"] = "off"
    if args.quick:
        args.duration = 0.5
    if args.kept is None:
        args.kept = [2] if args.quick else [2, 4, 5, 6]
    if args.implicit_span is None:
        args.implicit_span = 0.05 if args.quick else 0.25

    import diffrax
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    import dtwin.simulation.simulate  # noqa: F401  (the module, not the function dtwin exports)
    from dtwin.model.faults import MissingTooth
    from dtwin.spec import preset
    from dtwin.spec.build import build_twin

    S = sys.modules["dtwin.simulation.simulate"]
    code = _condensation_code()
    load_start = load_average()
    f_sun, fs, over, discard = 30.0, 5000.0, 4, 0.05
    tw = build_twin(preset("paper-sim"), kind="torsional", faults=(MissingTooth(0.5, location="sun"),))
    y0 = S.initial_state(tw, f_sun, "steady")
    freqs = np.asarray(code["modes"](tw, *y0)[0])
    taps = S.daq_filter(over)
    half = (len(taps) - 1) // 2
    daq = S.DAQ(sample_rate=fs, oversample=over)
    rs, _ = tw.kinematic_ratios
    dtmax = 0.1 / (f_sun / rs * tw.lp.z_ring)
    fam = line_families(f_sun, int(tw.lp.z_sun), int(tw.lp.z_ring))

    def grid(duration):
        ts = discard + np.arange(-half, int(round(duration * fs)) * over + half) / (fs * over)
        return ts, float(ts[0]), float(ts[-1])

    def run_full(duration, solver=None):
        ts, t0, t1 = grid(duration)
        # another solver: `_solve`'s `unrolled=False` branch builds `diffrax.Tsit5()`, swapped
        # for the call (a separate trace of the jitted `_solve`: `unrolled` is static)
        tsit5 = diffrax.Tsit5
        if solver is not None:
            diffrax.Tsit5 = solver
        try:
            ys, res, ns = S._solve(tw, y0, t0, t1, jnp.asarray(ts), "acceleration", args.rtol,
                                   args.rtol, dtmax, int(400_000 * (t1 - t0) + 10_000), "forward",
                                   False, 0.3, 0.3, solver is None, S.RATE_SCALE_HZ)
            sig = S.acquire(ys, taps, daq, fs, ns, 0, discard).signal
            return (np.asarray(jax.block_until_ready(sig)), int(ns) / (t1 - t0),
                    bool(res == diffrax.RESULTS.successful))
        finally:
            diffrax.Tsit5 = tsit5

    def run_cond(duration, n_kept):
        ts, t0, t1 = grid(duration)
        ys, res, ns = code["solve_condensed"](tw, y0, f_sun, t0, t1, jnp.asarray(ts), args.rtol,
                                              args.rtol, dtmax, int(400_000 * (t1 - t0) + 10_000),
                                              n_kept)
        sig = S.acquire(ys, taps, daq, fs, ns, 0, discard).signal
        return (np.asarray(jax.block_until_ready(sig)), int(ns) / (t1 - t0),
                bool(res == diffrax.RESULTS.successful))

    def twice(label, fn):
        say(f"{label}: first call (compiles)")
        _, w1, c1 = timed(fn)
        say(f"{label}: second call")
        (sig, steps, ok), w2, c2 = timed(fn)
        return sig, dict(compile_s=w1 - w2, compile_cpu_s=c1 - c2, wall_s=w2, cpu_s=c2,
                         steps_per_s=steps, successful=ok, load=load_average())

    out = {"kind": "bandlimit", "duration": args.duration, "rtol": args.rtol,
           "natural_frequencies_hz": [float(f) for f in freqs], "load_start": load_start}
    ref, out["full"] = twice("full twin", lambda: run_full(args.duration))
    for nk in args.kept:
        sig, fig = twice(f"condensed, {nk} kept", lambda nk=nk: run_cond(args.duration, nk))
        fig["kept_hz"] = [float(f) for f in freqs[:nk]]
        fig["lines"] = compare_lines(ref, sig, fs, fam)
        out[f"condensed_{nk}"] = fig
    if args.implicit_span > 0:
        _, out["implicit_tsit5_span"] = twice("full twin over the implicit span",
                                              lambda: run_full(args.implicit_span))
        _, out["implicit_kvaerno5_span"] = twice("Kvaerno5 over the implicit span",
                                                 lambda: run_full(args.implicit_span, diffrax.Kvaerno5))
        out["implicit_span_s"] = args.implicit_span
    if args.diagnose:
        out["diagnose"] = diagnose(tw, y0, f_sun, code, args.kept)
    out["load_end"] = load_average()
    # top-level figures for run_all.py's table: CPU time over the full twin's, and the largest
    # level difference of the mesh family's lines within 40 dB of the strongest
    for nk in args.kept:
        f = out[f"condensed_{nk}"]
        out[f"cpu_over_full_{nk}_kept"] = f["cpu_s"] / out["full"]["cpu_s"]
        mesh = f["lines"].get("h fm + k fc, within 40 dB")
        if mesh:
            out[f"mesh_lines_max_db_{nk}_kept"] = mesh["max_abs_db"]
    if args.implicit_span > 0:
        out["kvaerno5_cpu_over_tsit5"] = (out["implicit_kvaerno5_span"]["cpu_s"]
                                          / out["implicit_tsit5_span"]["cpu_s"])

    if args.json:
        print(json.dumps([out], default=float))
        return 0
    print(f"{args.duration:g} s at 5 kHz, rtol = atol = {args.rtol:g}; load {load_start} → "
          f"{out['load_end']}; modes (Hz): " + ", ".join(f"{f:.0f}" for f in freqs))
    for key in ["full"] + [f"condensed_{nk}" for nk in args.kept]:
        f = out[key]
        print(f"{key}: {f['cpu_s']:.2f} s CPU ({f['wall_s']:.2f} s wall), {f['steps_per_s']:.0f} "
              f"steps/s, compile {f['compile_s']:.1f} s wall")
        for name, v in f.get("lines", {}).items():
            if name == "rms_difference":
                print(f"  rms difference to full: {v:.3g} of the signal's rms")
            else:
                print(f"  {name}: {v['lines']} lines, max |Δ| {v['max_abs_db']:.2f} dB, "
                      f"median {v['median_abs_db']:.2f} dB")
    if args.implicit_span > 0:
        a, b = out["implicit_tsit5_span"], out["implicit_kvaerno5_span"]
        print(f"over {args.implicit_span:g} s: Tsit5 {a['cpu_s']:.2f} s CPU, {a['steps_per_s']:.0f} "
              f"steps/s; Kvaerno5 {b['cpu_s']:.2f} s CPU, {b['steps_per_s']:.0f} steps/s, compile "
              f"{b['compile_s']:.1f} s")
    if args.diagnose:
        print("diagnose (static correction on the exact states): " + json.dumps(out["diagnose"]))
    return 0


def diagnose(tw, y0, f_sun, code, kept):
    """Ring-mesh force lines reconstructed through the static correction from the full twin's
    exact states (rtol 1e-8, 0.1–0.2 s), against the full twin's own, per number kept."""
    import diffrax
    import jax
    import jax.numpy as jnp

    n = tw.n_dof
    ops = tw.operators()

    def vf(t, y, args):
        zd, zdd, ad = tw.vector_field(t, (y[:n], y[n:2 * n], y[2 * n:]), ops)
        return jnp.concatenate([zd, zdd, ad])

    ts = jnp.linspace(0.1, 0.2, 2001)
    sol = diffrax.diffeqsolve(diffrax.ODETerm(vf), diffrax.Tsit5(), 0.0, 0.2, None,
                              jnp.concatenate(y0), saveat=diffrax.SaveAt(ts=ts),
                              stepsize_controller=diffrax.PIDController(rtol=1e-8, atol=1e-14),
                              max_steps=2_000_000)
    A = jnp.asarray(tw.kinematic_map())
    Mz = A.T @ tw.mass_matrix() @ A
    m = 2 * tw.n_planets
    fs = 1.0 / float(ts[1] - ts[0])
    res = {}
    for nk in kept:
        cond = code["condense"](tw, y0, 0.0, f_sun, nk)

        def one(t, y, cond=cond):
            z, zd, aux = y[:n], y[n:2 * n], y[2 * n:]
            eta, etad = cond.reduce(Mz, z, zd, t)
            _, _, F, _ = code["static_part"](tw, cond, t, eta, etad, aux)
            mesh = tw.accelerations(t, (z, zd, aux), ops)[6]
            return jnp.sum(mesh.force_rp), jnp.sum(F[m // 2:m])

        true, rec = (np.asarray(v) for v in jax.vmap(one)(ts, sol.ys))
        fm = f_sun / (1 + tw.lp.z_ring / tw.lp.z_sun) * tw.lp.z_ring
        f = np.array([h * float(fm) for h in range(1, 5)])
        a0, a = amplitudes(true, fs, f), amplitudes(rec, fs, f)
        res[f"{nk}_kept"] = {f"{h} fm": float(20 * np.log10(a[h - 1] / a0[h - 1])) for h in range(1, 5)}
    return res


if __name__ == "__main__":
    raise SystemExit(main())
