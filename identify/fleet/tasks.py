"""The tasks of a fleet run: fit the records of one task, discover on one fitted record, and the
result entries they return (run in a worker process under Ray, or here)."""

from __future__ import annotations

import importlib
import os
import socket
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import numpy as np

from dtwin.errors import DtwinError
from dtwin.io.readers import read_record
from dtwin.model.registry import ensure_parts, set_value
from dtwin.signal.order import RUNUP_SPEED_CHANGE, tacho_speed_range
from dtwin.spec import load_spec
from dtwin.spec.build import SEVERITY_KIND, build_twin, twin_kind

from ..discover import DiscoverySettings, discover
from ..excitation_response import SPLIT_STIFFNESS, stiffness_split
from ..segment import segment_for_fit
from ..severity import estimate_severity, fault_location
from .settings import FAIL_ENV, SCHEMA, FleetSettings
from .store import _now

#: The module ``dtwin.identify.fit`` (the package re-exports a *function* of that name): its
#: functions are looked up when a task runs, so a test can count the calls of ``fit_batch``.
_fit = importlib.import_module("dtwin.identify.fit")

_GAP_THRESHOLD_DB = 12.0


def _inject(job: Mapping[str, Any], inject: str | None, attempts_dir: str | None,
            in_ray: bool) -> None:
    """Failure injection (module docstring)."""
    if not inject:
        return
    target, _, times = inject.partition("@")
    target, _, mode = target.partition(":")
    if not target or target not in job["path"]:
        return
    if times:
        marker = Path(attempts_dir or ".") / f"{job['key']}.attempts"
        marker.parent.mkdir(parents=True, exist_ok=True)
        with open(marker, "a") as f:
            f.write("x")
        if marker.stat().st_size > int(times):
            return
    if mode == "exit" and in_ray:
        os._exit(17)
    raise RuntimeError(f"injected failure ({FAIL_ENV}={inject!r}) in the task of {job['path']}")


def _identity(job: Mapping[str, Any]) -> dict[str, Any]:
    return {"record": job["path"], "key": job["key"], "machine": job["machine"],
            "timestamp": job["timestamp"], "identity_source": job["identity_source"],
            "sha256": job["sha256"]}


def failure_entry(job: Mapping[str, Any], error: BaseException | str, *, stage: str,
                  fingerprint: str, kind: str = "fit", attempts: int | None = None
                  ) -> dict[str, Any]:
    """The result entry of a record that failed at `stage` (``read``, ``fit``, ``task``,
    ``discover``) with `error`."""
    if isinstance(error, BaseException):
        etype, msg = type(error).__name__, str(error)
    else:
        etype, msg = "Error", str(error)
    return {"schema": SCHEMA, "kind": kind, "status": "failed", **_identity(job),
            "settings_fingerprint": fingerprint, "stage": stage, "error_type": etype,
            "error": msg[-4000:], "attempts": attempts, "host": socket.gethostname(),
            "finished": _now()}


def fit_gap_db(res) -> float:
    """In-sample gap (dB) of a fit over its own points (module docstring).

    The residuals at the optimum are the fit's own (`FitResult.residuals`, from its last
    accepted step): ``r = log(model level) − log(A_meas + F)`` per point, so the model level is
    ``exp(meas + r)``."""
    problem = res.problem
    r = np.asarray(res.residuals)
    d2, off = [], 0
    for obs in problem.observations:
        m = int(obs.meas.shape[0])
        meas = np.asarray(obs.meas)
        floor = np.asarray(obs.floor)
        lr = r[off: off + m] / obs.weight
        off += obs.size
        thr = floor * 10.0 ** (_GAP_THRESHOLD_DB / 20.0)
        a_meas, a_model = np.exp(meas), np.exp(meas + lr)
        mask = ((a_meas - floor) > thr) | ((a_model - floor) > thr)
        d2.append(((20.0 / np.log(10.0)) * lr[mask]) ** 2)
    d = np.concatenate(d2) if d2 else np.zeros(0)
    return float(np.sqrt(d.mean())) if d.size else 0.0


