"""The paper's comparison (its Section 6, Figure 15): traditional model versus motor-coupled twin.

The *traditional* model is the twin driven by the ideal speed source
(:class:`~dtwin.model.motor.speed_source.IdealSpeedSource`): the rotor end of the drive shaft turns at
the set speed whatever the torque. The *coupled* twin is the same `Twin` with the PMSM under
field-oriented control (:class:`~dtwin.model.motor.pmsm.PMSM`) in its place. Both drives carry the same
`Shaft` (`k_shaft`, `c_shaft`) built from the same `[motor]` table, and the two twins are equal
leaf for leaf except for the drive part (:func:`comparison_twins`; `tests/test_coupling.py`
checks it with ``eqx.tree_equal``), so every difference comes from the drive.

For a sun missing tooth of severity ``s`` in [0, 1] (:class:`~dtwin.model.faults.MissingTooth`: fraction
of the face width removed) the indicator is the RMS of the sensor signal over a steady window::

    RMS(s) = sqrt(mean_t (x(t; s) - mean_t x)^2)

recorded after `discard` seconds of transient (a run started at speed, ``start="steady"``, or
from standstill by the paper's STEP, ``start="rest"``). The sensitivity ``dRMS/ds`` comes from
forward-mode automatic differentiation through the ODE solve (`jax.jvp`,
``SolverOptions(adjoint="forward")``), vectorised over the severities with `jax.vmap`.

:func:`sensitivity_sweep` repeats ``dRMS/ds`` at one severity over shaft stiffnesses `k_shaft`
(N·m/rad) and speed-loop bandwidths (Hz): the ideal source does not depend on the bandwidth,
the PMSM does. Reference.md §1 treats the paper's finding (coupled twin more sensitive) as a
claim to reproduce and report; docs/coupling.md reports what this twin gives.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..errors import SolverError, SpecError
from ..model.faults import MissingTooth
from ..model.motor.drive import DrivePart
from ..model.parts.local_fault import LocalFault
from ..model.twin import Twin
from ..simulation.simulate import DAQ, SolverOptions, simulate
from ..spec import Spec, load_spec
from ..spec.build import build_twin, daq_from_spec, operating_speed
from ..spec.motor import drive_from_spec

__all__ = [
    "MODELS",
    "SOLVER_DEFAULT",
    "DriveComparison",
    "SensitivitySweep",
    "compare_drives",
    "comparison_twins",
    "fault_rms",
    "fault_rms_and_slope",
    "sensitivity_sweep",
    "set_drive_parameters",
    "with_severity",
]

#: The two models of the comparison, in the order of every table and figure.
MODELS = ("traditional", "coupled")

#: Solver settings of the comparison. Forward-mode derivatives through the adaptive solve follow
#: the discrete solution: at the twin's default tolerance (1e-5) ``dRMS/ds`` was off by up to
#: 100 % where the slope is small (low severities); at 1e-7 it agrees with central finite
#: differences to < 1 % (tests/test_coupling.py), for about twice the steps.
SOLVER_DEFAULT = SolverOptions(rtol=1e-7, atol=1e-7, adjoint="forward")

#: Default severities of the comparison (fraction of the sun tooth's face width removed).
SEVERITIES_DEFAULT = (0.0, 0.25, 0.5, 0.75, 1.0)


# --------------------------------------------------------------------------------- the twins
def _motor_table(spec, motor_type: str, start: str, f_sun: float, overrides: dict) -> dict:
    """The spec's `[motor]` table with the drive type, speed and start replaced (as
    `dtwin.spec.build.drive_part` does) and the shaft/controller overrides applied."""
    table = {k: v for k, v in dict(spec["motor"] or {}).items() if v is not None}
    table["type"] = motor_type
    if start == "steady":
        table["start"] = "constant"
        table["speed_rpm"] = 60.0 * f_sun
    else:
        table.setdefault("speed_rpm", 60.0 * f_sun)
    for key in ("k_shaft", "c_shaft"):
        if overrides.get(key) is not None:
            table[key] = float(overrides[key])
    sub = dict(table.get("pmsm", {}) or {})
    for key in ("speed_bandwidth", "current_bandwidth"):
        if overrides.get(key) is not None:
            sub[key] = float(overrides[key])
    if sub:
        table["pmsm"] = sub
    if motor_type == "ideal":
        table.pop("pmsm", None)
        table.pop("induction", None)
    return table


def comparison_twins(
    spec,
    *,
    kind: str | None = None,
    start: str = "steady",
    f_sun: float | None = None,
    tooth: int = 0,
    severity: float = 0.0,
    k_shaft: float | None = None,
    c_shaft: float | None = None,
    speed_bandwidth: float | None = None,
    current_bandwidth: float | None = None,
) -> tuple[Twin, Twin]:
    """The traditional twin (ideal speed source) and the coupled twin (PMSM), identical apart
    from the drive part, both with a sun missing tooth.

    The spec's own faults are replaced by one :class:`~dtwin.model.faults.MissingTooth` on sun tooth
    `tooth` (so that :func:`with_severity` can set its severity); everything else (gears,
    supports, load, sensor, imperfections) comes from the spec through
    :func:`dtwin.spec.build.build_twin`. Both drives are built by
    :func:`dtwin.spec.motor.drive_from_spec` from the spec's `[motor]` table with ``type`` set to
    ``"ideal"`` and ``"pmsm"``, so they share the `Shaft`.

    **Arguments:**

    - `spec`: a `dtwin.spec.Spec` (or what `load_spec` accepts).
    - `kind`: ``"translational"`` / ``"torsional"`` (default: the spec's `model.kind`).
    - `start`: ``"steady"`` (drives at the set speed from t = 0) or ``"rest"`` (the `[motor]`
      table's start, by default the paper's STEP from standstill).
    - `f_sun`: input speed (Hz), default `operating.f_sun`.
    - `tooth`: index of the faulty sun tooth.
    - `severity`: initial severity in [0, 1].
    - `k_shaft` (N·m/rad), `c_shaft` (N·m·s/rad), `speed_bandwidth`, `current_bandwidth` (Hz):
      overrides of the `[motor]` table (None: the table's value or the documented default).

    **Returns:** ``(traditional, coupled)``.
    """
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    if start not in ("steady", "rest"):
        raise SpecError([("start", f"must be 'steady' or 'rest', got {start!r}")])
    f = operating_speed(spec) if f_sun is None else float(f_sun)
    overrides = dict(k_shaft=k_shaft, c_shaft=c_shaft, speed_bandwidth=speed_bandwidth,
                     current_bandwidth=current_bandwidth)
    fault = MissingTooth(severity, location="sun", tooth=int(tooth))
    base = build_twin(spec, kind=kind, faults=(fault,), start=start, f_sun=f)
    i = _drive_index(base)
    twins = []
    for motor_type in ("ideal", "pmsm"):
        drive = drive_from_spec(_motor_table(spec, motor_type, start, f, overrides))
        twins.append(eqx.tree_at(lambda t: t.parts[i], base, DrivePart(drive)))
    return twins[0], twins[1]


def _drive_index(twin: Twin) -> int:
    idx = [j for j, p in enumerate(twin.parts) if isinstance(p, DrivePart)]
    if len(idx) != 1:
        raise SpecError([("motor", f"the comparison needs exactly one drive part, found {len(idx)}")])
    return idx[0]


def _fault_index(twin: Twin) -> int:
    idx = [j for j, p in enumerate(twin.parts)
           if isinstance(p, LocalFault) and isinstance(p.fault, MissingTooth)
           and p.fault.location == "sun"]
    if len(idx) != 1:
        raise SpecError([("faults", "the comparison needs exactly one sun missing tooth "
                          f"(build the twins with comparison_twins), found {len(idx)}")])
    return idx[0]


def with_severity(twin: Twin, severity: Float[Array, ""] | float) -> Twin:
    """`twin` with the severity of its sun missing tooth replaced (differentiable, traceable).

    **Arguments:** `twin` (from :func:`comparison_twins`), `severity` (fraction of the face width
    removed, in [0, 1]; may be a tracer). **Returns:** the new `Twin`.
    """
    i = _fault_index(twin)
    return eqx.tree_at(lambda t: t.parts[i].fault.severity, twin,
                       jnp.asarray(severity, dtype=jnp.float64))


def set_drive_parameters(
    twin: Twin,
    *,
    k_shaft: float | Array | None = None,
    c_shaft: float | Array | None = None,
    speed_bandwidth: float | Array | None = None,
) -> Twin:
    """`twin` with the drive's shaft stiffness (N·m/rad), shaft damping (N·m·s/rad) or speed-loop
    bandwidth (Hz, PMSM only; ignored by the ideal source) replaced. The leaves are arrays, so a
    jitted solve is not recompiled."""
    i = _drive_index(twin)
    drive = twin.parts[i].drive
    if k_shaft is not None:
        drive = eqx.tree_at(lambda d: d.shaft.k_shaft, drive, jnp.asarray(k_shaft, jnp.float64))
    if c_shaft is not None:
        drive = eqx.tree_at(lambda d: d.shaft.c_shaft, drive, jnp.asarray(c_shaft, jnp.float64))
    if speed_bandwidth is not None and hasattr(drive, "speed_bandwidth"):
        drive = eqx.tree_at(lambda d: d.speed_bandwidth, drive,
                            jnp.asarray(speed_bandwidth, jnp.float64))
    return eqx.tree_at(lambda t: t.parts[i].drive, twin, drive)


# --------------------------------------------------------------------------------- indicator
@dataclasses.dataclass(frozen=True)
class _Run:
    """Static settings of one RMS evaluation. `simulate` is not jittable as a whole (it reads
    the time grid as Python floats); its solve is, and `jax.vmap`/`jax.jvp` go through it."""

    f_sun: float
    duration: float
    discard: float
    start: str
    daq: DAQ
    solver: SolverOptions


def _rms(twin: Twin, severity, run: _Run):
    res = simulate(with_severity(twin, severity), duration=run.duration, f_sun=run.f_sun,
                   daq=run.daq, start=run.start, discard=run.discard, solver=run.solver,
                   check=False)
    x = res.signal
    return jnp.sqrt(jnp.mean((x - jnp.mean(x)) ** 2))


def _rms_batch(twin: Twin, severities, run: _Run):
    return jax.vmap(lambda s: _rms(twin, s, run))(severities)


def _rms_slope_batch(twin: Twin, severities, run: _Run):
    def one(s):
        return jax.jvp(lambda u: _rms(twin, u, run), (s,), (jnp.ones_like(s),))

    return jax.vmap(one)(severities)


def _run(f_sun, duration, discard, start, daq, solver) -> _Run:
    if not (duration > 0 and math.isfinite(duration)):
        raise ValueError(f"duration must be a positive number of seconds, got {duration}")
    solver = solver or SOLVER_DEFAULT
    if solver.adjoint != "forward":
        solver = dataclasses.replace(solver, adjoint="forward")
    return _Run(float(f_sun), float(duration), float(discard), start, daq or DAQ(), solver)


def _severity_array(severities) -> np.ndarray:
    s = np.atleast_1d(np.asarray(severities, dtype=np.float64))
    if s.ndim != 1 or s.size == 0:
        raise SpecError([("severities", "give a non-empty list of severities")])
    if not np.all((s >= 0.0) & (s <= 1.0)):
        raise SpecError([("severities", f"every severity must lie in [0, 1] (fraction of the "
                          f"face width removed), got {s.tolist()}")])
    return s


def _finite(values, what: str) -> np.ndarray:
    arr = np.asarray(values)
    if not np.all(np.isfinite(arr)):
        raise SolverError(
            f"the ODE solve for the {what} failed (non-finite result): raise "
            "SolverOptions(max_steps=...), shorten the record or check the parameters"
        )
    return arr


def fault_rms(
    twin: Twin,
    severities: Sequence[float] | Float[Array, " s"],
    *,
    f_sun: float,
    duration: float = 0.5,
    discard: float = 0.1,
    start: str = "steady",
    daq: DAQ | None = None,
    solver: SolverOptions | None = None,
    vectorise: bool = True,
) -> np.ndarray:
    """RMS of the sensor signal over the steady window for each sun-fault severity.

    **Arguments:**

    - `twin`: a twin from :func:`comparison_twins` (either drive).
    - `severities`: fraction of the sun tooth's face width removed, each in [0, 1].
    - `f_sun`: input speed (Hz); `duration`: steady window (s); `discard`: transient simulated
      before the window (s); `start`: ``"steady"`` or ``"rest"``.
    - `daq`: DAQ settings (the quantity sets the unit of the RMS); `solver`: solver settings.
    - `vectorise`: one `jax.vmap` over the severities (True) or a loop of single solves.

    **Returns:** RMS per severity (numpy, unit of the DAQ quantity).
    """
    run = _run(f_sun, duration, discard, start, daq, solver)
    s = _severity_array(severities)
    if vectorise:
        out = _rms_batch(twin, jnp.asarray(s), run)
    else:
        out = jnp.concatenate([_rms_batch(twin, jnp.asarray(s[k : k + 1]), run)
                               for k in range(s.size)])
    return _finite(out, "RMS")


def fault_rms_and_slope(
    twin: Twin,
    severities: Sequence[float] | Float[Array, " s"],
    *,
    f_sun: float,
    duration: float = 0.5,
    discard: float = 0.1,
    start: str = "steady",
    daq: DAQ | None = None,
    solver: SolverOptions | None = None,
    vectorise: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """RMS and its sensitivity ``dRMS/dseverity`` at each severity (forward-mode autodiff).

    One `jax.jvp` through the solve per severity (tangent 1 on the severity), vectorised with
    `jax.vmap` when `vectorise`. Arguments as :func:`fault_rms`; the solver's adjoint is forced
    to ``"forward"``.

    **Returns:** ``(rms, slope)``: numpy arrays, unit of the DAQ quantity (per unit severity).
    """
    run = _run(f_sun, duration, discard, start, daq, solver)
    s = _severity_array(severities)
    if vectorise:
        rms, slope = _rms_slope_batch(twin, jnp.asarray(s), run)
    else:
        parts = [_rms_slope_batch(twin, jnp.asarray(s[k : k + 1]), run) for k in range(s.size)]
        rms = jnp.concatenate([p[0] for p in parts])
        slope = jnp.concatenate([p[1] for p in parts])
    return _finite(rms, "RMS"), _finite(slope, "RMS sensitivity")


# --------------------------------------------------------------------------------- comparison
@dataclasses.dataclass(frozen=True)
class DriveComparison:
    """RMS of the sensor signal versus sun-fault severity for the two models (Figure 15).

    - `severities`: (s,) fraction of the sun tooth's face width removed;
    - `rms`, `slope`: ``{"traditional": (s,), "coupled": (s,)}`` RMS (`unit`) and ``dRMS/ds``
      (`unit` per unit severity; None when not computed);
    - `unit`: unit of the sensor quantity; `settings`: how the records were made.
    """

    severities: np.ndarray
    rms: dict[str, np.ndarray]
    slope: dict[str, np.ndarray] | None
    unit: str
    settings: dict[str, Any]

    def relative_rise(self, model: str) -> np.ndarray:
        """``RMS(s) / RMS(s_0) - 1`` (1) relative to the first severity."""
        r = self.rms[model]
        return r / r[0] - 1.0

    def mean_slope(self, model: str) -> float:
        """Secant slope ``(RMS(s_last) - RMS(s_0)) / (s_last - s_0)`` (`unit` per severity)."""
        s, r = self.severities, self.rms[model]
        return float((r[-1] - r[0]) / (s[-1] - s[0])) if s.size > 1 else float("nan")

    def rows(self) -> list[dict[str, float]]:
        """One row per severity: RMS, rise over the first severity and slope of both models."""
        out = []
        for k, s in enumerate(self.severities):
            row: dict[str, float] = {"severity": float(s)}
            for m in MODELS:
                row[f"rms_{m}"] = float(self.rms[m][k])
                row[f"rise_{m}"] = float(self.relative_rise(m)[k])
                if self.slope is not None:
                    row[f"slope_{m}"] = float(self.slope[m][k])
            out.append(row)
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (rows, settings, secant slopes and their ratio coupled/traditional)."""
        sec = {m: self.mean_slope(m) for m in MODELS}
        out: dict[str, Any] = {
            "unit": self.unit,
            "settings": dict(self.settings),
            "rows": self.rows(),
            "secant_slope": sec,
            "secant_slope_ratio": sec["coupled"] / sec["traditional"]
            if sec["traditional"] else float("nan"),
        }
        if self.slope is not None:
            out["mean_autodiff_slope"] = {m: float(np.mean(self.slope[m])) for m in MODELS}
        return out


_UNITS = {"acceleration": "m/s^2", "velocity": "m/s", "displacement": "m", "ring_velocity": "m/s"}


def compare_drives(
    spec,
    severities: Sequence[float] = SEVERITIES_DEFAULT,
    *,
    kind: str | None = None,
    duration: float = 0.5,
    discard: float = 0.1,
    start: str = "steady",
    f_sun: float | None = None,
    daq: DAQ | None = None,
    solver: SolverOptions | None = None,
    sensitivity: bool = True,
    vectorise: bool = True,
    k_shaft: float | None = None,
    c_shaft: float | None = None,
    speed_bandwidth: float | None = None,
    tooth: int = 0,
) -> DriveComparison:
    """The paper's Figure 15: RMS versus sun missing-tooth severity, traditional and coupled.

    **Arguments:**

    - `spec`: gearbox spec (`Spec`, path or mapping).
    - `severities`: sun-tooth severities in [0, 1] (fraction of the face width removed).
    - `kind`: ``"translational"`` / ``"torsional"`` (default: the spec's).
    - `duration`: steady window (s) over which the RMS is taken; `discard`: transient before it (s).
    - `start`: ``"steady"`` (at speed) or ``"rest"`` (the paper's STEP; give `discard` ≥ 0.3 s).
    - `f_sun`: input speed (Hz); `daq`: DAQ settings (default: the spec's `[sensor]`).
    - `solver`: solver settings (default `SOLVER_DEFAULT` with `sensitivity`, the twin's default
      `SolverOptions()` without; the forward adjoint is forced).
    - `sensitivity`: also compute ``dRMS/ds`` by forward-mode autodiff.
    - `vectorise`: `jax.vmap` over the severities.
    - `k_shaft` (N·m/rad), `c_shaft` (N·m·s/rad), `speed_bandwidth` (Hz): drive overrides.
    - `tooth`: faulty sun tooth.

    **Returns:** a :class:`DriveComparison`.
    """
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    f = operating_speed(spec) if f_sun is None else float(f_sun)
    daq = daq or daq_from_spec(spec)
    trad, coup = comparison_twins(spec, kind=kind, start=start, f_sun=f, tooth=tooth,
                                  k_shaft=k_shaft, c_shaft=c_shaft,
                                  speed_bandwidth=speed_bandwidth)
    if solver is None and not sensitivity:
        solver = SolverOptions()  # the RMS alone is accurate to ~1e-4 at the twin's tolerance
    kw = dict(f_sun=f, duration=duration, discard=discard, start=start, daq=daq, solver=solver,
              vectorise=vectorise)
    s = _severity_array(severities)
    rms: dict[str, np.ndarray] = {}
    slope: dict[str, np.ndarray] | None = {} if sensitivity else None
    for name, tw in zip(MODELS, (trad, coup), strict=True):
        if sensitivity:
            rms[name], slope[name] = fault_rms_and_slope(tw, s, **kw)  # type: ignore[index]
        else:
            rms[name] = fault_rms(tw, s, **kw)
    shaft = coup.parts[_drive_index(coup)].drive.shaft
    settings = {
        "spec": spec.name, "kind": trad.kind, "f_sun_hz": f, "duration_s": duration,
        "discard_s": discard, "start": start, "quantity": daq.quantity,
        "sample_rate_hz": daq.sample_rate, "fault": f"sun:missing_tooth (tooth {tooth})",
        "k_shaft": float(shaft.k_shaft), "c_shaft": float(shaft.c_shaft),
        "speed_bandwidth_hz": float(coup.parts[_drive_index(coup)].drive.speed_bandwidth),
        "traditional": "IdealSpeedSource", "coupled": "PMSM (FOC)",
    }
    return DriveComparison(s, rms, slope, _UNITS[daq.quantity], settings)


# --------------------------------------------------------------------------------- sweep
@dataclasses.dataclass(frozen=True)
class SensitivitySweep:
    """``dRMS/ds`` at one severity versus shaft stiffness and speed-loop bandwidth.

    - `severity`: where the slope is taken; `k_shafts` (k,) N·m/rad; `bandwidths` (b,) Hz;
    - `traditional`: (k,) slope of the ideal-source model (independent of the bandwidth);
    - `coupled`: (k, b) slope of the PMSM-coupled twin;
    - `rms_traditional` (k,), `rms_coupled` (k, b): RMS at `severity`; `unit`, `settings`.
    """

    severity: float
    k_shafts: np.ndarray
    bandwidths: np.ndarray
    traditional: np.ndarray
    coupled: np.ndarray
    rms_traditional: np.ndarray
    rms_coupled: np.ndarray
    unit: str
    settings: dict[str, Any]

    def ratio(self) -> np.ndarray:
        """(k, b) sensitivity of the coupled twin over the traditional model's (1)."""
        return self.coupled / self.traditional[:, None]

    def to_dict(self) -> dict[str, Any]:
        return {
            "severity": self.severity, "unit": self.unit, "settings": dict(self.settings),
            "k_shaft": self.k_shafts.tolist(), "speed_bandwidth_hz": self.bandwidths.tolist(),
            "slope_traditional": self.traditional.tolist(), "slope_coupled": self.coupled.tolist(),
            "rms_traditional": self.rms_traditional.tolist(),
            "rms_coupled": self.rms_coupled.tolist(), "ratio": self.ratio().tolist(),
        }


def sensitivity_sweep(
    spec,
    *,
    severity: float = 0.5,
    k_shafts: Sequence[float] = (500.0, 2000.0, 8000.0, 32000.0),
    bandwidths: Sequence[float] = (5.0, 20.0, 80.0),
    kind: str | None = None,
    duration: float = 0.5,
    discard: float = 0.1,
    f_sun: float | None = None,
    daq: DAQ | None = None,
    solver: SolverOptions | None = None,
) -> SensitivitySweep:
    """``dRMS/ds`` of both models at `severity` for each shaft stiffness (N·m/rad) and, for the
    coupled twin, each speed-loop bandwidth (Hz). The parameters are array leaves of the drive
    (:func:`set_drive_parameters`), so one compiled solve per model serves the whole sweep.
    Other arguments as :func:`compare_drives` (``start="steady"``)."""
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    f = operating_speed(spec) if f_sun is None else float(f_sun)
    daq = daq or daq_from_spec(spec)
    trad, coup = comparison_twins(spec, kind=kind, f_sun=f)
    kw = dict(f_sun=f, duration=duration, discard=discard, daq=daq, solver=solver)
    ks = np.asarray(k_shafts, dtype=np.float64)
    bws = np.asarray(bandwidths, dtype=np.float64)
    st, rt = np.zeros(ks.size), np.zeros(ks.size)
    sc, rc = np.zeros((ks.size, bws.size)), np.zeros((ks.size, bws.size))
    for i, k in enumerate(ks):
        r, d = fault_rms_and_slope(set_drive_parameters(trad, k_shaft=k), [severity], **kw)
        rt[i], st[i] = r[0], d[0]
        for j, b in enumerate(bws):
            tw = set_drive_parameters(coup, k_shaft=k, speed_bandwidth=b)
            r, d = fault_rms_and_slope(tw, [severity], **kw)
            rc[i, j], sc[i, j] = r[0], d[0]
    settings = {"spec": spec.name, "kind": trad.kind, "f_sun_hz": f, "duration_s": duration,
                "discard_s": discard, "quantity": daq.quantity}
    return SensitivitySweep(float(severity), ks, bws, st, sc, rt, rc, _UNITS[daq.quantity],
                            settings)
