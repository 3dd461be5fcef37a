"""Where a registered parameter lives in a twin: one typed address per parameter.

Every entry of :mod:`dtwin.model.registry` names its address; building, fitting
(:class:`dtwin.identify.params.ParameterSet`), fleet runs and discovery effects read and write
parameters through it and nowhere else. In the spirit of ``equinox.tree_at``, an address is a
small static object with

- ``get(twin)``: the value (SI) in `twin`;
- ``set(twin, value)``: a new twin with the value written (differentiable in `value`);
- ``ensure(twin)``: a twin holding what ``set`` needs (a zero-valued part added when the twin
  has none; zero leaves the dynamics bit-identical), called once, outside any jit.

The kinds of address are final classes: :class:`LumpedField` (a field of
:class:`dtwin.model.lumped.LumpedParameters`), :class:`PartField` (a field of the first part of a
type, optionally matching a condition), :class:`PartElement` (one element of a part's array
field), :class:`Tie` (several addresses set together) and
:class:`SignalGain` (a gain applied to the simulated signal after the solve, not a twin field).
A new parameter is a registry entry with one of these, next to the part that owns it.
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..errors import ParameterError
from .lumped import LumpedParameters, replace

__all__ = ["AbstractAddress", "LumpedField", "PartElement", "PartField", "SignalGain", "Tie"]


class AbstractAddress(abc.ABC):
    """Where one parameter lives in a twin (module docstring)."""

    #: False for a parameter applied after the ODE solve (it needs no tangent through it).
    changes_twin: ClassVar[bool] = True

    @abc.abstractmethod
    def get(self, twin) -> float:
        """The value (SI) in `twin` (a float)."""

    @abc.abstractmethod
    def set(self, twin, value):
        """`twin` with `value` (SI, scalar; may be traced) written."""

    @abc.abstractmethod
    def ensure(self, twin):
        """`twin` holding what :meth:`set` needs (a zero-valued part added if missing)."""


@dataclasses.dataclass(frozen=True)
class LumpedField(AbstractAddress):
    """A field of the twin's :class:`dtwin.model.lumped.LumpedParameters` (``twin.lp``)."""

    field: str

    def __post_init__(self):
        if self.field not in LumpedParameters.__dataclass_fields__:
            raise ParameterError(f"LumpedParameters has no field {self.field!r}")

    def get(self, twin) -> float:
        return float(getattr(twin.lp, self.field))

    def set(self, twin, value):
        return eqx.tree_at(lambda t: t.lp, twin, replace(twin.lp, **{self.field: value}))

    def ensure(self, twin):
        return twin


def _attr(obj, path: tuple[str, ...]):
    for name in path:
        obj = getattr(obj, name)
    return obj


@dataclasses.dataclass(frozen=True)
class PartField(AbstractAddress):
    """A field of the first part of type `part` in ``twin.parts`` whose attributes match.

    - `part`: the part class (e.g. :class:`dtwin.model.parts.imperfections.TransmissionError`).
    - `path`: attribute path to the scalar inside the part, e.g. ``("fault", "severity")``.
    - `match`: ``((dotted attribute path, value), ...)`` the part must satisfy, e.g.
      ``(("fault.location", "sun"),)``.
    - `factory`: builds the part at value zero (for :meth:`ensure`); None: the part must exist.
    - `missing`: the value :meth:`get` reports when the twin has no such part (SI).
    """

    part: type
    path: tuple[str, ...]
    match: tuple[tuple[str, Any], ...] = ()
    factory: Callable[[], Any] | None = None
    missing: float = 0.0

    def _describe(self) -> str:
        cond = ", ".join(f"{k} = {v!r}" for k, v in self.match)
        return self.part.__name__ + (f" with {cond}" if cond else "")

    def index(self, twin) -> int | None:
        """Position in ``twin.parts`` of the part, or None."""
        for i, p in enumerate(twin.parts):
            if isinstance(p, self.part) and all(
                    _attr(p, tuple(k.split("."))) == v for k, v in self.match):
                return i
        return None

    def get(self, twin) -> float:
        i = self.index(twin)
        if i is None:
            return float(self.missing)
        try:
            return float(_attr(twin.parts[i], self.path))
        except AttributeError:
            raise ParameterError(f"the twin's {self._describe()} has no "
                                 f"{'.'.join(self.path)} to read") from None

    def set(self, twin, value):
        i = self.index(twin)
        if i is None:
            raise ParameterError(f"the twin has no {self._describe()}; add one first "
                                 "(ensure, or ParameterSet.prepare)")
        try:
            _attr(twin.parts[i], self.path)
        except AttributeError:
            raise ParameterError(f"the twin's {self._describe()} has no "
                                 f"{'.'.join(self.path)} to set") from None
        return eqx.tree_at(lambda t: _attr(t.parts[i], self.path), twin,
                           jnp.asarray(value, dtype=jnp.float64))

    def ensure(self, twin):
        if self.factory is None or self.index(twin) is not None:
            return twin
        return twin.with_parts(self.factory())

    def make(self, value):
        """A new part (from `factory`) holding `value` (SI)."""
        if self.factory is None:
            raise ParameterError(f"{self._describe()}: no factory to build the part")
        return eqx.tree_at(lambda p: _attr(p, self.path), self.factory(),
                           jnp.asarray(value, dtype=jnp.float64))