def _fit_entry(job: Mapping[str, Any], res, *, fingerprint: str, engine: str, batched: int,
               wall: float) -> dict[str, Any]:
    unc = res.uncertainty
    intervals = {}
    std = {}
    if unc is not None:
        for i, n in enumerate(res.names):
            intervals[n] = [float(unc.interval[i][0]), float(unc.interval[i][1])]
            std[n] = float(unc.std[i])
    try:
        gap = fit_gap_db(res)
    except Exception as e:  # noqa: BLE001 — the gap is a summary; the fit stands without it
        gap = float("nan")
        res.message += f"; gap not computed ({type(e).__name__}: {e})"
    ops = res.operating_points[0] if res.operating_points else {}
    return {
        "schema": SCHEMA, "kind": "fit", "status": "ok", **_identity(job),
        "settings_fingerprint": fingerprint, "names": list(res.names),
        "values": dict(res.values), "intervals_95": intervals, "std": std,
        "not_determined": dict(res.not_determined), "converged": bool(res.converged),
        "at_bound": list(res.at_bound), "message": res.message, "loss": float(res.loss),
        "iterations": int(res.iterations), "f_sun": ops.get("f_sun"), "operating_point": ops,
        "gap_db": gap, "excitation": res.excitation, "engine": engine,
        "batched_with": batched, "wall_time_s": wall,
        "host": socket.gethostname(), "pid": os.getpid(), "finished": _now(),
        "fit": res.to_dict(),
    }


def _structure(problem):
    static = eqx.partition(problem, eqx.is_array)[1]
    shapes = jax.tree.map(lambda a: a.shape, eqx.filter(problem, eqx.is_array))
    return static, shapes


def _read_jobs(jobs, spec, settings: FleetSettings, free, kw, *, fingerprint: str, engine: str,
               inject: str | None, attempts_dir: str | None):
    """Read a task's records: a run-up is fitted at once (alone); a steady record is cut to
    its fit window (:func:`dtwin.identify.segment.segment_for_fit`) and its problem made.
    **Returns** ``(entries, ready, windows)``: the entries done (run-ups, read failures), the
    ``(job, record, problem)`` left to fit, and the fit window of each windowed record."""
    entries: dict[str, dict[str, Any]] = {}
    ready: list[tuple[Mapping[str, Any], Any, Any]] = []
    windows: dict[str, dict[str, Any]] = {}  # a long steady record is fitted on a window
    for job in jobs:
        _inject(job, inject, attempts_dir, engine == "ray")
        try:
            rec = read_record(job["path"], **settings.record_reading())
            runup = runup_range(rec, spec, settings.channel)
            if runup is not None:  # a run-up is fitted as one, alone (never batched as steady)
                entries[job["key"]] = _runup_entry(job, rec, spec, free, settings, kw, runup,
                                                   fingerprint, engine)
                continue
            seg = segment_for_fit(rec, spec, settings.f_sun, channel=settings.channel)
            if seg.windowed:  # dtwin.identify.segment: a steady stretch at the rate needed
                rec, windows[job["key"]] = seg.record, seg.to_dict()
            prob, _ = _fit.make_problem(rec, spec, free, **settings.problem_kwargs())
            ready.append((job, rec, prob))
        except DtwinError as e:
            entries[job["key"]] = failure_entry(job, e, stage="read", fingerprint=fingerprint)
    return entries, ready, windows


def _by_structure(ready):
    """The ready ``(job, record, problem)`` items in groups of one problem structure (one
    compiled batch each), in order of first appearance."""
    groups: list[list[tuple[Mapping[str, Any], Any, Any]]] = []
    sigs: list[Any] = []
    for item in ready:
        s = _structure(item[2])
        for g, sg in zip(groups, sigs, strict=True):
            if sg == s:
                g.append(item)
                break
        else:
            groups.append([item])
            sigs.append(s)
    return groups


