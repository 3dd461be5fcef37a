"""Which twin parameters a fit moves, and how: registry names ↔ an unconstrained vector θ.

A :class:`ParameterSet` names the free parameters (registry names, :mod:`dtwin.model.registry`), their
initial values (from the twin or given), bounds, optional Gaussian priors and the parameters held
fixed at given values. A fit works on a nondimensional, unconstrained vector ``θ`` (one entry per
free parameter, ``θ = 0`` at the initial value) mapped to physical values by the registry's
transform:

- ``log``:   ``x = x0 exp(θ)``                          (positive quantities; θ ≈ relative change)
- ``logit``: ``x = lo + (hi - lo) sigmoid(θ + logit((x0 - lo)/(hi - lo)))``   (inside (lo, hi))
- ``none``:  ``x = x0 + s θ`` with ``s = max(|x0|, 1)``

so every θ is of order one and the bounds can never be crossed (optimistix has no bounds for
least squares; docs/identification.md). :meth:`ParameterSet.apply` writes values into a
`Twin` through each parameter's registry address (:mod:`dtwin.model.address`): lumped fields, ties
(``zeta_mesh`` → ``zeta_sun_planet`` and ``zeta_ring_planet``), fields of parts (fault
severities, ``te_amplitude``, ``sun_eccentricity``, ``load_torque``; :meth:`ParameterSet.prepare`
adds a zero-valued part where the twin has none, before any compute: zero is bit-identical to
healthy). ``sensor_gain`` is not a twin field: the residuals multiply the simulated signal by
it (:meth:`ParameterSet.gain`).

Unknown names raise :class:`~dtwin.errors.ParameterError` when the set is built, before any
simulation.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from dtwin.errors import ParameterError
from dtwin.model.address import SignalGain
from dtwin.model.registry import ParameterInfo, ensure_parts, get_value, lookup, set_value

__all__ = ["ParameterSet", "current_value", "ensure_fault_parts", "settable"]

#: Smallest distance (as a fraction of the range) an initial value keeps from a logit bound.
_EDGE = 1e-3


def settable(name: str) -> bool:
    """Whether :meth:`ParameterSet.apply` can write the registry parameter `name` into a twin
    (its registry entry has an address, :mod:`dtwin.model.address`)."""
    return lookup(name).settable


def ensure_fault_parts(twin, names: Sequence[str]):
    """A twin holding every part the free `names` live in (:func:`dtwin.model.registry.ensure_parts`:
    e.g. a zero-severity `MissingTooth` for a free ``<location>_fault``, a zero-amplitude
    `TransmissionError` for ``te_amplitude``). Zero leaves the dynamics bit-identical."""
    return ensure_parts(twin, names)


def current_value(twin, name: str) -> float:
    """The value of registry parameter `name` in `twin` (a tie: the mean of its members),
    read through its address (:func:`dtwin.model.registry.get_value`)."""
    return get_value(twin, name)


@dataclasses.dataclass(frozen=True)
class _Free:
    name: str
    transform: str
    x0: float
    lower: float
    upper: float


class ParameterSet(eqx.Module):
    """Free and fixed parameters of a fit, with transforms, bounds and priors (module docstring).

    Build with :meth:`build`. Fields (static except `x0`, an array so that fits from other
    initial values reuse one compiled function):

    - `free`: registry names of the free parameters, in θ order.
    - `transforms`, `x0`, `lower`, `upper`: per free parameter (initial value and bounds in SI).
    - `fixed`: names → values written into the twin once, before the fit.
    - `priors`: names → ``(mean, sd)`` (SI): a residual ``(x - mean)/sd`` per prior.
    """

    free: tuple[str, ...] = eqx.field(static=True)
    transforms: tuple[str, ...] = eqx.field(static=True)
    x0: jax.Array
    lower: tuple[float, ...] = eqx.field(static=True)
    upper: tuple[float, ...] = eqx.field(static=True)
    fixed: tuple[tuple[str, float], ...] = eqx.field(static=True, default=())
    priors: tuple[tuple[str, float, float], ...] = eqx.field(static=True, default=())

    @classmethod
    def build(
        cls,
        free: Sequence[str] | str,
        twin=None,
        *,
        initial: Mapping[str, float] | None = None,
        fixed: Mapping[str, float] | None = None,
        bounds: Mapping[str, tuple[float, float]] | None = None,
        priors: Mapping[str, tuple[float, float]] | None = None,
    ) -> ParameterSet:
        """A parameter set; every name is checked against the registry first.

        **Arguments:**

        - `free`: registry names (a list, or one comma-separated string as on the CLI).
        - `twin`: the twin giving initial values (unless `initial` names them).
        - `initial`: initial values (SI) overriding the twin's.
        - `fixed`: values (SI) to hold fixed (written into the twin by :meth:`prepare`).
        - `bounds`: (lower, upper) overriding the registry's; a ``log`` parameter with finite
          bounds becomes ``logit`` between them.
        - `priors`: ``(mean, sd)`` in SI per parameter (regularisation residuals).

        **Raises:** `ParameterError` for an unknown, duplicated, unsettable or tied-and-member
        name, an initial value outside its bounds, or a ``log`` parameter starting at 0.
        """
        if isinstance(free, str):
            free = [s.strip() for s in free.split(",") if s.strip()]
        free = list(free)
        if not free:
            raise ParameterError("no free parameter given; name at least one registry parameter")
        infos = _checked_names(free, fixed, initial, bounds, priors)
        fixed = dict(fixed or {})
        both = set(fixed) & set(free)
        if both:
            raise ParameterError(f"parameters both free and fixed: {sorted(both)}")
        frees = [_free(info, twin, initial, bounds) for info in infos]
        pri = tuple((n, float(m), float(s)) for n, (m, s) in (priors or {}).items())
        for n, _, s in pri:
            if n not in free:
                raise ParameterError(f"prior on {n!r}, which is not free")
            if not s > 0:
                raise ParameterError(f"prior on {n!r} needs a positive sd, got {s}")
        return cls(
            free=tuple(f.name for f in frees),
            transforms=tuple(f.transform for f in frees),
            x0=jnp.asarray([f.x0 for f in frees], dtype=jnp.float64),
            lower=tuple(f.lower for f in frees),
            upper=tuple(f.upper for f in frees),
            fixed=tuple((k, float(v)) for k, v in fixed.items()),
            priors=pri,
        )

    # ---------------------------------------------------------------------------- mapping
    @property
    def size(self) -> int:
        return len(self.free)

    def _offset(self, i: int):
        lo, hi, x0 = self.lower[i], self.upper[i], self.x0[i]
        u = (x0 - lo) / (hi - lo)
        return jnp.log(u / (1.0 - u))

    def values(self, theta) -> jax.Array:
        """Physical values (SI), shape ``(p,)``, of the unconstrained vector `theta`."""
        theta = jnp.asarray(theta, dtype=jnp.float64)
        out = []
        for i, tr in enumerate(self.transforms):
            t = theta[..., i]
            if tr == "log":
                out.append(self.x0[i] * jnp.exp(t))
            elif tr == "logit":
                lo, hi = self.lower[i], self.upper[i]
                out.append(lo + (hi - lo) * jax.nn.sigmoid(t + self._offset(i)))
            else:
                out.append(self.x0[i] + jnp.maximum(jnp.abs(self.x0[i]), 1.0) * t)
        return jnp.stack(out, axis=-1)

    def theta(self, values) -> np.ndarray:
        """The unconstrained vector of physical `values` (a sequence in `free` order, or a
        mapping by name); values on a logit bound are pulled inside by 1e-3 of the range."""
        if isinstance(values, Mapping):
            values = [values[n] for n in self.free]
        out = []
        x0s = [float(v) for v in np.asarray(self.x0)]
        for i, (tr, x) in enumerate(zip(self.transforms, values, strict=True)):
            x = float(x)
            if tr == "log":
                out.append(math.log(x / x0s[i]))
            elif tr == "logit":
                lo, hi = self.lower[i], self.upper[i]
                u = min(max((x - lo) / (hi - lo), _EDGE), 1 - _EDGE)
                out.append(math.log(u / (1 - u)) - float(self._offset(i)))
            else:
                out.append((x - x0s[i]) / max(abs(x0s[i]), 1.0))
        return np.asarray(out)

    def dvalues_dtheta(self, theta) -> jax.Array:
        """Derivative of each physical value by its θ (the transform is diagonal)."""
        return jax.jacfwd(lambda t: self.values(t))(jnp.asarray(theta, dtype=jnp.float64)).diagonal()

    def as_dict(self, theta) -> dict[str, float]:
        """Physical values by name (floats)."""
        return {n: float(v) for n, v in zip(self.free, np.asarray(self.values(theta)), strict=True)}

    # ---------------------------------------------------------------------------- twin
    def prepare(self, twin):
        """The twin a fit starts from: the parts the free names need added and the fixed
        values written (call once, outside any jit)."""
        twin = ensure_fault_parts(twin, self.free + tuple(n for n, _ in self.fixed))
        for n, v in self.fixed:
            twin = set_value(twin, n, v)
        return twin

    def apply(self, twin, values):
        """`twin` with the free parameters set to `values` (SI, shape ``(p,)`` or a mapping);
        differentiable. The twin must come from :meth:`prepare`."""
        if isinstance(values, Mapping):
            values = jnp.stack([jnp.asarray(values[n], dtype=jnp.float64) for n in self.free])
        for i, n in enumerate(self.free):
            twin = set_value(twin, n, values[i])
        return twin

    @property
    def twin_indices(self) -> tuple[int, ...]:
        """Positions in `free` of the parameters that change the twin (all but signal gains
        such as ``sensor_gain``, which scale the simulated signal after the solve): only these
        need tangents through the ODE (`dtwin.identify.solve.value_and_jacfwd`)."""
        return tuple(i for i, n in enumerate(self.free) if lookup(n).address.changes_twin)

    def gain(self, values) -> jax.Array:
        """The product of the signal gains among `values` (``sensor_gain``; 1 when none is
        free)."""
        g = jnp.ones((), dtype=jnp.float64)
        for i, n in enumerate(self.free):
            if isinstance(lookup(n).address, SignalGain):
                g = g * values[i]
        return g

    def prior_residuals(self, values) -> jax.Array:
        """``(x - mean)/sd`` for every prior (empty without priors)."""
        if not self.priors:
            return jnp.zeros(0)
        return jnp.stack([(values[self.free.index(n)] - m) / s for n, m, s in self.priors])

    def at_bound(self, theta, tol: float = 1e-3) -> list[str]:
        """Free logit parameters within `tol` of the range from a bound."""
        vals = np.asarray(self.values(theta))
        out = []
        for i, tr in enumerate(self.transforms):
            if tr == "logit":
                u = (vals[i] - self.lower[i]) / (self.upper[i] - self.lower[i])
                if u < tol or u > 1 - tol:
                    out.append(self.free[i])
        return out

    def summary(self) -> str:
        """A readable table of the free (initial value, bounds, transform, prior) and fixed
        parameters."""
        rows = [f"{'parameter':<18} {'status':<6} {'initial/value':>14} {'unit':<8} "
                f"{'bounds':<22} transform"]
        pri = {n: (m, s) for n, m, s in self.priors}
        for i, n in enumerate(self.free):
            info = lookup(n)
            b = f"[{self.lower[i]:.3g}, {self.upper[i]:.3g}]"
            extra = f"  prior {pri[n][0]:.3g} ± {pri[n][1]:.3g}" if n in pri else ""
            rows.append(f"{n:<18} {'free':<6} {float(self.x0[i]):>14.5g} {info.unit:<8} {b:<22} "
                        f"{self.transforms[i]}{extra}")
        for n, v in self.fixed:
            rows.append(f"{n:<18} {'fixed':<6} {v:>14.5g} {lookup(n).unit:<8}")
        return "\n".join(rows)


def describe_free(names: Sequence[str]) -> list[dict[str, Any]]:
    """Registry entries of `names` as dicts (unit, description, transform, bounds)."""
    return [dataclasses.asdict(lookup(n)) for n in names]


def _checked_names(free: list[str], fixed, initial, bounds, priors) -> list[ParameterInfo]:
    """The registry entries of `free`, after every name given is checked: unknown, repeated,
    the operating point, not settable, or freed beside a parameter that ties it."""
    infos: list[ParameterInfo] = [lookup(n) for n in free]  # unknown names raise here
    for n in list(fixed or {}) + list(initial or {}) + list(bounds or {}) + list(priors or {}):
        lookup(n)
    if len(set(free)) != len(free):
        raise ParameterError(f"free parameters repeat a name: {free}")
    for info in infos:
        if info.name == "f_sun":
            raise ParameterError(
                "f_sun is the operating point: it is estimated from the record before the "
                "fit (dtwin.identify.operating_point) and held fixed; do not list it as free"
            )
        if not settable(info.name):
            raise ParameterError(f"parameter {info.name!r} cannot be fitted by identify yet")
        for t in info.ties:
            if t in free:
                raise ParameterError(f"{info.name} ties {', '.join(info.ties)}: do not free "
                                     f"{t} as well")
    return infos


def _free(info: ParameterInfo, twin, initial, bounds) -> _Free:
    """A free parameter: its transform (``log`` with finite bounds given becomes ``logit``),
    initial value (given, else the twin's; checked against the transform, and kept off a
    ``logit`` parameter's bounds) and bounds."""
    lo, hi = (bounds or {}).get(info.name, info.bounds)
    lo, hi = float(lo), float(hi)
    tr = info.transform
    if tr == "log" and math.isfinite(hi) and lo > 0 and (bounds or {}).get(info.name):
        tr = "logit"
    if (initial or {}).get(info.name) is not None:
        x0 = float(initial[info.name])
    elif twin is not None:
        x0 = current_value(twin, info.name)
    else:
        raise ParameterError(f"{info.name}: give an initial value or a twin to read it")
    if tr == "log":
        if not x0 > 0:
            raise ParameterError(
                f"{info.name} starts at {x0:g} {info.unit}; its log transform needs a "
                "positive initial value: pass initial={...}"
            )
    elif tr == "logit":
        if not (lo <= x0 <= hi):
            raise ParameterError(f"{info.name} = {x0:g} lies outside its bounds "
                                 f"[{lo:g}, {hi:g}] {info.unit}")
        span = hi - lo
        x0 = min(max(x0, lo + _EDGE * span), hi - _EDGE * span)
    return _Free(info.name, tr, x0, lo, hi)
