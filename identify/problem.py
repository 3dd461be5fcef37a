"""What is fitted: a :class:`Problem` (the prepared twin, the parameter set, the observations)
made from records, a spec or twin and the free parameters (:func:`make_problem`).

"Spec or twin" is resolved here, once: :func:`spec_of` gives the spec (None for a twin), and
:func:`as_twin`, :func:`calibrated_spec` and :func:`sensor_response` read it.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from dtwin.errors import FitError, ParameterError, RecordError, SettingsError
from dtwin.model.registry import lookup
from dtwin.model.twin import Twin
from dtwin.simulation.simulate import SolverOptions
from dtwin.spec import Spec, load_spec
from dtwin.spec.build import build_twin, is_calibrated, twin_kind

from .operating_point import estimate_speed_profile, nominal_speed, resolve_speed
from .params import ParameterSet
from .residuals import (
    FAILED_RESIDUAL,
    Features,
    Observation,
    _check,
    model_signal_and_defect,
    observation_residuals,
    observe,
)

__all__ = ["PROBLEM_KEYS", "Problem", "as_twin", "calibrated_spec", "check_free", "make_problem",
           "sensor_response", "spec_of"]


# ------------------------------------------------------------------------------ spec or twin
def spec_of(spec_or_twin) -> Spec | None:
    """The spec of `spec_or_twin` (a path, mapping or `Spec`), loaded; None for a `Twin`, which
    carries no spec (no geometry, calibration or sensor response to read)."""
    if isinstance(spec_or_twin, Twin):
        return None
    return spec_or_twin if isinstance(spec_or_twin, Spec) else load_spec(spec_or_twin)


def as_twin(spec_or_twin, kind: str | None = None) -> Twin:
    """The twin: `spec_or_twin` itself, or built from its spec with `kind`
    (:func:`dtwin.spec.build.twin_kind`)."""
    spec = spec_of(spec_or_twin)
    return spec_or_twin if spec is None else build_twin(spec, kind=twin_kind(spec, kind))


def calibrated_spec(spec_or_twin) -> Spec | None:
    """The spec when it was written by ``dtwin calibrate`` (None: a twin or an uncalibrated
    spec)."""
    spec = spec_of(spec_or_twin)
    return spec if spec is not None and is_calibrated(spec) else None


def sensor_response(spec_or_twin) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
    """The calibrated sensor response ``(frf_hz, frf_db)`` of a spec (None: flat, or a twin)."""
    spec = spec_of(spec_or_twin)
    if spec is None:
        return None
    s = spec["sensor"]
    return None if s["frf_hz"] is None else (tuple(s["frf_hz"]), tuple(s["frf_db"]))


def check_free(free: Sequence[str] | str) -> list[str]:
    """Registry names of a `--free` list, checked (unknown → `ParameterError`)."""
    names = [s.strip() for s in free.split(",") if s.strip()] if isinstance(free, str) else list(free)
    if not names:
        raise ParameterError("no free parameter given")
    for n in names:
        lookup(n)
    return names


# ------------------------------------------------------------------------------ the problem
class Problem(eqx.Module):
    """A fitting problem: the prepared twin, the parameter set and the observations.

    A pytree: arrays (twin parameters, measured levels) are leaves, shapes and settings are
    static, so one compiled residual serves every problem of the same structure (other records
    of the same length, other noise, other starting values).
    """

    twin: Any
    pset: ParameterSet
    observations: tuple[Observation, ...]
    rtol: float = eqx.field(static=True, default=1e-5)
    atol: float = eqx.field(static=True, default=1e-5)
    adjoint: str = eqx.field(static=True, default="forward")
    periodic: str = eqx.field(static=True, default="off")
    periodic_settle: float = eqx.field(static=True, default=0.1)

    def solver_options(self):
        return SolverOptions(rtol=self.rtol, atol=self.atol, adjoint=self.adjoint,
                             periodic=self.periodic, periodic_settle=self.periodic_settle)

    def signals(self, theta):
        """``(signals, values)``: the twin's signal per record and the parameter values (SI)
        at the unconstrained `theta`."""
        sigs, values, _ = self.simulated(theta)
        return sigs, values

    def simulated(self, theta):
        """``(signals, values, defect)``: :meth:`signals` and the largest periodicity defect
        of the records simulated over one period of the gear set and tiled (relative rms
        difference of a signal as integrated and as tiled over a probe window,
        `dtwin.simulation.simulate.SimResult.periodic_defect`; 0 where no record is tiled). A defect above `SolverOptions.periodic_tolerance` means the start-up
        transient had not died out within the settling time (:func:`dtwin.identify.fit.fit` then fits again)."""
        values = self.pset.values(theta)
        tw = self.pset.apply(self.twin, values)
        out = [model_signal_and_defect(tw, o, self.solver_options()) for o in self.observations]
        defects = [d for _, d in out if d is not None]
        worst = jnp.max(jnp.stack(defects)) if defects else jnp.zeros(())
        return [sig for sig, _ in out], values, worst

    def residuals(self, theta):
        """The residual vector (all records, then priors) at the unconstrained `theta`."""
        return self.residuals_from(self.signals(theta)[0], theta)

    def residuals_and_defect(self, theta):
        """``(residuals, defect)`` at `theta`: :meth:`residuals` and the periodicity defect of
        :meth:`simulated`, from one simulation."""
        sigs, _, defect = self.simulated(theta)
        return self.residuals_from(sigs, theta), defect

    def residuals_from(self, sigs, theta):
        """The residual vector from simulated signals `sigs` (one per record) at `theta`:
        everything after the ODE solve (sensor gain, spectra, priors)."""
        values = self.pset.values(theta)
        gain = self.pset.gain(values)
        rs = [observation_residuals(s, o, gain) for s, o in zip(sigs, self.observations, strict=True)]
        rs.append(self.pset.prior_residuals(values))
        r = jnp.concatenate(rs)
        return jnp.where(jnp.isfinite(r), r, FAILED_RESIDUAL)

    @property
    def n_profiled_gains(self) -> int:
        """Nuisance values profiled out per evaluation (degrees of freedom lost): one gain per
        record with ``gain="profile"``, one white-noise level per spectrogram record."""
        noise = sum(1 for o in self.observations if o.noise is not None)
        if "sensor_gain" in self.pset.free:
            return noise
        return noise + sum(1 for o in self.observations if o.gain_mode == "profile")




def make_problem(
    records,
    spec_or_twin,
    free: Sequence[str] | str | ParameterSet,
    *,
    kind: str | None = None,
    f_sun: float | Sequence[float | None] | None = None,
    runup: tuple[float, float] | Sequence[tuple[float, float] | None] | None = None,
    features: Features | Sequence[Features] | None = None,
    weights: Sequence[float] | None = None,
    initial: Mapping[str, float] | None = None,
    fixed: Mapping[str, float] | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    priors: Mapping[str, tuple[float, float]] | None = None,
    channel: int | str = 0,
    discard: float = 0.05,
    oversample: int = 4,
    rtol: float = 1e-5,
    atol: float = 1e-5,
    jac: str = "fwd",
    periodic: str = "auto",
) -> tuple[Problem, list[dict[str, float]]]:
    """Checks, operating points and observations → a :class:`Problem` (no simulation yet).

    Arguments as :func:`fit`; `periodic`: ``"auto"`` (default: a constant-speed record whose
    settling time (0.1 s) and the gear set's period fit in 3/4 of it is simulated over those
    only and tiled, ``dtwin.simulation.simulate.SolverOptions.periodic``; run-ups and twins whose response is not
    periodic are simulated in full; :func:`fit` settles longer where the tiled response at its
    optimum was not periodic) or ``"off"`` (always in full).
    **Returns:** ``(problem, operating_points)``.
    """
    pset = free if isinstance(free, ParameterSet) else None
    if pset is None:
        # names first: an unknown name fails before the twin is even built
        names = [s.strip() for s in free.split(",")] if isinstance(free, str) else list(free)
        for n in names + list(fixed or {}) + list(initial or {}):
            lookup(n)
    if jac not in ("fwd", "rev"):
        raise SettingsError(f"jac must be 'fwd' or 'rev', got {jac!r}")
    if not isinstance(records, (list, tuple)):
        records = [records]
    if not records:
        raise FitError("no record to fit")
    spec = spec_of(spec_or_twin)
    source = spec_or_twin if spec is None else spec  # the spec read once
    twin = as_twin(source, kind)
    if pset is None:
        pset = ParameterSet.build(names, twin, initial=initial, fixed=fixed, bounds=bounds,
                                  priors=priors)
    twin = pset.prepare(twin)
    per_record = _per_record(len(records), f_sun, runup, features, weights)
    nominal = nominal_speed(source)
    frf = sensor_response(source)
    obs, ops = [], []
    for i, (rec, (f, ru, feat, w)) in enumerate(zip(records, per_record, strict=True)):
        f0, f1, op = _operating_point(i, rec, twin, source, nominal, f, ru, channel)
        ops.append(op)
        ob = observe(rec, twin, f_sun=f0, f_end=f1, features=feat, channel=channel,
                     weight=w, discard=discard, oversample=oversample)
        obs.append(dataclasses.replace(ob, frf_hz=frf[0], frf_db=frf[1]) if frf else ob)
    if periodic not in ("off", "auto"):
        raise SettingsError(f"periodic must be 'off' or 'auto', got {periodic!r}")
    problem = Problem(twin, pset, tuple(obs), rtol=rtol, atol=atol,
                      adjoint="forward" if jac == "fwd" else "reverse", periodic=periodic)
    return problem, ops


#: The keyword arguments of :func:`make_problem` that a fit passes on (`jac` is a fit setting).
PROBLEM_KEYS = tuple(k for k in inspect.signature(make_problem).parameters
                     if k not in ("records", "spec_or_twin", "free", "jac"))


def _per_record(n: int, f_sun, runup, features, weights) -> list[tuple[Any, Any, Any, float]]:
    """``(f_sun, runup, features, weight)`` of each of `n` records: a list gives one entry per
    record, anything else is every record's."""
    f_list = list(f_sun) if isinstance(f_sun, (list, tuple)) else [f_sun] * n
    r_list = list(runup) if isinstance(runup, list) else [runup] * n
    feat_list = list(features) if isinstance(features, (list, tuple)) else [features] * n
    w_list = list(weights) if weights is not None else [1.0] * n
    if not (len(f_list) == len(r_list) == len(feat_list) == len(w_list) == n):
        raise FitError("f_sun, runup, features and weights need one entry per record")
    return list(zip(f_list, r_list, feat_list, w_list, strict=True))


