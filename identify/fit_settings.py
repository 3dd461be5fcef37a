"""Settings of a fit (:class:`FitSettings`): how :func:`dtwin.identify.fit.fit` and
:func:`dtwin.identify.fit_batch.fit_batch` search, stop and report, apart from what is fitted
(the records, the spec or twin, the free parameters and the keyword arguments of
:func:`dtwin.identify.problem.make_problem`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from dtwin.errors import SettingsError

from .stopping import SIGMA_TOL, SOLVERS

__all__ = ["FitSettings", "settings_and_problem_kwargs"]


@dataclasses.dataclass(frozen=True)
class FitSettings:
    """How a fit runs (defaults: one start, Levenberg–Marquardt, uncertainties checked).

    - `solver`: ``lm`` (Levenberg–Marquardt), ``gauss-newton`` or ``dogleg``.
    - `starts`: number of grid starts (batched evaluation), or an array of θ starts ``(k, p)``,
      or a list of dicts of physical starting values; `refine`: how many of the best starts are
      refined (batched); `spread`: grid half-width in θ (0.3 ≈ ±30 % for log parameters);
      `seed`: the grid's sub-sampling (:func:`dtwin.identify.fit.start_grid`).
    - `jac`: ``fwd`` (forward mode through diffrax) or ``rev``.
    - `max_steps`, `tol`: solver steps, and its rtol = atol on θ and on the residuals (RMS
      norm, :func:`dtwin.identify.stopping.make_solver`).
    - `sigma_tol`: also stop when the Gauss–Newton step from the accepted point is below this
      many standard errors (:func:`dtwin.identify.stopping.gauss_newton_step_in_sigma`; 0
      turns the test off).
    - `batch`: how the start grid and several refined starts run in their one compiled call,
      ``"auto"``, ``"vmap"`` or ``"map"`` (:func:`dtwin.identify.solve.batch_mode`).
    - `uncertainty`: compute covariance, intervals and flags. When a severity's profile
      likelihood passes a point of lower loss than the optimum (by more than the χ²₁ 95 %
      level), the optimum was a local one: the solver goes on from that point (up to
      ``MAX_RELOCATIONS`` times) and the result lists it in `relocations`.
    - `scan`: with `uncertainty`, also scan the loss of each free stiffness, mass and inertia
      that the Gaussian analysis finds determined over a decade each side of the optimum (8
      points, two batched evaluations each): a point of lower loss is refitted from as above,
      a second minimum within the 95 % level flags the parameter
      (:mod:`dtwin.identify.uncertainty`, "Scan").
    - `confounding`: with a calibrated spec and a free stiffness, damping ratio, mass or
      inertia, flag the parameters the calibrated mesh excitation and load-share clearances
      confound (:mod:`dtwin.identify.confounding`; one more Jacobian with their columns).
    - `progress`: print the stages and losses (stderr).
    - `throw`: raise `FitError` when not converged or at a bound.
    - `splits`: with a calibrated spec whose mesh excitation or sensor response was calibrated,
      fit the free parameters again with the other end of its excitation/response split (the
      stiffness waveform's excitation, a flat response) and report the split of least loss
      (for a sun or ring fault, scored with the low band too, which the fits do not use:
      :func:`dtwin.identify.excitation_response.low_band_losses`), with intervals over both
      where the record cannot reject either (:mod:`dtwin.identify.excitation_response`);
      None: where a fault severity is free (a healthy record cannot tell the splits apart, a
      fault's sidebands can), True: for any parameters, False: never. Not with a `problem`
      given to :func:`~dtwin.identify.fit.fit`.

    The solver's name is checked here; `jac` and `batch` where they are used (the same
    :class:`~dtwin.errors.SettingsError`).
    """

    solver: str = "lm"
    starts: int | np.ndarray | Sequence[Mapping[str, float]] = 1
    refine: int = 1
    spread: float = 0.3
    seed: int = 0
    jac: str = "fwd"
    max_steps: int = 40
    tol: float = 1e-4
    sigma_tol: float = SIGMA_TOL
    batch: str = "auto"
    uncertainty: bool = True
    scan: bool = True
    confounding: bool = True
    progress: bool = False
    throw: bool = False
    splits: bool | None = None

    def __post_init__(self):
        if self.solver not in SOLVERS:
            raise SettingsError(f"solver must be one of {SOLVERS}, got {self.solver!r}")


#: The names of :class:`FitSettings`' fields.
FIELDS = tuple(f.name for f in dataclasses.fields(FitSettings))


def settings_and_problem_kwargs(settings: FitSettings | None, overrides: Mapping[str, Any],
                                problem_keys: Sequence[str], *, unused: Sequence[str] = ()
                                ) -> tuple[FitSettings, dict[str, Any]]:
    """``(settings, problem_kwargs)`` from a caller's `settings` (None: the defaults) and
    keyword arguments `overrides`: those named like a :class:`FitSettings` field replace it,
    those in `problem_keys` (:func:`dtwin.identify.problem.make_problem`'s) are returned apart.
    Any other name, or a field in `unused` (one the caller has no use for), is a
    `SettingsError` naming what is taken."""
    if settings is not None and not isinstance(settings, FitSettings):
        raise SettingsError(f"settings must be a FitSettings, got {type(settings).__name__}")
    taken = [k for k in FIELDS if k not in unused]
    fields, problem_kwargs = {}, {}
    for k, v in overrides.items():
        if k in taken:
            fields[k] = v
        elif k in problem_keys:
            problem_kwargs[k] = v
        else:
            raise SettingsError(
                f"unknown fit setting {k!r}: the settings are {', '.join(taken)} "
                f"(FitSettings), and {', '.join(problem_keys)} (make_problem)")
    base = settings if settings is not None else FitSettings()
    return (dataclasses.replace(base, **fields) if fields else base), problem_kwargs
