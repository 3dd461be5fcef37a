"""``dtwin stiffness``: the mesh-stiffness waveform of a gearbox, with and without faults.

    dtwin stiffness --preset paper-sim|paper-bench | --spec FILE
                    [--fault LOCATION:KIND:SEVERITY[:TOOTH[:PLANET[:FLANK]]] ...]
                    [--planet P] [--cycles C] [--json] [--out DIR] [--force]

Shows planet 0's (``--planet``; default the first planet fault's planet) sun–planet and
ring–planet mesh stiffness under rigid kinematics (ring fixed)
over a span of mesh cycles: one relative sun revolution (``Zs`` cycles) for a healthy gearbox or
a sun fault, ``Zp`` for a planet fault and ``Zr`` for a ring fault, unless ``--cycles`` says.
Faults come from ``--fault`` (repeatable, e.g. ``--fault sun:missing_tooth:0.5``) and, if none
is given, from the spec's ``[[faults]]``. Terminal: a table of ``k_mean``, ``c'``, ``1.75 c'``,
``eps`` and, with faults, the smallest faulty stiffness of each mesh. ``--json``: the same on
stdout. ``--out DIR``: ``stiffness.json`` (with the curves), ``stiffness.png``, ``manifest.json``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from ..errors import SpecError
from . import options as opts
from .app import app


def _fault_label(f: Any) -> str:
    kind = {"MissingTooth": "missing tooth", "Pitting": "pitting", "RootCrack": "root crack"}
    where = f"planet {f.planet}" if f.location == "planet" else f.location
    return f"{where} tooth {f.tooth} {kind.get(type(f).__name__, type(f).__name__)} {float(f.severity):g}"


def stiffness_curves(
    lp: Any,
    faults: Any = (),
    *,
    n_cycles: float | None = None,
    samples_per_cycle: int = 40,
    n_harmonics: int = 12,
    planet: int = 0,
) -> dict[str, Any]:
    """Planet `planet`'s mesh stiffness under rigid kinematics, healthy and with `faults`.

    The carrier turns from ``-2`` to ``n_cycles + 2`` mesh cycles (``Zr theta_c / 2 pi``), the
    sun at ``theta_c (1 + Zr/Zs)``, the planets at ``theta_c (1 - Zr/Zp)``, the ring fixed.
    `n_cycles` defaults to the tooth count of the faulty gear (``Zs`` without faults).

    **Returns:** dict with ``mesh_cycles`` (T,), ``k_sun_planet``, ``k_ring_planet`` (healthy,
    N/m) and, with faults, ``k_sun_planet_faulty``, ``k_ring_planet_faulty`` (N/m), all numpy.
    """
    import jax
    import jax.numpy as jnp
    import numpy as np

    from ..faults import mesh_stiffnesses

    if n_cycles is None:
        z = {"sun": lp.z_sun, "planet": lp.z_planet, "ring": lp.z_ring}
        n_cycles = max([lp.z_sun] + [z[f.location] for f in faults])
    x = np.arange(-2.0, n_cycles + 2.0, 1.0 / samples_per_cycle)
    tc = jnp.asarray(x * 2 * np.pi / lp.z_ring, dtype=jnp.float64)
    ts = tc * (1.0 + lp.z_ring / lp.z_sun)
    tp = jnp.broadcast_to((tc * (1.0 - lp.z_ring / lp.z_planet))[:, None],
                          (tc.shape[0], lp.n_planets))
    tr = jnp.zeros_like(tc)

    def run(fs):
        f = jax.vmap(lambda a, b, c, d: mesh_stiffnesses(lp, a, b, c, d, fs,
                                                         n_harmonics=n_harmonics))
        k_sp, k_rp = f(ts, tc, tr, tp)
        return np.asarray(k_sp[:, planet]), np.asarray(k_rp[:, planet])

    out: dict[str, Any] = {"mesh_cycles": x}
    out["k_sun_planet"], out["k_ring_planet"] = run(())
    if faults:
        out["k_sun_planet_faulty"], out["k_ring_planet_faulty"] = run(tuple(faults))
    return out


def stiffness_report(lp: Any, faults: Any, curves: dict[str, Any]) -> dict[str, Any]:
    """JSON-ready summary: per mesh k_mean, c', 1.75 c', eps and the faulty extremes (N/m)."""
    import numpy as np

    from ..stiffness import DOUBLE_CONTACT_FACTOR, single_pair_from_mean

    meshes = {}
    for name, k, eps, key in (("sun_planet", lp.k_sun_planet, lp.eps_sp, "k_sun_planet"),
                              ("ring_planet", lp.k_ring_planet, lp.eps_rp, "k_ring_planet")):
        c1 = float(single_pair_from_mean(k, eps))
        row = {"k_mean": float(k), "c_single": c1, "c_double": DOUBLE_CONTACT_FACTOR * c1,
               "eps": float(eps), "k_min_healthy": float(np.min(curves[key])),
               "k_max_healthy": float(np.max(curves[key]))}
        if faults:
            kf = curves[key + "_faulty"]
            row["k_min_faulty"] = float(np.min(kf))
            row["max_loss"] = float(np.max(curves[key] - kf))
        meshes[name] = row
    return {
        "z_sun": lp.z_sun, "z_planet": lp.z_planet, "z_ring": lp.z_ring,
        "n_planets": lp.n_planets, "meshes": meshes,
        "faults": [{"label": _fault_label(f), "type": type(f).__name__, "location": f.location,
                    "tooth": f.tooth, "planet": f.planet, "flank": f.flank,
                    "severity": float(f.severity), "meaning": f.severity_meaning}
                   for f in faults],
    }


@app.command()
def stiffness(
    preset: str | None = opts.preset_option(),
    spec: Path | None = opts.spec_option(),
    fault: list[str] | None = typer.Option(
        None, "--fault", help="LOCATION:KIND:SEVERITY[:TOOTH[:PLANET[:FLANK]]], e.g. "
        "sun:missing_tooth:0.5 or planet:pitting:0.3:4:1 (repeatable; kinds missing_tooth, "
        "pitting, crack). Default: the spec's [[faults]]."),
    planet: int | None = typer.Option(
        None, "--planet", help="Planet whose meshes are shown (default: that of the first planet "
        "fault, else 0)."),
    cycles: float | None = typer.Option(
        None, "--cycles", help="Mesh cycles shown (default: teeth of the faulty gear, Zs "
        "without faults)."),
    json_out: bool = opts.json_option(),
    out: Path | None = opts.out_option("stiffness.json, stiffness.png"),
    force: bool = opts.force_option(),
) -> None:
    """Mesh-stiffness waveform of planet 0's sun and ring meshes, healthy and faulty."""
    from ..faults import faults_from_table, parse_fault

    opts.positive("--cycles", cycles)
    if cycles is not None and cycles > 10_000:
        raise opts.OptionError("--cycles", f"at most 10000 mesh cycles, got {cycles:g}")
    opts.check_out(out, force)
    gb = opts.load_gearbox(preset, spec)
    spec_obj, lp, source = gb.spec, gb.lumped(), gb.source
    faults = [parse_fault(f) for f in fault] if fault else list(faults_from_table(spec_obj["faults"]))
    n_harm = int(spec_obj["mesh"].get("n_harmonics", 12))
    for f in faults:  # boundary checks (tooth, planet) before any computation
        if f.location == "planet" and f.planet >= lp.n_planets:
            raise SpecError([("--fault", f"planet {f.planet} does not exist; the gear set has "
                              f"planets 0..{lp.n_planets - 1}")])
    if planet is None:
        planet = next((f.planet for f in faults if f.location == "planet"), 0)
    if not 0 <= planet < lp.n_planets:
        raise SpecError([("--planet", f"planets are numbered 0..{lp.n_planets - 1}, got {planet}")])
    curves = stiffness_curves(lp, faults, n_cycles=cycles, n_harmonics=n_harm, planet=planet)
    report = stiffness_report(lp, faults, curves)
    report["source"] = source
    report["planet"] = planet
    report["n_harmonics"] = n_harm

    def files() -> dict:
        import numpy as np

        from ..plotting.stiffness import plot_mesh_stiffness

        zoom = None
        if faults:
            loss = (curves["k_sun_planet"] - curves["k_sun_planet_faulty"]
                    + curves["k_ring_planet"] - curves["k_ring_planet_faulty"])
            centre = float(curves["mesh_cycles"][int(np.argmax(loss))])
            zoom = (centre - 2.5, centre + 2.5)
        fig = plot_mesh_stiffness(
            curves["mesh_cycles"], curves["k_sun_planet"], curves["k_ring_planet"],
            k_sun_planet_faulty=curves.get("k_sun_planet_faulty"),
            k_ring_planet_faulty=curves.get("k_ring_planet_faulty"),
            zoom=zoom, planet=planet, fault_label=" + ".join(r["label"] for r in report["faults"]) or "faulty",
            title=f"{source}: mesh stiffness (Zs={lp.z_sun}, Zp={lp.z_planet}, Zr={lp.z_ring})",
        )
        return {"stiffness.json": {**report, "curves": curves}, "stiffness.png": fig}

    opts.emit(report, json_out=json_out, table=lambda: _print_table(report), out=out,
              force=force, files=files, gearbox=gb,
              parameters={"source": source, "fault": fault or []})


def _print_table(report: dict[str, Any]) -> None:
    from rich.table import Table

    faulty = bool(report["faults"])
    title = (f"{report['source']}: mesh stiffness of planet {report['planet']} (Zs="
             f"{report['z_sun']}, Zp={report['z_planet']}, Zr={report['z_ring']}, "
             f"N={report['n_planets']})")
    table = Table(title=title)
    table.add_column("mesh")
    table.add_column("k_mean (N/m)", justify="right")
    table.add_column("c' single (N/m)", justify="right")
    table.add_column("1.75 c' double (N/m)", justify="right")
    table.add_column("eps", justify="right")
    if faulty:
        table.add_column("min k with fault (N/m)", justify="right")
    for name, r in report["meshes"].items():
        cells = [name.replace("_", "-"), f"{r['k_mean']:.4g}", f"{r['c_single']:.4g}",
                 f"{r['c_double']:.4g}", f"{r['eps']:.3f}"]
        if faulty:
            cells.append(f"{r['k_min_faulty']:.4g}")
        table.add_row(*cells)
    console = opts.console()
    opts.print_table(table)
    for f in report["faults"]:
        console.print(f"fault: {f['label']} (severity = {f['meaning']})")