def fit_task(jobs: Sequence[Mapping[str, Any]], spec_data: Mapping[str, Any],
             settings: FleetSettings, *, fingerprint: str, engine: str = "local",
             inject: str | None = None, attempts_dir: str | None = None) -> list[dict[str, Any]]:
    """Fit the records of one task (module docstring); one entry per record, ``ok`` or
    ``failed``. A `DtwinError` of one record is reported for that record; any other exception
    propagates (Ray retries the task)."""
    spec = load_spec(spec_data)
    settings = settings.resolved(spec_data)
    kw = settings.fit_kwargs()
    free = list(settings.free)
    entries, ready, windows = _read_jobs(jobs, spec, settings, free, kw, fingerprint=fingerprint,
                                         engine=engine, inject=inject, attempts_dir=attempts_dir)
    groups = _by_structure(ready)

    location = fault_location(free)
    if location is not None and settings.kind is None:  # a tooth fault's twin (one path)
        kw["kind"] = SEVERITY_KIND

    def depth(job, rec):
        """A tooth fault's depth: the problem ``dtwin severity`` fits (one path,
        :func:`dtwin.identify.severity.fault_location`); its interval is the severity's."""
        t0 = time.perf_counter()
        try:
            est = estimate_severity(rec, spec, location,
                                    free=[n for n in free if n != f"{location}_fault"],
                                    starts=settings.starts, refine=settings.refine,
                                    **{**kw, "kind": settings.kind})  # None: severity's own
        except DtwinError as e:
            return failure_entry(job, e, stage="fit", fingerprint=fingerprint)
        entry = _fit_entry(job, est.fit, fingerprint=fingerprint, engine=engine, batched=1,
                           wall=time.perf_counter() - t0)
        entry["intervals_95"][f"{location}_fault"] = [float(x) for x in est.interval]
        entry["excitation"] = est.excitation or entry["excitation"]
        entry["severity"] = est.to_dict(with_fit=False)
        entry["model"] = est.fit.problem.twin.kind
        return entry

    def single(job, rec):
        if location is not None:
            return depth(job, rec)
        t0 = time.perf_counter()
        try:
            res = _fit.fit(rec, spec, free, starts=settings.starts, refine=settings.refine, **kw)
            return _fit_entry(job, res, fingerprint=fingerprint, engine=engine, batched=1,
                              wall=time.perf_counter() - t0)
        except DtwinError as e:
            return failure_entry(job, e, stage="fit", fingerprint=fingerprint)

    for g in groups:
        if len(g) == 1:
            job, rec, _ = g[0]
            entries[job["key"]] = single(job, rec)
            continue
        t0 = time.perf_counter()
        try:
            results = _fit.fit_batch([r for _, r, _ in g], spec, free, **kw)
        except DtwinError:
            for job, rec, _ in g:  # isolate the record that fails
                entries[job["key"]] = single(job, rec)
            continue
        wall = (time.perf_counter() - t0) / len(g)
        for (job, _, _), res in zip(g, results, strict=True):
            entries[job["key"]] = _fit_entry(job, res, fingerprint=fingerprint, engine=engine,
                                             batched=len(g), wall=wall)
    for key, w in windows.items():
        if entries[key].get("status") == "ok":
            entries[key]["fit_window"] = w
    return [entries[j["key"]] for j in jobs]


def _fitted_twin(spec, settings: FleetSettings, values: Mapping[str, float], f_sun: float | None,
                 kind: str | None = None):
    """The spec's twin (of `kind`, default the settings') with the fitted `values` written
    through the registry's addresses."""
    twin = build_twin(spec, kind=kind or twin_kind(spec, settings.kind), f_sun=f_sun)
    names = [n for n in settings.free if n in values]
    twin = ensure_parts(twin, names)
    for n in names:
        twin = set_value(twin, n, float(values[n]))
    return twin


def discover_task(job: Mapping[str, Any], spec_data: Mapping[str, Any], settings: FleetSettings,
                  fit_entry: Mapping[str, Any], *, fingerprint: str, engine: str = "local",
                  inject: str | None = None, attempts_dir: str | None = None) -> dict[str, Any]:
    """Discovery on one record about its fitted twin (:func:`dtwin.identify.discover.discover`):
    effects named with their main parameter, held-out gap before and after, unexplained lines.
    The twin is the spec's, or the other end of a calibrated spec's excitation/response split
    where the fit reported that one (:mod:`dtwin.identify.split`). A `DtwinError` is reported;
    other exceptions propagate (retried)."""
    _inject({**job, "path": job["path"] + "#discover"}, inject, attempts_dir, engine == "ray")
    t0 = time.perf_counter()
    try:
        spec = load_spec(spec_data)
        if fit_entry.get("excitation") == SPLIT_STIFFNESS:
            spec = stiffness_split(spec)
        rec = read_record(job["path"], **settings.record_reading())
        kind = fit_entry.get("model") or twin_kind(spec, settings.kind)  # the fit's twin
        twin = _fitted_twin(spec, settings, fit_entry.get("values", {}), fit_entry.get("f_sun"),
                            kind)
        res = discover(rec.select([settings.channel]), spec, base_twin=twin, kind=kind,
                       settings=DiscoverySettings(**dict(settings.discover_options)))
    except DtwinError as e:
        return failure_entry(job, e, stage="discover", fingerprint=fingerprint, kind="discover")
    return {
        "schema": SCHEMA, "kind": "discover", "status": "ok", **_identity(job),
        "settings_fingerprint": fingerprint,
        "effects": [s.named for s in res.steps],
        "groups": [s.group for s in res.steps],
        "main": [dict(s.main, effect=s.effect) for s in res.steps],
        "gap_initial_db": res.initial_gap.total, "gap_final_db": res.final_gap.total,
        "unexplained": [r.to_dict() for r in res.unexplained], "stop_reason": res.stop_reason,
        "engine": engine, "wall_time_s": time.perf_counter() - t0, "host": socket.gethostname(),
        "finished": _now(), "result": res.to_dict(),
    }


