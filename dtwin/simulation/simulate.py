"""The diffrax solve: a twin → a sampled sensor record, as a DAQ would record it.

Pipeline (docs/references.md §6):

1. initial state: a steady state at the operating speed (static mesh deflections under the
   load, drive pre-loaded) or rest;
2. adaptive explicit Runge–Kutta (Tsit5 with its stages unrolled, `dtwin.simulation.integrator`; PID
   step-size control) on scaled integration
   coordinates (`dtwin.model.twin`), the state saved on a grid `oversample` times finer than the DAQ
   rate (at constant speed, with `SolverOptions(periodic="auto")`, only a settling time and one
   period of the gear set are integrated and the grid's later samples taken at their phases in
   it, advanced by the rigid rotation: `dtwin.simulation.periodic`); the sensor signal is computed from
   the states with the model's own equations
   (accelerations from the vector field, batched with `vmap` over the saved times: no
   differentiation of sampled output);
3. DAQ: a linear-phase FIR low-pass (Kaiser window, cut-off 0.4 × the output rate, ≥ 80 dB
   stop band at the output Nyquist) and decimation to `sample_rate`; then optional integration
   to velocity/displacement (frequency domain, high-pass at `f_highpass`), measurement noise
   at a given SNR and a tachometer channel.

Everything is JAX: `simulate(..., check=False)` is differentiable with respect to the twin's parameters
(forward mode through `diffrax.ForwardMode()`, or reverse through the default adjoint).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .. import _maps
from ..errors import SolverError
from ..io.record import Record
from ..model.motor.drive import DrivePart
from ..model.motor.speed_source import IdealSpeedSource
from ..model.parts.transfer_path import AbstractTransferPath, ring_velocity_fixed
from ..model.statics import static_balance
from ..model.twin import Twin
from .integrator import UnrolledTsit5
from .periodic import (
    fold_times,
    mechanical_cycles,
    mechanical_reason,
    mesh_frequency,
    rigid_advance,
)
from .sensor_response import apply_frf, knot_basis

QUANTITIES = ("acceleration", "velocity", "displacement", "ring_velocity")
#: Default of `SolverOptions.rate_scale_hz` (Hz): rates are scaled by 2π times this.
RATE_SCALE_HZ = 10_000.0


@dataclasses.dataclass(frozen=True)
class SolverOptions:
    """Solver settings.

    - `rtol`, `atol`: tolerances on the scaled state (`state_scales`: translations and rotations
      in µm, a rotation as the arc on its gear's base circle; rates in µm × 2π `rate_scale_hz`),
      so `atol = 1e-5` means ~1e-11 m. With the defaults the sensor signal of the paper's
      gearbox is accurate to ~5e-5 of its rms, the numerical error's largest spectral line is
      ~98 dB below the signal's strongest, and in an ideal gearbox the lines the sideband rule
      forbids stay ≥ ~65 dB below f_mesh (measured: benchmarks/README.md).
    - `rate_scale_hz`: the frequency (Hz) that converts a displacement scale into a rate scale,
      `sv = 2π rate_scale_hz sz`. A mode at this frequency weighs its displacement and velocity
      errors alike in the error norm; slower motion is controlled by its displacement, faster
      by its velocity. The default 10 kHz is the order of the highest mesh modes of gearboxes
      of the paper's size (8–17 kHz); a lower value tightens control of the fastest modes (and
      costs steps: 1 kHz takes ~40 % more on the paper's gearbox).
    - `pcoeff`, `icoeff`: the step-size controller's proportional and integral coefficients
      (`diffrax.PIDController`); the default PI controller (0.3, 0.3) rejects ~8 % of the
      attempted steps where the integral-only controller (0, 1) rejects ~27 % on the twin, whose
      step is near the stability limit of its ~12 kHz mode (benchmarks/README.md).
    - `dtmax`: largest step (s); None → a tenth of a mesh period.
    - `max_steps`: None → 400 000 per simulated second.
    - `adjoint`: ``"forward"`` (for `jax.jacfwd`/`jvp`), ``"reverse"`` (checkpointed, for
      `jax.grad`).
    - `unrolled`: True (default) → `dtwin.simulation.integrator.UnrolledTsit5`, the same method as
      `diffrax.Tsit5` with the stages written out (~5–20 % less time per step on a CPU); False →
      `diffrax.Tsit5` itself (same steps and solution to rounding).
    - `periodic`: ``"off"`` (default): the whole record is integrated. ``"auto"``: when the twin
      runs at constant speed and its gear set's motion is periodic
      (`dtwin.simulation.periodic.mechanical_cycles`: one mesh cycle for a healthy gearbox, `Zs` cycles
      with a sun fault, …), only `periodic_settle` s of start-up transient and one such period
      are integrated, the record's later samples are taken at their phases in that period
      advanced by the rigid rotation, and the housing paths' filters (which see the planets
      pass with the carrier's period) are applied to the whole record afterwards (reference §6,
      "Periodic steady state"); used when `periodic_settle` + the period + a probe window fit
      in at most `periodic_max_fraction` of the simulated span, otherwise the whole record is
      integrated. `simulate` checks the periodicity (the signal over a probe window one period
      after the settling time, as integrated and as tiled: relative rms difference
      `SimResult.periodic_defect`); where it exceeds
      `periodic_tol` it tries a longer settling time (`longer_settle`) and then integrates the
      whole record; `SimResult.method` says which was used. The
      default None means ``max(1e-3, 50 rtol)``: the defect also holds the integrator's own
      error of two periods, which grows with `rtol` (measured on a calibrated twin of the
      paper's gearbox: 7.6e-5 at rtol 1e-5, 2.6–3.0e-3 at rtol 1e-4 whatever the settling
      time), so a fixed 1e-3 would send every simulation at rtol 1e-4 to the whole record.
    """

    rtol: float = 1e-5
    atol: float = 1e-5
    rate_scale_hz: float = RATE_SCALE_HZ
    pcoeff: float = 0.3
    icoeff: float = 0.3
    dtmax: float | None = None
    max_steps: int | None = None
    adjoint: str = "forward"
    unrolled: bool = True
    periodic: str = "off"
    periodic_settle: float = 0.1
    periodic_tol: float | None = None
    periodic_max_fraction: float = 0.75

    def __post_init__(self):
        if self.periodic not in ("off", "auto"):
            raise ValueError(f"SolverOptions.periodic must be 'off' or 'auto', got {self.periodic!r}")
        if not (0.0 <= self.periodic_settle < math.inf and 0.0 < self.periodic_max_fraction <= 1.0):
            raise ValueError("SolverOptions.periodic_settle must be >= 0 s and "
                             "periodic_max_fraction in (0, 1]")
        for name in ("rtol", "atol", "rate_scale_hz", "periodic_tol"):
            v = getattr(self, name)
            if name == "periodic_tol" and v is None:
                continue
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"SolverOptions.{name} must be a positive number, got {v!r}")


    @property
    def periodic_tolerance(self) -> float:
        """The periodicity defect above which the whole record is integrated (`periodic_tol`,
        or ``max(1e-3, 50 rtol)`` when None)."""
        return self.periodic_tol if self.periodic_tol is not None else max(1e-3, 50.0 * self.rtol)


#: End of a DAQ's anti-aliasing pass band, as a fraction of its sampling rate, where the spec
#: states none: a delta-sigma converter's digital filter passes flat to about 0.45 fs (a
#: classic analyser's fs/2.56 = 0.39 fs is the other common choice).
DEFAULT_PASSBAND = 0.45
#: Stop-band attenuation (dB) of the anti-aliasing filter from ``(1 − passband) fs`` up: what
#: folds onto the pass band's edge lies this far down.
STOPBAND_DB = 80.0


@dataclasses.dataclass(frozen=True)
class DAQ:
    """Data-acquisition settings of the simulated sensor.

    - `sample_rate`: output rate (Hz), default 5 kHz as in the paper.
    - `oversample`: internal rate = `oversample` × `sample_rate` (anti-aliasing, reference §6).
    - `quantity`: ``acceleration`` (m/s², default), ``velocity`` (m/s), ``displacement`` (m) of
      the sensor, or ``ring_velocity`` (the ring's velocity along the sensor axis, what the
      paper's simulation plotted).
    - `gain`: sensor gain (1).
    - `f_highpass`: corner (Hz) of the high-pass used when integrating to velocity/displacement.
    - `snr_db`: measurement noise, signal power over noise power over the record (dB); None =
      no noise.
    - `tacho_ppr`, `tacho_shaft`: tachometer pulses per revolution of ``"sun"`` or
      ``"carrier"``; None = no tachometer.
    - `passband`: end of the anti-aliasing filter's pass band, a fraction of `sample_rate`
      (:func:`daq_filter`; default :data:`DEFAULT_PASSBAND`, a delta-sigma DAQ's 0.45).
    - `frf_hz`, `frf_db`: a smooth sensor frequency response (knots in Hz and gains in dB,
      :mod:`dtwin.simulation.sensor_response`) applied to the sampled signal before any integration and
      noise; None = flat (a gain of 1).
    """

    sample_rate: float = 5000.0
    oversample: int = 4
    quantity: str = "acceleration"
    gain: float = 1.0
    f_highpass: float = 2.0
    snr_db: float | None = None
    tacho_ppr: int | None = None
    tacho_shaft: str = "sun"
    frf_hz: tuple[float, ...] | None = None
    frf_db: tuple[float, ...] | None = None
    passband: float = DEFAULT_PASSBAND

    def __post_init__(self):
        if self.quantity not in QUANTITIES:
            raise ValueError(f"quantity must be one of {QUANTITIES}, got {self.quantity!r}")
        if not (self.sample_rate > 0 and math.isfinite(self.sample_rate)):
            raise ValueError(f"sample_rate must be a positive number of Hz, got {self.sample_rate}")
        if self.oversample < 2:
            raise ValueError("oversample must be >= 2 so the DAQ filter can remove aliases")
        if self.tacho_shaft not in ("sun", "carrier"):
            raise ValueError(f"tacho_shaft must be 'sun' or 'carrier', got {self.tacho_shaft!r}")
        if (self.frf_hz is None) != (self.frf_db is None) or (
            self.frf_hz is not None and len(self.frf_hz) != len(self.frf_db)
        ):
            raise ValueError("frf_hz and frf_db go together, one gain (dB) per knot (Hz)")
        if self.frf_hz is not None:
            object.__setattr__(self, "frf_hz", tuple(float(v) for v in self.frf_hz))
            object.__setattr__(self, "frf_db", tuple(float(v) for v in self.frf_db))
            knot_basis([1.0], self.frf_hz)  # validates the knots


class SimResult(eqx.Module):
    """A simulated record and the model's internal signals, at the DAQ rate.

    - `time` (s), `signal` (the sensor, unit of `quantity`), `tacho` (V, or None);
    - `outputs`: named internal signals, point-sampled at the DAQ rate (not anti-alias
      filtered): shaft angles `theta_sun`, `theta_carrier` (rad) and speeds `omega_sun`,
      `omega_carrier` (rad/s), total mesh forces `force_sun_planet`, `force_ring_planet` (N,
      summed over planets), mean mesh deflections `deflection_sun_planet`,
      `deflection_ring_planet` (m) and the least over the planets
      `least_deflection_sun_planet`, `least_deflection_ring_planet` (m: below 0 the teeth of
      that mesh part), dissipated powers (W), drive and load outputs (torques N·m,
      currents A, powers W …);
    - `num_steps`: accepted solver steps; `f_sun`: nominal input speed (Hz).
    - `method`: ``"full"`` (the whole record integrated) or ``"periodic"`` (one period of the
      gear set after a settling time, tiled: `SolverOptions.periodic`), with the reason when
      ``periodic="auto"`` fell back; `periodic_defect`: the relative rms difference of the
      signal as integrated and as tiled over a probe window (None when not tiled).
    """

    time: Float[Array, " n"]
    signal: Float[Array, " n"]
    tacho: Float[Array, " n"] | None
    outputs: dict[str, Float[Array, " n"]]
    num_steps: Any
    sample_rate: float = eqx.field(static=True)
    quantity: str = eqx.field(static=True)
    method: str = eqx.field(static=True, default="full")
    periodic_defect: Any = None

    def to_record(self, metadata: dict | None = None):
        """The result as a `dtwin.io.Record` (channel ``vibration``, optional tachometer)."""
        unit = {"acceleration": "m/s^2", "velocity": "m/s", "displacement": "m",
                "ring_velocity": "m/s"}[self.quantity]
        return Record(
            data=np.asarray(self.signal)[None, :],
            sample_rate=float(self.sample_rate),
            channels=("vibration",),
            units=(unit,),
            tacho=None if self.tacho is None else np.asarray(self.tacho),
            metadata=dict(metadata or {}),
        )


# --------------------------------------------------------------------------------- state
def state_scales(twin: Twin, rate_scale_hz: float = RATE_SCALE_HZ) -> tuple[Array, Array]:
    """Scales of the integration coordinates z and their rates, so that the error control sees
    lengths along the lines of action: translations 1e-6 m; a gear's rotation deviation
    1e-6 m / (its base radius) rad (1 µm of arc on its base circle, the unit in which it enters
    the mesh deflections); the carrier angle 1 rad. Rates: `2π rate_scale_hz` times these
    (`SolverOptions.rate_scale_hz`), the carrier speed 10 rad/s."""
    rb_s, rb_p, rb_r = jax.lax.stop_gradient((twin.lp.rb_sun, twin.lp.rb_planet, twin.lp.rb_ring))
    sz = jnp.full(twin.n_dof, 1e-6)
    sz = sz.at[twin._index("theta_s")].set(1e-6 / rb_s)
    sz = sz.at[twin._index("theta_r")].set(1e-6 / rb_r)
    for i in range(twin.n_planets):
        sz = sz.at[twin._index("theta_p", i)].set(1e-6 / rb_p)
    sz = sz.at[twin._index("theta_c")].set(1.0)
    sv = sz * 2.0 * jnp.pi * rate_scale_hz
    sv = sv.at[twin._index("theta_c")].set(10.0)
    return sz, sv


def initial_state(twin: Twin, f_sun: float | Array, start: str = "steady"):
    """Initial `(z, z', aux)` (unscaled) for a run at input speed `f_sun` (Hz).

    ``start="steady"``: rigid rotation at the operating speed with the static mesh and bearing
    deflections of the mean-stiffness model under the load torque (solved with the carrier
    angle held), and the drive in its steady state delivering the balancing torque.
    ``start="rest"``: everything at rest, undeflected (the paper's start from standstill).
    """
    rs, _ = twin.kinematic_ratios
    n = twin.n_dof
    ic = twin._index("theta_c")
    omega_s = 2.0 * jnp.pi * jnp.asarray(f_sun, dtype=jnp.float64)
    if start == "rest":
        z = jnp.zeros(n)
        zd = jnp.zeros(n)
        aux = [p.aux_init(twin, jnp.zeros(())) for p in twin.parts]
    elif start == "steady":
        omega_c = omega_s / rs
        A, keep, K, F, torque_sun = static_balance(twin, omega_c)
        x = jnp.linalg.solve(K, F)
        z = jnp.zeros(n).at[keep].set(x)
        zd = jnp.zeros(n).at[ic].set(omega_c)
        aux = []
        q0, qd0 = twin.unpack(A @ z), twin.unpack(A @ zd)
        mesh0 = None
        for p in twin.parts:
            if isinstance(p, DrivePart):
                aux.append(p.aux_init(twin, omega_s, torque_sun))
            elif hasattr(p, "aux_from_state"):
                # parts whose states follow the gear set (filters): start them in steady state
                if mesh0 is None:
                    t0 = jnp.zeros(())
                    mesh0 = twin.mesh_state(t0, q0, qd0, twin.modulation(t0, q0, qd0))
                aux.append(p.aux_from_state(twin, jnp.zeros(()), q0, qd0, mesh0))
            else:
                aux.append(p.aux_init(twin, omega_s))
    else:
        raise ValueError(f"start must be 'steady' or 'rest', got {start!r}")
    aux = jnp.concatenate([jnp.asarray(a, dtype=jnp.float64).reshape(-1) for a in aux]) if aux else jnp.zeros(0)
    return z, zd, aux


_initial_state_jit = eqx.filter_jit(initial_state)


def _initial_state_compiled(twin: Twin, f_sun, start: str):
    """`initial_state` compiled as one program: run op by op it dispatches (and, the first time,
    compiles) hundreds of small operations, several seconds on a loaded CPU. Parts whose
    initial state needs concrete values fall back to the op-by-op form."""
    try:
        return _initial_state_jit(twin, jnp.asarray(f_sun, dtype=jnp.float64), start)
    except jax.errors.JAXTypeError:
        return initial_state(twin, f_sun, start)


# --------------------------------------------------------------------------------- solve
@functools.lru_cache(maxsize=32)
def _daq_taps(oversample: int, passband: float) -> np.ndarray:
    import scipy.signal  # deferred: scipy.signal takes seconds to import; `import dtwin` stays light

    # normalised to the internal Nyquist frequency (oversample × fs / 2): the band from
    # passband·fs to (1 − passband)·fs, which decimation folds onto itself, is the transition
    width = 2.0 * (1.0 - 2.0 * passband) / oversample
    numtaps, beta = scipy.signal.kaiserord(STOPBAND_DB + 3.0, width)  # 3 dB design margin
    numtaps += 1 - numtaps % 2  # odd: a centred, zero-phase filter
    taps = scipy.signal.firwin(numtaps, 1.0 / oversample, window=("kaiser", beta))
    taps = taps / taps.sum()
    taps.setflags(write=False)
    return taps


def daq_filter(oversample: int, passband: float = DEFAULT_PASSBAND) -> np.ndarray:
    """FIR anti-aliasing filter taps of a DAQ (Kaiser window design, unit DC gain): flat (within
    ~0.001 dB) up to ``passband`` × the output rate, :data:`STOPBAND_DB` down from ``(1 −
    passband)`` × the output rate, the band that decimation by `oversample` folds onto the pass
    band; the transition is centred on the output Nyquist frequency.

    **Arguments:** `oversample` (internal rate over the output rate, ≥ 2); `passband` (fraction
    of the output rate, 0.3–0.49: 0.45 for a delta-sigma DAQ, 1/2.56 for a classic analyser).
    **Returns:** the taps (read-only), at the internal rate.
    """
    if not 0.3 <= float(passband) < 0.5:
        raise ValueError(f"passband must lie in [0.3, 0.5) of the sampling rate, got {passband}")
    return _daq_taps(int(oversample), float(passband))


def _filtered_paths(twin: Twin, quantity: str) -> list[int]:
    """Indices (in `twin.parts`) of the transfer paths whose states `_observe(..., split=True)`
    leaves to a filter after the solve (output-only paths with states)."""
    if quantity == "ring_velocity":
        return []
    return [i for i, p in enumerate(twin.parts) if isinstance(p, AbstractTransferPath)
            and p.output_only and p.aux_size > 0]


def _observe(twin: Twin, ops, quantity, t, y, split: bool = False):
    """The observables at time `t` (s) and state ``y = (z, z', aux)`` (unscaled). With
    `split`, the output-only transfer paths' states in `y` are ignored: the signal is computed
    with them at zero, and for each such path (`_filtered_paths`) the observables also hold
    its source (``"source_<i>"``) and the signal's derivative with respect to its states
    (``"gain_<i>"``), the signal being affine in them; `_filter_paths` completes it."""
    _, _, _, q, qdot, qddot, mesh, outputs = twin.accelerations(t, y, ops)
    extra = {}
    if quantity == "ring_velocity":
        paths = twin.find(AbstractTransferPath)
        ang = paths[0].direction_angle if paths else jnp.pi / 2
        d = jnp.stack([jnp.cos(ang), jnp.sin(ang)])
        sig = ring_velocity_fixed(q, qdot) @ d
    else:
        sig = jnp.zeros(())
        filtered = _filtered_paths(twin, quantity) if split else []
        for i, (p, a) in enumerate(zip(twin.parts, twin.split_aux(y[2]), strict=True)):
            if not isinstance(p, AbstractTransferPath):
                continue
            if i in filtered:
                def acc(states, p=p):
                    return p.acceleration(twin, t, q, qdot, qddot, mesh, states)

                zero = jnp.zeros_like(a)
                sig = sig + acc(zero)
                extra[f"gain_{i}"] = jax.jacfwd(acc)(zero)
                extra[f"source_{i}"] = p.source(twin, q, mesh)
            else:
                sig = sig + p.acceleration(twin, t, q, qdot, qddot, mesh, a)
    out = {
        "signal": sig,
        "theta_sun": q.theta_s,
        "theta_carrier": q.theta_c,
        "omega_sun": qdot.theta_s,
        "omega_carrier": qdot.theta_c,
        "force_sun_planet": jnp.sum(mesh.force_sp),
        "force_ring_planet": jnp.sum(mesh.force_rp),
        "deflection_sun_planet": jnp.mean(mesh.delta_sp),
        "deflection_ring_planet": jnp.mean(mesh.delta_rp),
        "least_deflection_sun_planet": jnp.min(mesh.delta_sp),
        "least_deflection_ring_planet": jnp.min(mesh.delta_rp),
    }
    for k, v in outputs.items():
        out[k] = jnp.asarray(v)
    out.update(extra)
    return out


@eqx.filter_jit
def _solve(twin: Twin, y0, t0, t1, ts, quantity: str, rtol, atol, dtmax, max_steps: int,
           adjoint: str, progress: bool, pcoeff, icoeff, unrolled: bool, rate_scale_hz: float):
    # every setting comes from `SolverOptions` (its defaults are the only ones)
    ops = twin.operators()
    ys, result, nsteps = _integrate(twin, ops, y0, t0, t1, ts, rtol, atol, dtmax, max_steps,
                                    adjoint, progress, pcoeff, icoeff, unrolled, rate_scale_hz)
    obs = jax.vmap(lambda t, y: _observe(twin, ops, quantity, t, y))(ts, ys)
    return obs, result, nsteps


def _integrate(twin: Twin, ops, y0, t0, t1, ts, rtol, atol, dtmax, max_steps: int, adjoint: str,
               progress: bool, pcoeff, icoeff, unrolled: bool, rate_scale_hz: float):
    """Integrate the twin from ``y0 = (z, z', aux)`` at `t0` to `t1` (s), the state saved at
    `ts`. **Returns** ``((z, z', aux) at ts (unscaled), result, accepted steps)``."""
    sz, sv = state_scales(twin, rate_scale_hz)
    n = twin.n_dof
    z0, zd0, aux0 = y0
    ys0 = jnp.concatenate([z0 / sz, zd0 / sv, aux0])

    def unflat(y):
        return y[:n] * sz, y[n : 2 * n] * sv, y[2 * n :]

    # `Twin.vector_field` on the scaled state, the scales folded into its constant matrices:
    # [q; L q; q'; L q'] = Wy y and z''/sv = By [F; y]
    m = 2 * twin.n_planets
    na = aux0.shape[0]
    Wy = (jnp.zeros((2 * (n + m), 2 * n + na))
          .at[: n + m, :n].set(ops.W * sz).at[n + m :, n : 2 * n].set(ops.W * sv))
    By = jnp.concatenate(
        [ops.B[:, : m + n], ops.B[:, m + n : m + 2 * n] * sz, ops.B[:, m + 2 * n :] * sv,
         jnp.zeros((n, na))], axis=1) / sv[:, None]

    def vf(t, y, args):
        X = Wy @ y
        F, daux = twin.generalised_forces(t, X[:n], X[n + m : 2 * n + m], X[n : n + m], X[2 * n + m :],
                                          y[2 * n :])
        return jnp.concatenate([y[n : 2 * n] * (sv / sz), By @ jnp.concatenate([F, y]), daux])

    # save the state only; the sensor is evaluated afterwards, batched over the saved times
    # (inside the solver loop it cost about as much as the integration itself)
    saveat = diffrax.SaveAt(ts=ts)
    adj = diffrax.ForwardMode() if adjoint == "forward" else diffrax.RecursiveCheckpointAdjoint()
    meter = diffrax.TextProgressMeter() if progress else diffrax.NoProgressMeter()
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(vf),
        UnrolledTsit5() if unrolled else diffrax.Tsit5(),
        t0=t0,
        t1=t1,
        dt0=None,
        y0=ys0,
        saveat=saveat,
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol, dtmax=dtmax, pcoeff=pcoeff,
                                                  icoeff=icoeff),
        max_steps=max_steps,
        adjoint=adj,
        throw=False,
        progress_meter=meter,
    )
    return jax.vmap(unflat)(sol.ys), sol.result, sol.stats["num_accepted_steps"]


#: High-rate samples of the window, just after the tiled period, over which the signal as
#: integrated is compared with the signal as tiled (`periodic_defect`).
PERIODIC_PROBE = 256


#: How much longer `longer_settle` lets the start-up transient decay, and its least time (s).
SETTLE_FACTOR, SETTLE_MIN = 5.0, 0.5


def longer_settle(solver: SolverOptions) -> SolverOptions:
    """`solver` with the settling time that a response found not periodic after
    `solver.periodic_settle` is tried with next (`SETTLE_FACTOR` times it, at least
    `SETTLE_MIN` s): a lightly damped mode of a drive or a housing can outlast the default
    settling time by several of its time constants ``1/(zeta omega)``."""
    return dataclasses.replace(
        solver, periodic_settle=max(SETTLE_FACTOR * solver.periodic_settle, SETTLE_MIN))


def settling_sequence(solver: SolverOptions) -> tuple[SolverOptions, ...]:
    """The options tried in turn until a tiled response is periodic within
    `solver.periodic_tolerance`: `solver`, then :func:`longer_settle`, then the whole record
    (``periodic="off"``). `simulate`, the calibration's linearisation and a fit each move to
    the next where the periodicity defect of the last one exceeds the tolerance."""
    return (solver, longer_settle(solver), dataclasses.replace(solver, periodic="off"))


def periodic_plan(twin: Twin, f_sun: float, t0: float, t_end: float, solver: SolverOptions,
                  fs_hi: float, start: str = "steady") -> tuple[float | None, str]:
    """Whether a record over ``[t0, t_end]`` (s) is integrated over one period of the gear set
    (`dtwin.simulation.periodic.mechanical_cycles`): ``(period_estimate_s, "periodic")`` or
    ``(None, reason)`` (the reason it is integrated in full). The period follows the drive's
    set point; where that is traced, `f_sun` (Hz, static) estimates it for the decision."""
    if solver.periodic == "off":
        return None, "full"
    if start != "steady":
        return None, "full (periodic: a start from rest is a run-up)"
    cycles = mechanical_cycles(twin)
    if cycles is None:
        return None, f"full (periodic: {mechanical_reason(twin)})"
    f_mesh = float(mesh_frequency(twin, float(f_sun)))
    T = cycles / f_mesh
    need = solver.periodic_settle + T + PERIODIC_PROBE / fs_hi
    if need > solver.periodic_max_fraction * (t_end - t0):
        return None, (f"full (periodic: settle {solver.periodic_settle:g} s + period "
                      f"{T:.3g} s is more than {solver.periodic_max_fraction:g} of the "
                      f"{t_end - t0:.3g} s simulated)")
    return T, "periodic"


#: Slowest decay of an output filter's start (time constants) that its prefix lets pass, and
#: the prefix (s) where a filter's time constant is traced (unknown when compiling).
FILTER_PREFIX_TAUS, FILTER_PREFIX_TRACED = 16.0, 1.0


def _filter_prefix(twin: Twin, quantity: str, fs_hi: float) -> int:
    """Samples of constant source put before the record when the output-only paths' states are
    filtered after the solve (`_filter_paths`): `FILTER_PREFIX_TAUS` of the slowest path's time
    constant, so that what the circular filter wraps from the record's end has decayed to
    ``exp(-16) = 1e-7`` when the record starts."""
    taus = [twin.parts[i].aux_decay_time() for i in _filtered_paths(twin, quantity)]
    if not taus:
        return 0
    span = max(FILTER_PREFIX_TRACED if tau is None else FILTER_PREFIX_TAUS * tau for tau in taus)
    # a power of two: twins whose filters differ a little share the compiled solve
    return 1 << int(math.ceil(math.log2(max(span * fs_hi, 1.0))))


def _filter_paths(twin: Twin, obs: dict, fs_hi: float, n_pre: int) -> dict:
    """Complete the signal of `_observe(..., split=True)` on a uniform grid of rate `fs_hi`
    (Hz): each output-only path's states are its source filtered by its frequency response
    (`AbstractTransferPath.aux_response`), started as the solve starts them — in the steady
    state of the first sample's source (`aux_from_state`) — by `n_pre` samples of that source
    before the grid; the filter is applied by FFT (exact for a source band-limited to
    `fs_hi` / 2)."""
    obs = dict(obs)
    sig = obs["signal"]
    for key in [k for k in obs if k.startswith("source_")]:
        i = int(key.split("_")[1])
        src, gain = obs.pop(key), obs.pop(f"gain_{i}")
        n = src.shape[0]
        x = jnp.concatenate([jnp.full((n_pre,), src[0]), src])
        import scipy.fft  # deferred: a heavy import that `import dtwin` does not need

        m = int(scipy.fft.next_fast_len(x.shape[0], real=True))
        X = jnp.fft.rfft(x, m)
        R = twin.parts[i].aux_response(2.0 * jnp.pi * jnp.fft.rfftfreq(m, 1.0 / fs_hi))
        states = jnp.fft.irfft(X[:, None] * R, m, axis=0)[n_pre : n_pre + n]
        sig = sig + jnp.sum(gain * states, axis=1)
    obs["signal"] = sig
    return obs


def _aux_advance(twin: Twin) -> np.ndarray:
    """How much each of the parts' states advances under the rigid rotation per radian the sun
    turns: an ideal speed source's rotor angle by 1, every other state by 0."""
    out = []
    for p in twin.parts:
        adv = np.zeros(p.aux_size)
        if isinstance(p, DrivePart) and isinstance(p.drive, IdealSpeedSource):
            adv[:] = 1.0
        out.append(adv)
    return np.concatenate(out) if out else np.zeros(0)


@eqx.filter_jit
def _solve_tiled(twin: Twin, y0, t0, t_ref, ts, fs_hi: float, cycles, n_pre: int,
                 quantity: str, rtol, atol, dtmax, max_steps: int,
                 adjoint: str, progress: bool, pcoeff, icoeff, unrolled: bool,
                 rate_scale_hz: float):
    """`_solve` over ``[t0, t_ref]`` (settling) and one period of the gear set (`cycles` mesh
    cycles, `dtwin.simulation.periodic.mechanical_cycles`; a value, so that twins of other periods share
    the compilation) only, the observables on the whole grid `ts` (s, uniform at `fs_hi` Hz):
    a sample at ``t >= t_ref + T`` takes the state at ``t_ref + (t - t_ref) mod T``
    (`dtwin.simulation.periodic.fold_times`) advanced by the rigid rotation
    over the periods removed (`dtwin.simulation.periodic.rigid_advance`), and is observed at its own time
    `t`; the output-only transfer paths' states are filtered from their sources over the
    whole grid afterwards (`_filter_paths`, `n_pre` samples of prefix), since a sensor on the
    housing sees the planets pass with the carrier's period, not the gear set's.
    Differentiable (the period follows the drive's set point, traced or not). **Returns**
    ``(observables, result, steps, defect)`` with `defect` the rms difference, over a window of
    `PERIODIC_PROBE` samples one period after `t_ref`, between the signal as integrated there
    and as the tiling makes it (the window at `t_ref` advanced by one period), both without the
    output-only paths' filtered states, over the rms of the record's signal: what a start-up
    transient that outlasted the settling time would leave in the tiled record."""
    ops = twin.operators()
    drive = next(p.drive for p in twin.parts if isinstance(p, DrivePart))
    period = cycles / mesh_frequency(twin, drive.speed.final / (2.0 * jnp.pi))
    n_probe = PERIODIC_PROBE
    save, back, turns, t1 = _tiled_grid(ts, t_ref, period, fs_hi)
    (z, zd, aux), result, nsteps = _integrate(twin, ops, y0, t0, t1, save, rtol, atol, dtmax,
                                              max_steps, adjoint, progress, pcoeff, icoeff,
                                              unrolled, rate_scale_hz)
    z, zd, aux = z[back], zd[back], aux[back]
    n = ts.shape[0]
    # the cycles a value: twins of other periods share the compilation
    sun, car = rigid_advance(twin, cycles)
    ic, aux_adv = twin._index("theta_c"), jnp.asarray(_aux_advance(twin))
    z_rec = z[:n].at[:, ic].add(turns * car)
    aux_rec = aux[:n] + (turns * sun)[:, None] * aux_adv[None, :]
    obs = jax.vmap(lambda t, y: _observe(twin, ops, quantity, t, y, split=True))(
        ts, (z_rec, zd[:n], aux_rec))
    obs = _filter_paths(twin, obs, fs_hi, n_pre)

    # the periodicity check: the probe window one period after `t_ref` as integrated, and as
    # the tiling makes it (the window at `t_ref` advanced by one period), observed alike
    tp = save[back][n + n_probe :]
    head = (z[n : n + n_probe].at[:, ic].add(car), zd[n : n + n_probe],
            aux[n : n + n_probe] + sun * aux_adv[None, :])
    tail = (z[n + n_probe :], zd[n + n_probe :], aux[n + n_probe :])

    def sensor(t, y):
        return _observe(twin, ops, quantity, t, y, split=True)["signal"]

    change = jax.vmap(sensor)(tp, tail) - jax.vmap(sensor)(tp, head)
    sig = obs["signal"]
    defect = jnp.sqrt(jnp.mean(change**2) / jnp.mean((sig - jnp.mean(sig)) ** 2))
    return obs, result, nsteps, defect


@jax.jit
def _tiled_grid(ts, t_ref, period, fs_hi):
    """The save times of `_solve_tiled`, sorted: the record's times mapped onto one period,
    then two probe windows of `PERIODIC_PROBE` samples at ``t_ref`` and ``t_ref + period``.
    **Returns** ``(save, back, turns, t1)``: ``save[back]`` restores that order, `turns` the
    whole periods removed from each time, `t1` (s) the last save time."""
    mapped, turns = fold_times(ts, t_ref, period)
    probe = jnp.arange(PERIODIC_PROBE, dtype=jnp.float64) / fs_hi
    every = jnp.concatenate([mapped, t_ref + probe, t_ref + period + probe])
    order = jnp.argsort(every)
    save = every[order]
    # the last save time itself, not the sum again: fused differently, it can round below it
    return save, jnp.argsort(order), turns, save[-1]


def integrate_observables(twin: Twin, y0, t0: float, ts_np: np.ndarray, fs_hi: float,
                          f_sun: float, quantity: str, solver: SolverOptions, dtmax,
                          progress: bool = False, start: str = "steady"):
    """The observables on the high-rate grid `ts_np` (s) from `t0` (s), integrated in full or
    over one period of the gear set (`periodic_plan`). **Returns** ``(observables, result,
    steps, method, defect)``; `defect` None when integrated in full."""
    t1 = float(ts_np[-1])
    T, method = periodic_plan(twin, f_sun, t0, t1, solver, fs_hi, start)
    # times, tolerances and the step limit enter the compiled solve as values, not as constants
    # of its program: another speed, start time or tolerance reuses the compilation
    f64 = functools.partial(jnp.asarray, dtype=jnp.float64)
    common = (quantity, f64(solver.rtol), f64(solver.atol), f64(dtmax))
    rest = (solver.adjoint, progress, solver.pcoeff, solver.icoeff, solver.unrolled,
            solver.rate_scale_hz)
    if T is None:
        max_steps = solver.max_steps or _step_budget(t1 - t0)
        ys, result, nsteps = _solve(twin, y0, f64(t0), f64(t1), jnp.asarray(ts_np), *common,
                                    max_steps, *rest)
        return ys, result, nsteps, method, None
    # the period follows the drive's set point, traced in a fit: its estimate `T` (from the
    # static `f_sun`) decides, the step budget covers the whole record as well
    cycles = mechanical_cycles(twin)
    span = max(solver.periodic_settle + 1.01 * T + PERIODIC_PROBE / fs_hi, t1 - t0)
    max_steps = solver.max_steps or _step_budget(span)
    ys, result, nsteps, defect = _solve_tiled(
        twin, y0, f64(t0), f64(t0 + solver.periodic_settle), jnp.asarray(ts_np), float(fs_hi),
        f64(cycles), _filter_prefix(twin, quantity, fs_hi), *common, max_steps, *rest)
    return ys, result, nsteps, method, defect


def _step_budget(span: float) -> int:
    """The default step limit of a solve over `span` s: 400 000 steps per simulated second
    plus 10 000, rounded up to a multiple of 100 000 so that spans a little apart (another
    speed's period) share one compiled solve (the limit is static in it)."""
    need = 400_000 * span + 10_000
    return int(math.ceil(need / 100_000) * 100_000)


def _check_finite(twin: Twin) -> None:
    """Refuse NaN/inf parameters before solving, naming the field."""
    leaves, _ = jax.tree_util.tree_flatten_with_path(eqx.filter(twin, eqx.is_array))
    for path, leaf in leaves:
        if isinstance(leaf, jax.core.Tracer):
            continue
        if not bool(jnp.all(jnp.isfinite(leaf))):
            name = jax.tree_util.keystr(path)
            raise SolverError(
                f"parameter twin{name} is NaN or inf: the ODE cannot be solved; give it a finite "
                "value"
            )


def _raise_for(result, t1) -> None:
    if result == diffrax.RESULTS.successful:
        return
    if result == diffrax.RESULTS.max_steps_reached:
        raise SolverError(
            "the ODE solver reached max_steps before the end of the record: pass a larger "
            "SolverOptions(max_steps=...), a shorter duration, or check for a stiffness "
            "that makes the model stiff (e.g. a huge support stiffness)"
        )
    raise SolverError(
        f"the ODE solver failed ({result}): the state became NaN/inf or the step size "
        "collapsed; check the parameters (negative or zero stiffness or mass, severity "
        "outside [0, 1], absurd load torque)"
    )


def daq_grid(duration: float, discard: float, daq: DAQ) -> tuple[float, np.ndarray, np.ndarray]:
    """The time grid a record of `duration` (s) after `discard` (s) is simulated on by `daq`:
    ``(fs_hi, taps, ts)``, the oversampled rate (Hz), the anti-alias filter's taps and the
    times (s, numpy): the output samples at ``fs_hi`` plus the filter's half-length on each
    side. Built in numpy, so it serves inside `jit`/`vmap` too."""
    fs_hi = float(daq.sample_rate) * daq.oversample
    taps = daq_filter(daq.oversample, daq.passband)
    half = (len(taps) - 1) // 2
    n_hi = int(round(duration * float(daq.sample_rate))) * daq.oversample
    return fs_hi, taps, float(discard) + np.arange(-half, n_hi + half, dtype=np.float64) / fs_hi


def step_limit(twin: Twin, f_sun: float, solver: SolverOptions) -> float:
    """The solver's largest step (s): ``solver.dtmax``, else a tenth of the mesh period at the
    input speed `f_sun` (Hz), ``f_mesh = f_sun z_ring / r_s`` with ``r_s`` the sun's kinematic
    ratio (:attr:`dtwin.model.twin.Twin.kinematic_ratios`)."""
    if solver.dtmax is not None:
        return solver.dtmax
    rs, _ = twin.kinematic_ratios
    return 0.1 / max(float(f_sun) / rs * twin.lp.z_ring, 1.0)


def drive_speed(twin: Twin, t: float | None = None) -> float:
    """The input (sun) speed (Hz) the twin's drive is set to: its speed set point at time `t`
    (s), or where the set point ends (a step's or ramp's final speed) when `t` is None or the
    set point is not yet positive at `t`. The drive and the sun turn together (the shaft's
    twist is small), so this is the sun's speed. Raises `SolverError` for a twin without a
    drive part (pass `f_sun` to :func:`simulate` then)."""
    drives = twin.find(DrivePart)
    speed = getattr(drives[0].drive, "speed", None) if drives else None
    if speed is None:
        raise SolverError("the twin has no drive with a speed set point to read its input "
                          "speed from: pass simulate(..., f_sun=HZ), or build the twin from a "
                          "spec (dtwin.build_twin), which adds its drive")
    omega = float(speed(jnp.asarray(t))) if t is not None else 0.0
    if not omega > 0.0:
        omega = float(speed.final)
    if not (math.isfinite(omega) and omega > 0.0):
        raise SolverError(f"the twin's drive is set to {omega / (2 * math.pi):g} Hz: pass "
                          "simulate(..., f_sun=HZ) with the input speed")
    # to 12 significant digits: undoes the last-bit rounding of the Hz -> rad/s conversion, so a
    # twin built at 30 Hz reads 30 Hz (not 29.999999999999996) and runs as when told 30 Hz
    return float(f"{omega / (2.0 * math.pi):.12g}")


def simulate(
    twin: Twin,
    *,
    duration: float,
    f_sun: float | None = None,
    daq: DAQ | None = None,
    start: str = "steady",
    discard: float = 0.0,
    solver: SolverOptions | None = None,
    seed: int = 0,
    progress: bool = False,
    check: bool = True,
) -> SimResult:
    """Simulate `twin` and record its sensor like a DAQ.

    **Arguments:**

    - `twin`: the `Twin` (with a drive part to turn it, a load and a transfer path).
    - `duration`: length of the returned record (s), after `discard`.
    - `f_sun`: nominal input speed (Hz), used for the steady initial state and the step limit.
      Default: the twin's drive (:func:`drive_speed`), so a twin built from a spec needs none.
    - `daq`: `DAQ` settings (default 5 kHz acceleration, no noise).
    - `start`: ``"steady"`` or ``"rest"`` (see `initial_state`).
    - `discard`: initial transient simulated but not returned (s).
    - `solver`: `SolverOptions`.
    - `seed`: seed of the measurement noise.
    - `progress`: print solver progress.
    - `check`: raise `SolverError` when the solver fails (needs concrete values: pass False
      inside `jax.jit`/`grad`, where failure shows as NaN instead).

    **Returns:** `SimResult`.

    The solve is compiled once per twin structure, record length and rate, quantity and
    solver settings other than the tolerances: another speed, start time, tolerance or
    parameter value reuses the compiled program.
    """
    _maps.relieve()  # a safe point: drop JAX's caches near the mapping limit (dtwin._maps)
    daq = daq or DAQ()
    solver = solver or SolverOptions()
    if check:
        _check_finite(twin)
    if duration <= 0 or not math.isfinite(duration):
        raise ValueError(f"duration must be a positive number of seconds, got {duration}")
    if discard < 0:
        raise ValueError(f"discard must be >= 0 s, got {discard}")
    fs_out = float(daq.sample_rate)
    n_out = int(round(duration * fs_out))
    if n_out < 8:
        raise ValueError(f"duration {duration} s gives only {n_out} samples at {fs_out} Hz")
    fs_hi, taps, ts_np = daq_grid(duration, discard, daq)
    half = (len(taps) - 1) // 2
    if start == "rest" and discard * fs_hi < half:
        # the filter needs samples before the first output sample; a run from rest starts at 0
        discard = half / fs_hi
        _, _, ts_np = daq_grid(duration, discard, daq)
    t_start = float(discard)
    t0 = float(ts_np[0]) if start == "steady" else min(0.0, float(ts_np[0]))
    t1 = float(ts_np[-1])
    if f_sun is None:
        f_sun = drive_speed(twin, t0 if start == "steady" else None)
    y0 = _initial_state_compiled(twin, f_sun, start)
    dtmax = step_limit(twin, f_sun, solver)
    # where the start-up transient has not decayed within the settling time: settle longer,
    # and where that fails too (or the response is not periodic) integrate in full
    tried = []
    for option in settling_sequence(solver):
        ys, result, nsteps, method, defect = integrate_observables(
            twin, y0, t0, ts_np, fs_hi, f_sun, daq.quantity, option, dtmax, progress, start)
        if not check or defect is None or float(defect) <= solver.periodic_tolerance:
            break
        tried.append(f"{float(defect):.2g} after {option.periodic_settle:g} s")
    if tried and defect is None:
        method = (f"full (periodic: the signal's rms change over one period was "
                  f"{', '.join(tried)}, above periodic_tol = {solver.periodic_tolerance:g})")
    if check:
        _raise_for(result, t1)
    # compiled as one program (op by op, its first call compiles each operation separately)
    res = _acquire_jit(ys, taps, daq, fs_out, nsteps, jnp.asarray(seed), jnp.asarray(t_start))
    return dataclasses.replace(res, method=method, periodic_defect=defect)


def acquire(ys, taps, daq: DAQ, fs_out, nsteps, seed, t_start) -> SimResult:
    """The record the DAQ `daq` makes of the observables `ys` (:func:`integrate_observables`,
    sampled at `daq.oversample` × `fs_out`): the anti-alias filter `taps` and decimation to
    `fs_out` (Hz), the sensor response and gain, integration to velocity or displacement, noise
    at the DAQ's SNR (seeded by `seed`), the tachometer; times from `t_start` (s)."""
    taps = jnp.asarray(taps)
    step = daq.oversample

    def decimate(x):
        return jnp.convolve(x, taps, mode="valid")[::step]

    sig = decimate(ys["signal"]) * daq.gain
    n = sig.shape[0]
    if daq.frf_hz is not None:
        sig = apply_frf(sig, fs_out, daq.frf_hz, daq.frf_db)
    if daq.quantity in ("velocity", "displacement"):
        sig = integrate_spectral(sig, fs_out, 1 if daq.quantity == "velocity" else 2, daq.f_highpass)
    half = (len(taps) - 1) // 2
    outputs = {}
    for k, v in ys.items():
        if k == "signal":
            continue
        outputs[k] = v[half : half + n * step : step]
    if daq.snr_db is not None:
        p_sig = jnp.mean((sig - jnp.mean(sig)) ** 2)
        sigma = jnp.sqrt(p_sig / 10.0 ** (daq.snr_db / 10.0))
        sig = sig + sigma * jax.random.normal(jax.random.PRNGKey(seed), sig.shape)
    tacho = None
    if daq.tacho_ppr is not None:
        ang = outputs["theta_sun" if daq.tacho_shaft == "sun" else "theta_carrier"]
        frac = jnp.mod(daq.tacho_ppr * ang / (2.0 * jnp.pi), 1.0)
        tacho = jnp.where(frac < 0.5, 5.0, 0.0)
    time = t_start + jnp.arange(n, dtype=jnp.float64) / fs_out
    return SimResult(time, sig, tacho, outputs, nsteps, fs_out, daq.quantity)


_acquire_jit = eqx.filter_jit(acquire)


def integrate_spectral(x: Float[Array, " n"], fs: float, order: int, f_highpass: float) -> Array:
    """Integrate a signal `order` times in the frequency domain (divide by (j 2 pi f)^order),
    with a smooth high-pass below `f_highpass` (Hz) to remove drift."""
    n = x.shape[0]
    X = jnp.fft.rfft(x - jnp.mean(x))
    f = jnp.fft.rfftfreq(n, 1.0 / fs)
    w = 2.0 * jnp.pi * f
    hp = (f / f_highpass) ** 4 / (1.0 + (f / f_highpass) ** 4)
    safe = jnp.where(f > 0, w, 1.0)
    # 1 / (j ω)^order = (-j)^order / ω^order, built from real parts (strict dtype promotion)
    c = (-1j) ** order
    g = jnp.where(f > 0, hp / safe**order, 0.0)
    H = jax.lax.complex(g * c.real, g * c.imag)
    return jnp.fft.irfft(X * H, n)
