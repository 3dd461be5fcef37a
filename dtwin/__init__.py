"""dtwin: a differentiable digital twin of planetary gearboxes.

Importing dtwin turns on float64 in JAX and the persistent compilation cache
(:mod:`dtwin._config`). Public names are re-exported here.
"""

from . import _config  # noqa: F401  (float64 + compilation cache, before anything else)
from .errors import (
    ChannelError as ChannelError,
    DtwinError as DtwinError,
    FitError as FitError,
    GeometryError as GeometryError,
    OutputExistsError as OutputExistsError,
    ParameterError as ParameterError,
    RecordError as RecordError,
    SolverError as SolverError,
    SpecError as SpecError,
    UnreadableFileError as UnreadableFileError,
)
from .lumped import LumpedParameters as LumpedParameters
from .registry import REGISTRY as REGISTRY

__version__ = "0.1.0"
