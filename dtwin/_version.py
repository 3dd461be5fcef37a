"""The installed distribution's version, read from its metadata (``pyproject.toml``)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__: str = version("dtwin")
except PackageNotFoundError:  # a source tree used without installing it
    __version__ = "0+unknown"
