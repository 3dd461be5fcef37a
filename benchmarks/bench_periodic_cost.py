"""Issue #21, lever 2, the frequency-domain form: what its building blocks cost on this CPU.

A harmonic-balance or Fourier-collocation solve of the twin's periodic steady state works on
the state at `points` instants of one hunting period. Each Newton–Krylov iteration evaluates
the twin's vector field at every instant (the residual) or its forward-mode derivative along
a direction (one Krylov mat-vec), plus FFT pairs of the state for the time derivative. This
script times those blocks, compiled, on the paper-sim torsional twin with a sun missing tooth
of severity 0.5 (the `bench_fit.py` gearbox), so the solve's cost can be put against the tiled
time-stepping residual and Jacobian (benchmarks/README.md, "Periodic steady state"):
``cost ≈ (Newton iterations + parameters) × Krylov iterations × (JVP + FFT pair)``.

It then counts the Krylov iterations themselves: GMRES (unrestarted, right-preconditioned,
written here) on the periodic linearised problem ``(D − J(t)) x = b`` about the nominal rigid
rotation (``b`` the nominal motion's residual, ``D`` the spectral derivative), with the
period-mean Jacobian as preconditioner (one complex ``(iω − J̄)⁻¹`` per frequency, the mean's
null space at ω = 0 by pseudo-inverse), for the healthy twin and the sun fault.

It builds no solver and adopts nothing: the numbers say how many Krylov iterations such a
solve needs, against how few it could afford to beat time stepping.

Usage: ``python benchmarks/bench_periodic_cost.py [--points N] [--repeat K] [--quick] [--json]``
"""

from __future__ import annotations

import argparse
import json
import sys

