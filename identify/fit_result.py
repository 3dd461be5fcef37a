"""The outcome of a fit (:class:`FitResult`) and its reporting: the table, the intervals and
status of each parameter, a JSON-ready dict, the measured and fitted spectra."""

from __future__ import annotations

import dataclasses
from typing import Any

import jax.numpy as jnp
import numpy as np

from .problem import Problem
from .residuals import fitted_levels, levels_from_residuals, residual_count
from .uncertainty import MODEL_FORM_REASON, Uncertainty

__all__ = ["FitResult"]


@dataclasses.dataclass
class FitResult:
    """Outcome of :func:`dtwin.identify.fit.fit` (and of each record of
    :func:`~dtwin.identify.fit_batch.fit_batch`).

    - `names`, `values` (SI, dict), `theta` (unconstrained optimum), `initial` (SI, dict);
    - `uncertainty` (:class:`dtwin.identify.uncertainty.Uncertainty`, or None);
    - `loss` (½‖r‖² at the optimum), `loss_history` (½‖r‖² at every residual evaluation of the
      solver from the chosen start: the loss over iterations, rejected trial steps included), `start_losses` (the batched multi-start evaluation), `starts` (θ),
      `refined` (per refined start: θ, converged, steps, loss);
    - `converged`, `at_bound` (names), `message`, `iterations` (solver steps), `wall_time` (s),
      `operating_points` (Hz per record), `problem` (for figures and re-evaluation),
      `residuals` and `jacobian` (the residual vector and its Jacobian in θ at the optimum,
      from the solver's last accepted step);
    - `relocations`: each time the fit went on from a point of lower loss that a severity's
      profile or a stiffness's scan passed (the first optimum was a local one): the
      parameter's name (``profile_of``), ``by`` (``"profile"`` or ``"scan"``) and the loss
      before and after;
    - `excitation`: for a fault severity fitted with both ends of a calibrated spec's
      excitation/response split (:mod:`dtwin.identify.excitation_response`), the one reported
      (:data:`~dtwin.identify.excitation_response.SPLIT_CALIBRATED` or
      :data:`~dtwin.identify.excitation_response.SPLIT_STIFFNESS`), and `splits`: a row per split (loss,
      values, intervals, accepted); empty otherwise;
    - `read_intervals`, `read_reasons`: for a value read without a covariance (a fault's depth
      from the sideband ratio, :mod:`dtwin.identify.line_ratio`; `uncertainty` is None), its 95 %
      interval (name → (low, high)) and, where it is not determined, why (name → reason).
    """

    names: tuple[str, ...]
    values: dict[str, float]
    theta: np.ndarray
    initial: dict[str, float]
    uncertainty: Uncertainty | None
    loss: float
    loss_history: list[float]
    start_losses: np.ndarray
    starts: np.ndarray
    refined: list[dict[str, Any]]
    converged: bool
    at_bound: list[str]
    message: str
    iterations: int
    wall_time: float
    operating_points: list[dict[str, float]]
    problem: Problem | None = dataclasses.field(default=None, repr=False)
    residuals: np.ndarray | None = dataclasses.field(default=None, repr=False)
    jacobian: np.ndarray | None = dataclasses.field(default=None, repr=False)
    relocations: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    excitation: str = ""
    splits: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    read_intervals: dict[str, tuple[float, float]] = dataclasses.field(default_factory=dict)
    read_reasons: dict[str, str] = dataclasses.field(default_factory=dict)

    @property
    def not_determined(self) -> dict[str, str]:
        return dict(self.read_reasons) if self.uncertainty is None else \
            dict(self.uncertainty.not_determined)

    def has_interval(self, name: str) -> bool:
        """Whether `name` has a 95 % interval (from the covariance or as read)."""
        return self.uncertainty is not None or name in self.read_intervals

    def interval(self, name: str) -> tuple[float, float]:
        """The 95 % interval of `name` (SI); KeyError when it has none
        (:meth:`has_interval`)."""
        if self.uncertainty is None:
            lo, hi = self.read_intervals[name]
            return float(lo), float(hi)
        i = self.names.index(name)
        lo, hi = self.uncertainty.interval[i]
        return float(lo), float(hi)

    @property
    def widened(self) -> float:
        """Factor the intervals were widened by for lack of fit (1: none;
        :mod:`dtwin.identify.uncertainty`, "Lack of fit")."""
        return 1.0 if self.uncertainty is None else float(self.uncertainty.widened)

    def status(self, name: str) -> str:
        """``NOT DETERMINED`` (``NOT DETERMINED: the model does not fit this record (loss N× the
        noise)`` above :data:`~dtwin.identify.uncertainty.MODEL_FORM_LIMIT`), ``unconverged``,
        ``widened ×k for lack of fit`` (the loss stands
        well above the noise: a model-form error of that size could move the value, so it is
        never called ok) or ``ok``; for a value read without a covariance, ``NOT DETERMINED:
        reason`` or ``ok``; empty for a value with no interval."""
        if self.uncertainty is None:
            if name in self.read_reasons:
                return f"NOT DETERMINED: {self.read_reasons[name]}"
            if name not in self.read_intervals:
                return ""
            return "ok" if self.converged else "unconverged"
        if name in self.uncertainty.not_determined:
            why = self.uncertainty.not_determined[name]
            return f"NOT DETERMINED: {why}" if why.startswith(MODEL_FORM_REASON) else \
                "NOT DETERMINED"
        if not self.converged:
            return "unconverged"
        if self.widened > 1.0:
            return f"widened ×{self.widened:.2g} for lack of fit"
        if not self.uncertainty.white:
            return f"residuals not white (p = {self.uncertainty.whiteness_p:.1g})"
        return "ok"

    def table(self) -> str:
        """A readable table: value, 95 % interval, determined or not."""
        rows = [f"{'parameter':<18} {'initial':>12} {'fitted':>12} {'95 % interval':>28}  status"]
        for n in self.names:
            if self.has_interval(n):
                lo, hi = self.interval(n)
                iv = f"[{lo:.5g}, {hi:.5g}]"
                st = self.status(n)
            else:
                iv, st = "", ""
            rows.append(f"{n:<18} {self.initial[n]:>12.5g} {self.values[n]:>12.5g} {iv:>28}  {st}")
        rows.append(f"loss {self.loss:.5g}, {self.iterations} iterations, "
                    f"{self.wall_time:.1f} s, "
                    + ("converged" if self.converged else f"NOT converged ({self.message})")
                    + (f"; at bound: {', '.join(self.at_bound)}" if self.at_bound else ""))
        if self.converged and self.message != "converged":
            rows.append(self.message.removeprefix("converged; "))
        for m in self.relocations:
            rows.append(f"local optimum left: the {m['by']} of {m['profile_of']} passed a point "
                        f"of lower loss; refined from it, loss {m['loss_before']:.5g} → "
                        f"{m['loss_after']:.5g}")
        for row in self.splits:
            mark = "reported" if row["excitation"] == self.excitation else \
                "not rejected: intervals over both" if row["accepted"] else "rejected"
            vals = ", ".join(f"{n} {row['values'][n]:.5g}" for n in self.names)
            low = (f" (with the low band, not fitted: {row['low_band_loss']:.5g})"
                   if "low_band_loss" in row else "")
            rows.append(f"excitation/response split {row['excitation']!r}: loss "
                        f"{row['loss']:.5g}{low}, {vals} ({mark})")
        u = self.uncertainty
        if u is not None and np.isfinite(u.lack_of_fit):
            rows.append(f"lack of fit: loss {u.lack_of_fit:.3g}× what the noise alone leaves"
                        + (f"; every interval widened ×{u.widened:.3g} (covariance × the ratio: "
                           "a model-form error of this size moves the estimates)"
                           if u.widened > 1.0 else ""))
        for n, why in self.not_determined.items():
            rows.append(f"  {n}: not determined by these data ({why})")
        return "\n".join(rows)

    def to_dict(self) -> dict[str, Any]:
        out = {
            "names": list(self.names), "values": self.values, "initial": self.initial,
            "theta": self.theta.tolist(), "loss": self.loss, "loss_history": self.loss_history,
            "start_losses": self.start_losses.tolist(), "refined": self.refined,
            "converged": self.converged, "at_bound": self.at_bound, "message": self.message,
            "iterations": self.iterations, "wall_time_s": self.wall_time,
            "operating_points": self.operating_points, "relocations": self.relocations,
            "excitation": self.excitation, "splits": self.splits,
        }
        if self.uncertainty is not None:
            out["uncertainty"] = self.uncertainty.to_dict()
            out["intervals_95"] = {n: list(map(float, self.uncertainty.interval[i]))
                                   for i, n in enumerate(self.names)}
            out["not_determined"] = dict(self.uncertainty.not_determined)
        elif self.read_intervals:
            out["intervals_95"] = {n: list(map(float, self.read_intervals[n]))
                                   for n in self.names if n in self.read_intervals}
            out["not_determined"] = dict(self.read_reasons)
        return out

    def spectra(self):
        """Per record: (freqs, measured, fitted) linear levels at the fitted points (numpy).

        The fitted levels come from the residual vector at the optimum, which holds them: a
        record's first residuals are ``weight (log fitted − log measured)`` at its points
        (:func:`dtwin.identify.residuals.observation_residuals`), so nothing is simulated
        again. Without residuals (or with a failed point in them) the twin is simulated at the
        optimum."""
        levels = self._levels_from_residuals()
        if levels is not None:
            return levels
        p = self.problem
        sigs, values = p.signals(jnp.asarray(self.theta))
        gain = p.pset.gain(values)
        out = []
        for s, o in zip(sigs, p.observations, strict=True):
            model, meas = fitted_levels(s, o, gain)
            out.append((np.asarray(o.freqs), meas, model))
        return out

    def _levels_from_residuals(self):
        """:meth:`spectra` read from `residuals`; None when they cannot give it."""
        p, r = self.problem, self.residuals
        if r is None or p is None:
            return None
        r = np.asarray(r, dtype=np.float64)
        out, off = [], 0
        for o in p.observations:
            n = residual_count(o)
            levels = levels_from_residuals(r[off: off + n], o)
            if levels is None:
                return None
            out.append((np.asarray(o.freqs), levels[1], levels[0]))
            off += n
        return out if off + len(p.pset.priors) == r.shape[0] else None

