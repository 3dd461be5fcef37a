"""Data in and out: records, spec files, result folders (see the submodules)."""

from .output import OutputFolder as OutputFolder
from .output import atomic_write_bytes as atomic_write_bytes
from .output import sha256_file as sha256_file
from .record import Record as Record
