"""dtwin: a differentiable digital twin of planetary gearboxes.

Importing dtwin turns on float64 in JAX and the persistent compilation cache
(:mod:`dtwin._config`). Public names are re-exported here; scripts and notebooks import only
these (and the submodules' documented functions).
"""

from . import (
    _cli_start,  # noqa: F401  (Ctrl-C while the dtwin command starts: one line, exit 130)
    _config,  # noqa: F401  (float64 + compilation cache, before anything else)
    _moved,  # noqa: F401  (old import paths of moved modules keep working)
)
from ._version import __version__ as __version__
from .errors import ChannelError as ChannelError
from .errors import DtwinError as DtwinError
from .errors import FitError as FitError
from .errors import GeometryError as GeometryError
from .errors import OutputExistsError as OutputExistsError
from .errors import ParameterError as ParameterError
from .errors import RecordError as RecordError
from .errors import SolverError as SolverError
from .errors import SpecError as SpecError
from .errors import UnreadableFileError as UnreadableFileError
from .io.output import OutputFolder as OutputFolder
from .io.readers import read_record as read_record
from .io.readers import write_record as write_record
from .io.record import Record as Record
from .io.validate import check_record as check_record
from .io.validate import validate_record as validate_record
from .model.faults import AbstractFault as AbstractFault
from .model.faults import MissingTooth as MissingTooth
from .model.faults import Pitting as Pitting
from .model.faults import RootCrack as RootCrack
from .model.faults import make_fault as make_fault
from .model.faults import mesh_phases as mesh_phases
from .model.faults import mesh_stiffnesses as mesh_stiffnesses
from .model.faults import parse_fault as parse_fault
from .model.faults import total_stiffness_loss as total_stiffness_loss
from .model.gears import GearSet as GearSet
from .model.gears import characteristic_frequencies as characteristic_frequencies
from .model.gears import mesh_phasing as mesh_phasing
from .model.lumped import LumpedParameters as LumpedParameters
from .model.modal import ModalResult as ModalResult
from .model.modal import frequency_sensitivities as frequency_sensitivities
from .model.modal import modal_analysis as modal_analysis
from .model.modal import natural_frequencies as natural_frequencies
from .model.motor.induction_motor import InductionMotor as InductionMotor
from .model.motor.loads import ConstantLoad as ConstantLoad
from .model.motor.loads import FluctuatingLoad as FluctuatingLoad
from .model.motor.pmsm import PMSM as PMSM
from .model.motor.shaft import Shaft as Shaft
from .model.motor.speed_source import IdealSpeedSource as IdealSpeedSource
from .model.motor.speed_source import SpeedProfile as SpeedProfile
from .model.registry import REGISTRY as REGISTRY
from .model.stiffness import mesh_stiffness_mean as mesh_stiffness_mean
from .model.stiffness import mesh_stiffness_waveform as mesh_stiffness_waveform
from .model.stiffness import single_pair_from_mean as single_pair_from_mean
from .model.stiffness import single_pair_stiffness as single_pair_stiffness
from .model.stiffness import transmission_error as transmission_error
from .model.twin import Coords as Coords
from .model.twin import Twin as Twin
from .signal.spectrum import FrequencyBasis as FrequencyBasis
from .signal.spectrum import amplitude_spectrum as amplitude_spectrum
from .signal.spectrum import envelope_spectrum as envelope_spectrum
from .signal.spectrum import find_peaks as find_peaks
from .signal.spectrum import label_peaks as label_peaks
from .signal.spectrum import level_at as level_at
from .signal.spectrum import noise_floor as noise_floor
from .signal.spectrum import time_stats as time_stats
from .signal.spectrum import to_db as to_db
from .simulation.simulate import DAQ as DAQ
from .simulation.simulate import SimResult as SimResult
from .simulation.simulate import SolverOptions as SolverOptions
from .simulation.simulate import simulate as simulate
from .spec import Spec as Spec
from .spec import load_spec as load_spec
from .spec import lumped_from_spec as lumped_from_spec
from .spec import preset as preset
from .spec import spec_to_dict as spec_to_dict
from .spec.build import build_twin as build_twin
from .spec.build import daq_from_spec as daq_from_spec
from .spec.motor import drive_from_spec as drive_from_spec

__all__ = [
    "__version__",
    "AbstractFault",
    "amplitude_spectrum",
    "build_twin",
    "ChannelError",
    "characteristic_frequencies",
    "check_record",
    "ConstantLoad",
    "Coords",
    "DAQ",
    "daq_from_spec",
    "drive_from_spec",
    "DtwinError",
    "envelope_spectrum",
    "find_peaks",
    "FitError",
    "FluctuatingLoad",
    "frequency_sensitivities",
    "FrequencyBasis",
    "GearSet",
    "GeometryError",
    "IdealSpeedSource",
    "InductionMotor",
    "label_peaks",
    "level_at",
    "load_spec",
    "lumped_from_spec",
    "LumpedParameters",
    "make_fault",
    "mesh_phases",
    "mesh_phasing",
    "mesh_stiffness_mean",
    "mesh_stiffness_waveform",
    "mesh_stiffnesses",
    "MissingTooth",
    "modal_analysis",
    "ModalResult",
    "natural_frequencies",
    "noise_floor",
    "OutputExistsError",
    "OutputFolder",
    "ParameterError",
    "parse_fault",
    "Pitting",
    "PMSM",
    "preset",
    "read_record",
    "Record",
    "RecordError",
    "REGISTRY",
    "RootCrack",
    "Shaft",
    "SimResult",
    "simulate",
    "single_pair_from_mean",
    "single_pair_stiffness",
    "SolverError",
    "SolverOptions",
    "Spec",
    "spec_to_dict",
    "SpecError",
    "SpeedProfile",
    "time_stats",
    "to_db",
    "total_stiffness_loss",
    "transmission_error",
    "Twin",
    "UnreadableFileError",
    "validate_record",
    "write_record",
]

# `import dtwin.simulate` (an old module path) keeps `dtwin.simulate` the function
_moved.register_imported("dtwin.simulate")
