"""dtwin.model.address / dtwin.model.registry: one address per parameter, read and written through the
registry by build, fit (ParameterSet), fleet and discovery.

A new parameter touches its registry entry and the part that owns it, nothing else: the test
below adds a part and its parameter that way and fits it through `ParameterSet`."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

from dtwin.errors import ParameterError
from dtwin.identify.params import ParameterSet, current_value
from dtwin.model.address import PartField
from dtwin.model.parts.base import AbstractPart
from dtwin.model.parts.imperfections import SunEccentricity
from dtwin.model.registry import REGISTRY, ParameterInfo, RegistryView, register
from dtwin.model.twin import Coords
from dtwin.spec import load_spec, preset, spec_to_dict
from dtwin.spec.build import build_twin


@pytest.fixture(scope="module")
def twin():
    return build_twin(preset("paper-sim"), kind="torsional")


class CarrierDrag(AbstractPart):
    """A constant drag torque (N·m) on the carrier: a part the twin did not know."""

    torque: jnp.ndarray

    def forces(self, twin, t, q, qdot, aux, mesh):
        f = Coords.zeros(twin.n_planets).set(theta_c=-self.torque)
        return f, jnp.zeros(0), {"torque_drag": self.torque}


def _zero_drag():
    return CarrierDrag(jnp.zeros(()))


def _carrier_force(tw) -> jnp.ndarray:
    """Sum of the parts' generalised forces on the carrier rotation (N·m) at rest."""
    total = jnp.zeros(())
    for p in tw.parts:
        if isinstance(p, CarrierDrag):
            f, _, _ = p.forces(tw, 0.0, None, None, None, None)
            total = total + f.theta_c
    return total


def test_a_new_part_and_parameter_fit_through_the_parameter_set(twin):
    """Register a parameter living in a new part (registry entry + the part, nothing else),
    then build, prepare (the part added at zero), apply, read back, and fit it: the value that
    reproduces a 'measured' carrier torque of −12.5 N·m is 12.5 N·m."""
    info = ParameterInfo("carrier_drag", "N*m", "drag torque on the carrier (test part)",
                         "test.carrier_drag", (0.0, 100.0), "logit", (0.0, 100.0),
                         address=PartField(CarrierDrag, ("torque",), factory=_zero_drag))
    register(info)
    try:
        ps = ParameterSet.build(["carrier_drag"], twin)
        assert current_value(twin, "carrier_drag") == 0.0  # no part yet: reads zero
        tw = ps.prepare(twin)
        drags = [p for p in tw.parts if isinstance(p, CarrierDrag)]
        assert len(drags) == 1 and float(drags[0].torque) == 0.0
        out = ps.apply(tw, jnp.asarray([7.0]))
        assert current_value(out, "carrier_drag") == 7.0

        def residual(theta, _):
            return jnp.atleast_1d(_carrier_force(ps.apply(tw, ps.values(theta))) - (-12.5))

        sol = optx.least_squares(residual, optx.LevenbergMarquardt(rtol=1e-10, atol=1e-12),
                                 jnp.zeros(1), max_steps=100)
        fitted = ps.as_dict(sol.value)["carrier_drag"]
        assert fitted == pytest.approx(12.5, rel=1e-8)
        # a different entry under the same name is refused
        with pytest.raises(ParameterError, match="already registered"):
            register(dataclasses.replace(info, unit="N"))
    finally:
        REGISTRY.pop("carrier_drag", None)
    with pytest.raises(ParameterError, match="unknown parameter"):
        ParameterSet.build(["carrier_drag"], twin)


def test_sun_eccentricity_is_registered_and_fittable(twin):
    """`sun_eccentricity` (spec `imperfections.sun_eccentricity`) lives in the SunEccentricity
    part: a twin built from a spec with 20 µm reads 20 µm; a healthy twin prepared by a
    ParameterSet gains a zero part, and writing 20 µm gives the spec-built part's value."""
    data = spec_to_dict(preset("paper-sim"))
    data["imperfections"]["sun_eccentricity"] = 2e-5
    from_spec = build_twin(load_spec(data), kind="torsional")
    assert current_value(from_spec, "sun_eccentricity") == pytest.approx(2e-5, rel=0, abs=0)
    assert current_value(twin, "sun_eccentricity") == 0.0
    ps = ParameterSet.build(["sun_eccentricity"], twin)
    assert ps.transforms == ("logit",)
    tw = ps.prepare(twin)
    [part] = [p for p in tw.parts if isinstance(p, SunEccentricity)]
    assert float(part.e) == 0.0
    out = ps.apply(tw, jnp.asarray([2e-5]))
    [written] = [p for p in out.parts if isinstance(p, SunEccentricity)]
    [built] = [p for p in from_spec.parts if isinstance(p, SunEccentricity)]
    assert float(written.e) == float(built.e) and float(written.phase) == float(built.phase)


def test_every_settable_entry_round_trips(twin):
    """Every registry entry with an address: ensure, set, get returns the value set."""
    for name, info in REGISTRY.items():
        if info.address is None or not info.address.changes_twin:
            continue
        if name == "load_torque":
            value = 33.0
        else:
            lo, hi = info.bounds
            value = 0.37 * hi if np.isfinite(hi) else 1.37 * current_value(twin, name)
        tw = info.address.ensure(twin)
        got = info.address.get(info.address.set(tw, value))
        assert got == pytest.approx(value, rel=1e-12), name


def test_effects_do_not_change_the_global_registry():
    """Discovery's effects declare their parameters; the extended model overlays them on the
    registry (RegistryView) and the global table stays as it was."""
    from dtwin.identify.discover import ExtendedModel
    from dtwin.identify.discover.effects import registered_effects
    from dtwin.identify.lines import Kinematics
    from dtwin.spec.build import daq_from_spec

    spec = preset("paper-sim")
    before = dict(REGISTRY)
    base = build_twin(spec, kind="torsional")
    model = ExtendedModel(base, registered_effects(), Kinematics.from_spec(spec),
                          daq_from_spec(spec), 1000, 30.0)
    assert dict(REGISTRY) == before
    names = [p.name for ps in model.parameters for p in ps]
    own = [n for n in names if n not in REGISTRY]  # e.g. sun_eccentricity_x; sun_fault is global
    assert own and len(own) < len(names)
    assert isinstance(model.registry, RegistryView)
    assert model.registry.lookup(own[0]).name == own[0]
    assert model.registry.lookup("sun_fault") is REGISTRY["sun_fault"]
    with pytest.raises(ParameterError):
        ParameterSet.build([own[0]], build_twin(spec, kind="torsional"))  # not global
