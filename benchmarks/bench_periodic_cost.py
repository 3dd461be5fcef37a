"""Issue #21, lever 2, the frequency-domain form: what its building blocks cost on this CPU.

A harmonic-balance or Fourier-collocation solve of the twin's periodic steady state works on
the state at `points` instants of one hunting period. Each Newton–Krylov iteration evaluates
the twin's vector field at every instant (the residual) or its forward-mode derivative along
a direction (one Krylov mat-vec), plus FFT pairs of the state for the time derivative. This
script times those blocks, compiled, on the paper-sim torsional twin with a sun missing tooth
of severity 0.5 (the `bench_fit.py` gearbox), so the solve's cost can be put against the tiled
time-stepping residual and Jacobian (benchmarks/README.md, "Periodic steady state"):
``cost ≈ (Newton iterations + parameters) × Krylov iterations × (JVP + FFT pair)``.

It builds no solver and adopts nothing: the numbers say how few Krylov iterations a
preconditioner must reach for such a solve to beat time stepping.

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

    from dtwin.build import build_twin
    from dtwin.faults import parse_fault
    from dtwin.periodic import hunting_cycles, mesh_frequency
    from dtwin.simulate import initial_state
    from dtwin.spec import preset

    spec = preset("paper-sim")
    f_sun = float(spec["operating"]["f_sun"])
    tw = build_twin(spec, kind="torsional", faults=(parse_fault("sun:missing_tooth:0.5"),))
    ops = tw.operators()
    y0 = initial_state(tw, f_sun)
    period = hunting_cycles(tw) / float(mesh_frequency(tw, f_sun))
    n = int(args.points)
    ts = jnp.linspace(0.0, period, n, endpoint=False)
    states = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a, (n,) + a.shape) + 0.0, y0)
    direction = jax.tree_util.tree_map(lambda a: jnp.full_like(a, 1e-9), states)
    n_state = sum(int(a.shape[-1]) for a in jax.tree_util.tree_leaves(y0))

    field = jax.jit(jax.vmap(lambda t, y: tw.vector_field(t, y, ops)))
    jvp = jax.jit(jax.vmap(lambda t, y, v: jax.jvp(lambda yy: tw.vector_field(t, yy, ops),
                                                   (y,), (v,))[1]))
    block = jnp.ones((n_state, n))
    fft_pair = jax.jit(lambda z: jnp.fft.irfft(1j * jnp.fft.rfft(z, axis=1), n=n, axis=1))

    out = dict(kind="periodic_cost", points=n, period_s=period, n_state=n_state,
               load_before=load_average())
    for name, fn, fargs in (("vector_field", field, (ts, states)),
                            ("jvp", jvp, (ts, states, direction)),
                            ("fft_pair", fft_pair, (block,))):
        _, wall_c, cpu_c = timed(lambda fn=fn, fargs=fargs: jax.block_until_ready(fn(*fargs)))
        walls, cpus = [], []
        for _ in range(repeat):
            _, w, c = timed(lambda fn=fn, fargs=fargs: jax.block_until_ready(fn(*fargs)))
            walls.append(w)
            cpus.append(c)
        walls.sort()
        cpus.sort()
        out[name] = dict(first_call_s=wall_c, median_wall_ms=1e3 * walls[len(walls) // 2],
                         median_cpu_ms=1e3 * cpus[len(cpus) // 2])
    out["load_after"] = load_average()
    records = [out]
    if args.json:
        print(json.dumps(records))
    else:
        print(f"{n} instants over one period of {period:.4f} s, {n_state} states; load "
              f"{out['load_before'][0]:.2f} → {out['load_after'][0]:.2f}")
        for name in ("vector_field", "jvp", "fft_pair"):
            r = out[name]
            print(f"  {name:13s} median {r['median_wall_ms']:7.1f} ms wall, "
                  f"{r['median_cpu_ms']:7.1f} ms CPU (first call {r['first_call_s']:.1f} s)")
    return records


if __name__ == "__main__":
    main(sys.argv[1:])