def _operating_point(i: int, rec, twin, source, nominal, f_sun, runup, channel
                     ) -> tuple[float, float | None, dict[str, Any]]:
    """``(f_start, f_end, operating point)`` of record `i` (``f_end`` None: steady): its
    samples checked finite, then the speed profile of a run-up or the speed of a steady
    record (given, from a tachometer or estimated)."""
    # cheap input checks before the speed estimate
    x = np.asarray(rec.channel(channel))
    if not np.all(np.isfinite(x)):
        bad = np.flatnonzero(~np.isfinite(x))
        raise RecordError(f"record {i} holds {bad.size} NaN/inf samples (first at sample "
                          f"{bad[0]}); clean or cut it before identification")
    if runup is not None:
        prof = estimate_speed_profile(rec, twin, runup, channel=channel)
        return prof.f_start, prof.f_end, {"f_sun_start": prof.f_start,
                                          "f_sun_end": prof.f_end, "method": prof.method}
    if f_sun is None and nominal is not None:
        _check(rec, twin, nominal, channel)  # rate and length, before the estimate
    op = resolve_speed(rec, source, f_sun, channel=channel, check=False,
                       fallback=False, required=False)
    if op is None:
        raise FitError("no input speed: pass f_sun, a record with a tachometer, or a "
                       "spec with operating.f_sun")
    f0 = op.f_sun
    return f0, None, ({"f_sun": f0, "method": "given"} if op.method == "given" else
                      {"f_sun": f0, "std_f_sun": op.std_f_sun, "method": op.method})
