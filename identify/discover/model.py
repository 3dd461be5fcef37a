"""The extended model of a discrepancy search: the base twin plus every candidate's parts, its
simulations and responses, cached in memory and optionally on disk."""

from __future__ import annotations

import collections
import dataclasses
import hashlib
import os
from collections.abc import Sequence
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from dtwin.errors import SettingsError
from dtwin.model.registry import RegistryView
from dtwin.simulation.simulate import SolverOptions, simulate

from ..lines import Kinematics
from .statistics import P_MAX


class ExtendedModel:
    """The base twin plus every candidate's parts, parametrised by one vector of fitting units
    (θ = 0: the base twin, bit for bit). One compilation serves the base simulation, the
    confirmation simulations and the responses of every candidate (``jax.jvp``)."""

    def __init__(self, base_twin, effects, kin: Kinematics, daq, n_samples: int,
                 f_sun: float, solver=None, response_mode: str = "fd"):
        self.base_twin = base_twin
        self.effects = tuple(effects)
        self.kin = kin
        self.daq = daq
        self.n = int(n_samples)
        self.duration = n_samples / daq.sample_rate
        self.f_sun = float(f_sun)
        self.solver = solver or SolverOptions(adjoint="forward")
        #: how many simulations were integrated each way (`dtwin.simulation.simulate.SimResult.method`)
        self.methods: collections.Counter[str] = collections.Counter()
        if response_mode not in ("fd", "jvp"):
            raise SettingsError(f"response_mode must be 'fd' or 'jvp', got {response_mode!r}")
        self.response_mode = response_mode
        self.parameters = [e.parameters(base_twin) for e in self.effects]
        # the effects' parameters over the global registry, which stays unchanged
        self.registry = RegistryView.of(p.info() for ps in self.parameters for p in ps)
        sizes = [len(ps) for ps in self.parameters]
        if max(sizes, default=0) > P_MAX:
            raise SettingsError(f"an effect has more than {P_MAX} parameters")
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self.scales = np.concatenate([[p.scale for p in ps] for ps in self.parameters]
                                     or [np.zeros(0)])
        self._columns: dict[int, np.ndarray] = {}
        self._base: np.ndarray | None = None
        #: whether the base signal was one tiled period (None: read from disk, not known), the
        #: base integrated in full where a response needs it, the last simulation's method
        self._base_tiled: bool | None = None
        self._base_full: np.ndarray | None = None
        self.last_method = ""
        self._disk = _disk_path(self)
        if self._disk is not None and self._disk.exists():
            with np.load(self._disk) as z:
                self._base = z["base"] if "base" in z else None
                self._columns = {int(k[4:]): z[k] for k in z.files if k.startswith("col_")}

    def _save(self) -> None:
        if self._disk is None:
            return
        arrays = {f"col_{j}": v for j, v in self._columns.items()}
        if self._base is not None:
            arrays["base"] = self._base
        tmp = self._disk.with_suffix(".tmp.npz")
        np.savez(tmp, **arrays)
        tmp.replace(self._disk)

    @property
    def size(self) -> int:
        return int(self.offsets[-1])

    def slice(self, i: int) -> slice:
        return slice(int(self.offsets[i]), int(self.offsets[i + 1]))

    def twin(self, theta_units, indices: Sequence[int] | None = None):
        """The twin at fitting units `theta_units`: the base twin plus the effects `indices`
        (default: all; the others are left out, not added at zero amplitude)."""
        theta = jnp.asarray(theta_units) * jnp.asarray(self.scales)
        parts = []
        for i in range(len(self.effects)) if indices is None else indices:
            parts += list(self.effects[i].parts(theta[self.slice(i)], self.base_twin, self.kin))
        return self.base_twin.with_parts(*parts)

    def signal(self, theta_units, full: bool = False) -> np.ndarray:
        """Simulated sensor signal (no noise) at `theta_units`; `full`: the whole record
        integrated, not one tiled period (`dtwin.simulation.simulate.SolverOptions.periodic`)."""
        return np.asarray(_ext_signal(self, jnp.asarray(theta_units, dtype=jnp.float64), full))

    def base_signal(self) -> np.ndarray:
        if self._base is None:
            self._base = self.signal(np.zeros(self.size))
            self._base_tiled = self.last_method == "periodic"
            self._save()
        return self._base

    def _difference_base(self) -> np.ndarray:
        """The base signal integrated as the last simulation was: a response is a difference
        of two simulations, and a tiled and a whole-record integration differ by what the
        twin's sampling aliases (`dtwin.simulate`, the sensor paths' filters), which must not
        enter it."""
        base = self.base_signal()
        if self._base_tiled and self.last_method != "periodic":
            if self._base_full is None:
                self._base_full = self.signal(np.zeros(self.size), full=True)
            return self._base_full
        return base

    def ensure_responses(self, indices: Sequence[int]) -> None:
        """Compute the responses of effects `indices`, one column per parameter.

        ``response="fd"`` (default): forward difference with a step of one fitting unit (the
        effect's typical amplitude scale), ``(s(h e_j) − s(0)) / h`` — one simulation per
        parameter, no extra compilation; exact up to the effect's own nonlinearity, which the
        confirmation simulation checks. ``response="jvp"``: forward-mode ``jax.jvp`` through the
        solve (exact derivative; about two simulations plus a compilation).
        """
        missing = [j for i in indices for j in range(self.slice(i).start, self.slice(i).stop)
                   if j not in self._columns]
        for j in missing:
            tangent = np.zeros(self.size)
            tangent[j] = 1.0
            if self.response_mode == "jvp":
                primal, tang = _ext_jvp(self, jnp.zeros(self.size), jnp.asarray(tangent))
                if self._base is None:
                    self._base = np.asarray(primal)
                self._columns[j] = np.asarray(tang)
            else:
                self.base_signal()  # first: it records how the base was integrated
                sig = self.signal(tangent)
                self._columns[j] = sig - self._difference_base()
            self._save()

    def response(self, i: int) -> np.ndarray:
        """d signal / d θ (fitting units) of effect `i` at θ = 0: shape (n, p_i)."""
        sl = self.slice(i)
        self.ensure_responses([i])
        return np.stack([self._columns[j] for j in range(sl.start, sl.stop)], axis=1)


