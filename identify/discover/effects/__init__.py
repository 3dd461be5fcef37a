"""The library of candidate effects (see :mod:`dtwin.identify.discover.effects.base`).

Default candidates, in their look-alike groups:

- ``carrier_sidebands`` (forbidden ``m fm + n fc`` lines): planet position errors, unequal load
  sharing, carrier eccentricity, load-torque fluctuation at 1 fc, a ring local fault;
- ``sun_rotation`` (``m fm ± j fs/N + n fc``): sun eccentricity, a sun local fault;
- ``planet_fault`` (``m fm ± j fp + n fc``): a planet local fault;
- ``motor`` (``± h fe + m fm``): torque ripple at 6 fe;
- ``planet_bearing_outer`` / ``_inner`` / ``_ball``: a planet-bearing defect (BPFO, BPFI, 2 BSF;
  geometry from the spec's ``[bearings.planet]``, withdrawn without it);
- ``housing_resonance``: a housing mode in the transfer path (frequency and damping located
  from the record, offered only when the lines call for one);
- ``carrier_sidebands`` also holds the time-varying (planet-pass) transfer path, offered only
  when the base twin's path has no planet window;
- ``located_modulation``: a load/speed fluctuation at a frequency located from the record
  (``f_x`` and ``L ± f_x``), offered only when the residual lines hold such a family.
"""

from .base import AbstractEffect as AbstractEffect
from .base import EffectContext as EffectContext
from .base import EffectParameter as EffectParameter
from .base import SignatureLine as SignatureLine
from .base import register_effect as register_effect
from .base import registered_effects as registered_effects
from .base import unregister_effect as unregister_effect
from .bearing import PlanetBearingEffect as PlanetBearingEffect
from .eccentricity import CarrierEccentricityEffect as CarrierEccentricityEffect
from .eccentricity import SunEccentricityEffect as SunEccentricityEffect
from .load_fluctuation import LoadFluctuationEffect as LoadFluctuationEffect
from .load_sharing import LoadSharingEffect as LoadSharingEffect
from .local_fault import LocalFaultEffect as LocalFaultEffect
from .modulation import LocatedModulationEffect as LocatedModulationEffect
from .planet_position import PlanetPositionEffect as PlanetPositionEffect
from .torque_ripple import TorqueRippleEffect as TorqueRippleEffect
from .transfer_path import HousingResonanceEffect as HousingResonanceEffect
from .transfer_path import TimeVaryingPathEffect as TimeVaryingPathEffect

for _e in (PlanetPositionEffect(), LoadSharingEffect(), CarrierEccentricityEffect(),
           LoadFluctuationEffect(order=1), LocalFaultEffect(location="ring"),
           SunEccentricityEffect(), LocalFaultEffect(location="sun"),
           LocalFaultEffect(location="planet"), TorqueRippleEffect(harmonic=6),
           PlanetBearingEffect(race="outer"), PlanetBearingEffect(race="inner"),
           PlanetBearingEffect(race="ball"), HousingResonanceEffect(), TimeVaryingPathEffect(),
           LocatedModulationEffect()):
    register_effect(_e)
del _e