@dataclasses.dataclass(frozen=True)
class PartElement(AbstractAddress):
    """One element of an array field of the first part of type `part` (e.g. the k-th cosine
    coefficient of the transfer path's window).

    - `part`, `path`: as :class:`PartField`, the path ending at a 1-D array (or None).
    - `element`: the index in that array.
    - `fill`: ``fill(part, size)`` → the array to install when the field is None or shorter
      than `size` (:meth:`ensure`); it must leave the dynamics unchanged (e.g. the series of
      the window the part already uses, or zeros).
    - `size`: the length :meth:`ensure` makes the array at least.
    - `factory`: builds the part when the twin has none (None: the part must exist).
    """

    part: type
    path: tuple[str, ...]
    element: int
    fill: Callable[[Any, int], Any]
    size: int
    factory: Callable[[], Any] | None = None

    def _index(self, twin) -> int | None:
        return next((i for i, p in enumerate(twin.parts) if isinstance(p, self.part)), None)

    def _array(self, twin):
        i = self._index(twin)
        if i is None:
            return None, None
        return i, _attr(twin.parts[i], self.path)

    def get(self, twin) -> float:
        _, arr = self._array(twin)
        if arr is None or jnp.shape(arr)[0] <= self.element:
            return 0.0
        return float(arr[self.element])

    def set(self, twin, value):
        i, arr = self._array(twin)
        if arr is None or jnp.shape(arr)[0] <= self.element:
            raise ParameterError(f"the twin's {self.part.__name__}.{'.'.join(self.path)} has no "
                                 f"element {self.element}; call ensure first")
        new = jnp.asarray(arr).at[self.element].set(jnp.asarray(value, dtype=jnp.float64))
        return eqx.tree_at(lambda t: _attr(t.parts[i], self.path), twin, new)

    def ensure(self, twin):
        if self._index(twin) is None:
            if self.factory is None:
                return twin
            twin = twin.with_parts(self.factory())
        i, arr = self._array(twin)
        if arr is None or jnp.shape(arr)[0] < self.size:
            twin = eqx.tree_at(lambda t: _attr(t.parts[i], self.path), twin,
                               jnp.asarray(self.fill(twin.parts[i], self.size),
                                           dtype=jnp.float64),
                               is_leaf=lambda x: x is None)
        return twin


@dataclasses.dataclass(frozen=True)
class Tie(AbstractAddress):
    """Several addresses set to one value together (reads their mean)."""

    members: tuple[AbstractAddress, ...]

    def get(self, twin) -> float:
        return float(np.mean([m.get(twin) for m in self.members]))

    def set(self, twin, value):
        for m in self.members:
            twin = m.set(twin, value)
        return twin

    def ensure(self, twin):
        for m in self.members:
            twin = m.ensure(twin)
        return twin


@dataclasses.dataclass(frozen=True)
class SignalGain(AbstractAddress):
    """A gain on the simulated signal, applied after the solve (not a twin field): reads 1,
    writes nothing; the residuals multiply the signal by the value."""

    changes_twin: ClassVar[bool] = False

    def get(self, twin) -> float:
        return 1.0

    def set(self, twin, value):
        return twin

    def ensure(self, twin):
        return twin