def _ext_signal_impl(model: ExtendedModel, theta, full: bool = False):
    # with concrete parameters `simulate` checks the periodic steady state (one period of the gear
    # set tiled when the twin is periodic, `SolverOptions.periodic`) and falls back to the whole
    # record when the signal is not periodic; under `jax.jvp` it could not check, so the whole
    # record is integrated there
    solver = model.solver
    traced = isinstance(theta, jax.core.Tracer)
    if traced or full:
        solver = dataclasses.replace(solver, periodic="off")
    res = simulate(model.twin(theta), duration=model.duration, f_sun=model.f_sun, daq=model.daq,
                   solver=solver, check=not traced)
    model.methods[res.method] += 1
    if not traced:
        model.last_method = res.method
    return res.signal


_MODEL_CACHE: dict = {}


def _disk_path(model: ExtendedModel):
    """Where the base signal and responses persist between processes: only when the
    environment variable ``DTWIN_DISCOVER_CACHE`` names a folder (off by default)."""
    root = os.environ.get("DTWIN_DISCOVER_CACHE")
    if not root:
        return None
    key = "|".join([_fingerprint(model.base_twin), repr(model.effects), repr(model.kin),
                    repr(model.daq), str(model.n), repr(model.f_sun), repr(model.solver),
                    repr(model.scales.tolist()), model.response_mode])
    Path(root).mkdir(parents=True, exist_ok=True)
    return Path(root) / (hashlib.sha1(key.encode()).hexdigest() + ".npz")


def _fingerprint(twin) -> str:
    leaves, treedef = jax.tree_util.tree_flatten(eqx.filter(twin, eqx.is_array))
    h = hashlib.sha1(str(treedef).encode())
    h.update(str(jax.tree_util.tree_structure(twin)).encode())
    for leaf in leaves:
        h.update(np.asarray(leaf).tobytes())
    return h.hexdigest()


def extended_model(base_twin, effects, kin, daq, n_samples, f_sun, solver=None,
                   response_mode: str = "fd") -> ExtendedModel:
    """An :class:`ExtendedModel`, cached by its content (base twin values and structure,
    effects, kinematics, DAQ, length, speed), so repeated searches on records of the same
    machine reuse the base simulation and the responses."""
    key = (_fingerprint(base_twin), tuple(effects), kin, daq, int(n_samples), float(f_sun),
           solver, response_mode)
    if key not in _MODEL_CACHE:
        _MODEL_CACHE[key] = ExtendedModel(base_twin, effects, kin, daq, n_samples, f_sun, solver,
                                          response_mode)
    return _MODEL_CACHE[key]


def _ext_signal(model: ExtendedModel, theta, full: bool = False):
    # no outer jit: `simulate` builds its time grid with concrete values; its solve is jitted
    # (and cached by the twin's structure), so repeated calls do not recompile
    return _ext_signal_impl(model, theta, full)


def _ext_jvp(model: ExtendedModel, theta, tangent):
    return jax.jvp(lambda th: _ext_signal_impl(model, th), (theta,), (tangent,))

