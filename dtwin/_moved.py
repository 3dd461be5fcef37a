"""Old import paths of modules that moved, kept working.

When a module moves (``dtwin.simulate`` into a room of its role, say), scripts that import it
by its old path must keep running. :data:`MOVED` maps each old dotted path to the new one; the
finder installed by :func:`install` (when this module is imported, at ``import dtwin``) answers an import of an old path, or
of anything below it, with **the same module object** as the new path, so classes, ``isinstance``
checks and monkeypatching agree whichever path a script uses. Nothing is imported until a
script asks for an old path. ``docs/changelog.md`` lists what moved.
"""

import importlib
import importlib.abc
import importlib.machinery
import sys

__all__ = ["MOVED", "install", "new_name"]

#: old dotted module path → new dotted module path (a package's submodules follow it)
MOVED: dict[str, str] = {
    "dtwin.identify.discover.candidates": "dtwin.identify.discover.coverage",
    "dtwin.identify.effects": "dtwin.identify.discover.effects",
    "dtwin.identify.split": "dtwin.identify.excitation_response",
}


def new_name(name: str) -> str | None:
    """The new path of `name` if it, or a package above it, moved; else None."""
    head = name
    while head:
        if head in MOVED:
            return MOVED[head] + name[len(head):]
        head = head.rpartition(".")[0]
    return None


class _AliasLoader(importlib.abc.Loader):
    """Loads an old path as the module already imported under its new path."""

    def __init__(self, target: str):
        self.target = target
        self._spec = None

    def create_module(self, spec):
        module = importlib.import_module(self.target)
        self._spec = module.__spec__
        return module

    def exec_module(self, module):
        # the import system has just set the alias's spec on the shared module: give it back
        # its own, so reload and introspection see the module's real name and file
        module.__spec__ = self._spec


class _MovedFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path=None, target=None):
        new = new_name(fullname)
        if new is None or new == fullname:
            return None
        return importlib.machinery.ModuleSpec(fullname, _AliasLoader(new))


def install() -> None:
    """Put the finder first on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _MovedFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _MovedFinder())


install()