from _timing import load_average, timed


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=27000,
                    help="collocation instants over one period (default 27000: 1.133 s at "
                         "~24 kHz, twice the stiffness waveform's 12th mesh harmonic)")
    ap.add_argument("--repeat", type=int, default=10, help="timed calls per block")
    ap.add_argument("--quick", action="store_true", help="3 timed calls per block")
    ap.add_argument("--json", action="store_true", help="print the records as JSON")
    args = ap.parse_args(argv)
    repeat = 3 if args.quick else args.repeat

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    from dtwin.model.faults import parse_fault
    from dtwin.spec import preset
    from dtwin.spec.build import build_twin

    spec = preset("paper-sim")
    f_sun = float(spec["operating"]["f_sun"])
    n = int(args.points)
    twins = {"healthy": build_twin(spec, kind="torsional"),
             "sun missing tooth 0.5": build_twin(
                 spec, kind="torsional", faults=(parse_fault("sun:missing_tooth:0.5"),))}
    problems = {name: _periodic_problem(tw, f_sun, n) for name, tw in twins.items()}
    pb = problems["sun missing tooth 0.5"]
    n_state = pb["y_nom"].shape[1]
    direction = jnp.full_like(pb["y_nom"], 1e-9)
    field = jax.jit(jax.vmap(pb["field"]))
    jvp = jax.jit(pb["jvp"])
    block = jnp.ones((n_state, n))
    fft_pair = jax.jit(lambda z: jnp.fft.irfft(1j * jnp.fft.rfft(z, axis=1), n=n, axis=1))

    out = dict(kind="periodic_cost", points=n, period_s=pb["period"], n_state=n_state,
               load_before=load_average())
    for name, fn, fargs in (("vector_field", field, (pb["ts"], pb["y_nom"])),
                            ("jvp", jvp, (pb["ts"], pb["y_nom"], direction)),
                            ("fft_pair", fft_pair, (block,))):
        _, first, _ = timed(lambda fn=fn, fargs=fargs: jax.block_until_ready(fn(*fargs)))
        walls, cpus = [], []
        for _ in range(repeat):
            _, w, c = timed(lambda fn=fn, fargs=fargs: jax.block_until_ready(fn(*fargs)))
            walls.append(w)
            cpus.append(c)
        walls.sort()
        cpus.sort()
        out[name] = dict(first_call_s=first, median_wall_ms=1e3 * walls[len(walls) // 2],
                         median_cpu_ms=1e3 * cpus[len(cpus) // 2])
    records = [out] + [_krylov(pb, name) for name, pb in problems.items()]
    out["load_after"] = load_average()
    if args.json:
        print(json.dumps(records))
    else:
        print(f"{n} instants over one period of {pb['period']:.4f} s, {n_state} states; load "
              f"{out['load_before'][0]:.2f} → {out['load_after'][0]:.2f}")
        for name in ("vector_field", "jvp", "fft_pair"):
            r = out[name]
            print(f"  {name:13s} median {r['median_wall_ms']:7.1f} ms wall, "
                  f"{r['median_cpu_ms']:7.1f} ms CPU (first call {r['first_call_s']:.1f} s)")
        for r in records[1:]:
            its = ", ".join(f"{t:g}: {k}" for t, k in zip(r["tolerances"], r["iterations"],
                                                         strict=True))
            print(f"  GMRES, {r['twin']}: iterations to relative residual {its} "
                  f"({r['gmres_s']:.2f} s wall); without a preconditioner "
                  f"{r['unpreconditioned_residual']:.1e} after {r['unpreconditioned_steps']}")
    return records


def _gmres(op, b, tol, maxit):
    """Unrestarted GMRES (modified Gram–Schmidt) on flat numpy vectors: the relative residual
    after each iteration."""
    import numpy as np

    bn = float(np.linalg.norm(b))
    basis, hist = [b / bn], []
    H = np.zeros((maxit + 1, maxit))
    g = np.zeros(maxit + 1)
    g[0] = bn
    for k in range(maxit):
        w = np.asarray(op(basis[k])).ravel()
        for i in range(k + 1):
            H[i, k] = basis[i] @ w
            w = w - H[i, k] * basis[i]
        H[k + 1, k] = np.linalg.norm(w)
        basis.append(w / H[k + 1, k])
        y = np.linalg.lstsq(H[:k + 2, :k + 1], g[:k + 2], rcond=None)[0]
        hist.append(float(np.linalg.norm(H[:k + 2, :k + 1] @ y - g[:k + 2])) / bn)
        if hist[-1] < tol:
            break
    return hist


def _periodic_problem(tw, f_sun: float, n: int) -> dict:
    """One hunting period of `tw` at `f_sun` (Hz) on `n` instants: times `ts` (s), the nominal
    motion `y_nom` (the steady initial state turning rigidly, the drive's angle advancing),
    its rate `drift`, the vector field `field(t, y)` on the flat state ``(z, z', aux)`` and
    `jvp(ts, ys, vs)`, its forward-mode derivative along `vs` at every instant (vmapped)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from dtwin.simulation.periodic import hunting_cycles, mesh_frequency
    from dtwin.simulation.simulate import initial_state

    ops = tw.operators()
    z0, zd0, aux0 = initial_state(tw, f_sun)
    sizes = np.cumsum([len(z0), len(zd0)])
    period = hunting_cycles(tw) / float(mesh_frequency(tw, f_sun))
    auxdot0 = tw.vector_field(0.0, (z0, zd0, aux0), ops)[2]
    ts = jnp.linspace(0.0, period, n, endpoint=False)
    drift = jnp.concatenate([zd0, jnp.zeros_like(zd0), auxdot0])  # rigid rotation, drive angle
    y_nom = jnp.concatenate([z0, zd0, aux0])[None, :] + ts[:, None] * drift[None, :]

    def field(t, y):
        return jnp.concatenate(tw.vector_field(t, tuple(jnp.split(y, sizes)), ops))

    jvp = jax.vmap(lambda t, y, v: jax.jvp(lambda yy: field(t, yy), (y,), (v,))[1])
    return dict(period=period, ts=ts, y_nom=y_nom, drift=drift, field=field, jvp=jvp)


def _krylov(pb: dict, label: str, tolerances=(1e-3, 1e-4, 1e-5, 1e-6), maxit=120) -> dict:
    """GMRES iterations of ``(D − J(t)) x = b`` over one hunting period (module docs), `pb`
    from :func:`_periodic_problem`."""
    import time

    import jax
    import jax.numpy as jnp
    import numpy as np

    ts, y_nom, drift, field, jvp = (pb[k] for k in ("ts", "y_nom", "drift", "field", "jvp"))
    n, m = y_nom.shape
    period = pb["period"]
    j_mean = np.asarray(jax.jit(jax.vmap(lambda t, y: jax.jacfwd(lambda yy: field(t, yy))(y)))(
        ts, y_nom)).mean(axis=0)
    omega = 2.0 * np.pi * np.fft.rfftfreq(n, d=period / n)
    blocks = 1j * omega[:, None, None] * np.eye(m)[None] - j_mean[None]
    p_inv = jnp.asarray(np.concatenate([np.linalg.pinv(blocks[:1]), np.linalg.inv(blocks[1:])]))
    w = jnp.asarray(omega)

    @jax.jit
    def operator(x):
        x = x.reshape(n, m)
        return (jnp.fft.irfft(1j * w[:, None] * jnp.fft.rfft(x, axis=0), n=n, axis=0)
                - jvp(ts, y_nom, x)).ravel()

    @jax.jit
    def precondition(r):
        R = jnp.fft.rfft(r.reshape(n, m), axis=0)
        return jnp.fft.irfft(jnp.einsum("kij,kj->ki", p_inv, R), n=n, axis=0).ravel()

    b = np.asarray(jax.vmap(field)(ts, y_nom) - drift[None, :]).ravel()

    def preconditioned(x):
        return operator(precondition(jnp.asarray(x)))

    preconditioned(b)
    t0 = time.perf_counter()
    hist = _gmres(preconditioned, b, min(tolerances), maxit)
    wall = time.perf_counter() - t0
    plain = _gmres(lambda x: operator(jnp.asarray(x)), b, min(tolerances), 60)
    return dict(kind="periodic_krylov", twin=label, points=n, tolerances=list(tolerances),
                iterations=[next((i + 1 for i, h in enumerate(hist) if h < t), None)
                            for t in tolerances],
                gmres_s=wall, unpreconditioned_steps=len(plain),
                unpreconditioned_residual=plain[-1])


if __name__ == "__main__":
    main(sys.argv[1:])