def runup_range(rec, spec, channel: str | int = 0) -> tuple[float, float] | None:
    """The input-speed range (Hz, with a 3 % margin) of a run-up or coast-down, or None for a
    steady record.

    The speed comes from the tachometer when the record has one (its 2nd and 98th
    percentiles), else from the strongest line near the mesh frequency in each quarter of the
    record (a run-up moves it monotonically). A record is a run-up when the speed changes by
    more than :data:`dtwin.signal.order.RUNUP_SPEED_CHANGE` of its median.
    """
    fs = float(rec.sample_rate)
    gs = spec.gear_set()
    to_sun = (gs.z_sun + gs.z_ring) / gs.z_sun
    if rec.tacho is not None and rec.tacho_ppr:
        lo, hi, med = (v * (to_sun if rec.tacho_shaft == "carrier" else 1.0)
                       for v in tacho_speed_range(rec.tacho, fs, rec.tacho_ppr))
        monotone = True
    else:
        nominal = spec["operating"].get("f_sun")
        x = np.asarray(rec.channel(channel), dtype=float)
        n4 = x.size // 4
        if not nominal or n4 < 256:
            return None
        mesh_order = gs.z_sun * gs.z_ring / (gs.z_sun + gs.z_ring)
        sp = []
        for q in range(4):
            seg = x[q * n4:(q + 1) * n4]
            amp = np.abs(np.fft.rfft((seg - seg.mean()) * np.hanning(n4), 4 * n4))
            f = np.fft.rfftfreq(4 * n4, 1.0 / fs)
            sel = (f > 0.5 * nominal * mesh_order) & (f < min(1.5 * nominal * mesh_order, fs / 2))
            if not sel.any():
                return None
            sp.append(float(f[sel][np.argmax(amp[sel])]) / mesh_order)
        sp = np.asarray(sp)
        lo, hi, med = float(sp.min()), float(sp.max()), float(np.median(sp))
        d = np.diff(sp)
        monotone = bool(np.all(d >= 0) or np.all(d <= 0))
    if med <= 0 or not monotone or (hi - lo) / med <= RUNUP_SPEED_CHANGE:
        return None
    return (0.97 * lo, 1.03 * hi)


def _runup_entry(job, rec, spec, free, settings: FleetSettings, kw, runup, fingerprint: str,
                 engine: str) -> dict[str, Any]:
    """Fit a run-up record as a run-up (speed profile, spectrogram residuals), or refuse it
    with the reason."""
    t0 = time.perf_counter()
    kw = {k: v for k, v in kw.items() if k not in ("f_sun", "features")}
    try:
        res = _fit.fit(rec, spec, free, runup=runup, starts=settings.starts,
                       refine=settings.refine, **kw)
    except DtwinError as e:
        entry = failure_entry(job, e, stage="fit", fingerprint=fingerprint)
        entry["error"] = (f"run-up record (input speed {runup[0]:.1f}–{runup[1]:.1f} Hz): "
                          + entry["error"])
        return entry

    entry = _fit_entry(job, res, fingerprint=fingerprint, engine=engine, batched=1,
                       wall=time.perf_counter() - t0)
    entry["runup_hz"] = [float(runup[0]), float(runup[1])]
    return entry
