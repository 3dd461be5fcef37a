"""dtwin: a differentiable digital twin of planetary gearboxes.

Importing dtwin turns on float64 in JAX and the persistent compilation cache
(:mod:`dtwin._config`). Public names are re-exported here.
"""

from . import _config  # noqa: F401  (float64 + compilation cache, before anything else)
from .errors import (
    ChannelError as ChannelError,
)
from .errors import (
    DtwinError as DtwinError,
)
from .errors import (
    FitError as FitError,
)
from .errors import (
    GeometryError as GeometryError,
)
from .errors import (
    OutputExistsError as OutputExistsError,
)
from .errors import (
    ParameterError as ParameterError,
)
from .errors import (
    RecordError as RecordError,
)
from .errors import (
    SolverError as SolverError,
)
from .errors import (
    SpecError as SpecError,
)
from .errors import (
    UnreadableFileError as UnreadableFileError,
)
from .lumped import LumpedParameters as LumpedParameters
from .registry import REGISTRY as REGISTRY

__version__ = "0.1.0"
