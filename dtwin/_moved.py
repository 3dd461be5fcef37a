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

__all__ = ["MOVED", "install", "new_name", "register_imported"]

#: old dotted module path → new dotted module path (a package's submodules follow it)
MOVED: dict[str, str] = {
    "dtwin.address": "dtwin.model.address",
    "dtwin.build": "dtwin.spec.build",
    "dtwin.cepstrum": "dtwin.signal.cepstrum",
    "dtwin.coords": "dtwin.model.coords",
    "dtwin.coupling": "dtwin.report.drive_comparison",
    "dtwin.envelope": "dtwin.signal.envelope",
    "dtwin.faults": "dtwin.model.faults",
    "dtwin.gears": "dtwin.model.gears",
    "dtwin.identify.discover.candidates": "dtwin.identify.discover.coverage",
    "dtwin.identify.effects": "dtwin.identify.discover.effects",
    "dtwin.identify.split": "dtwin.identify.excitation_response",
    "dtwin.indicators": "dtwin.signal.indicators",
    "dtwin.integrator": "dtwin.simulation.integrator",
    "dtwin.io.html_report": "dtwin.report.html_report",
    "dtwin.kinematics": "dtwin.model.kinematics",
    "dtwin.lumped": "dtwin.model.lumped",
    "dtwin.memory": "dtwin.simulation.memory",
    "dtwin.modal": "dtwin.model.modal",
    "dtwin.motor_spec": "dtwin.spec.motor",
    "dtwin.order": "dtwin.signal.order",
    "dtwin.parts": "dtwin.model.parts",
    "dtwin.parts.drive": "dtwin.model.motor.drive",
    "dtwin.parts.drive_base": "dtwin.model.motor.drive_base",
    "dtwin.parts.induction_motor": "dtwin.model.motor.induction_motor",
    "dtwin.parts.loads": "dtwin.model.motor.loads",
    "dtwin.parts.pmsm": "dtwin.model.motor.pmsm",
    "dtwin.parts.shaft": "dtwin.model.motor.shaft",
    "dtwin.parts.speed_fluctuation": "dtwin.model.motor.speed_fluctuation",
    "dtwin.parts.speed_source": "dtwin.model.motor.speed_source",
    "dtwin.parts.torque_ripple": "dtwin.model.motor.torque_ripple",
    "dtwin.periodic": "dtwin.simulation.periodic",
    "dtwin.plotting.coupling": "dtwin.report.drive_comparison_figures",
    "dtwin.presets": "dtwin.spec.presets",
    "dtwin.psd": "dtwin.signal.psd",
    "dtwin.registry": "dtwin.model.registry",
    "dtwin.reports": "dtwin.report.analyses",
    "dtwin.sensor_response": "dtwin.simulation.sensor_response",
    "dtwin.simulate": "dtwin.simulation.simulate",
    "dtwin.spec_writer": "dtwin.spec.writer",
    "dtwin.spectrum": "dtwin.signal.spectrum",
    "dtwin.speed_range": "dtwin.simulation.speed_range",
    "dtwin.statics": "dtwin.model.statics",
    "dtwin.stiffness": "dtwin.model.stiffness",
    "dtwin.tsa": "dtwin.signal.tsa",
    "dtwin.twin": "dtwin.model.twin",
    "dtwin.units": "dtwin.signal.units",
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


def register_imported(*old: str) -> None:
    """Register old paths whose new module ``import dtwin`` has already imported, for names
    the package binds to something else: ``dtwin.simulate`` is the function, and importing the
    old module path through the finder would rebind that name to the module."""
    for name in old:
        sys.modules.setdefault(name, importlib.import_module(new_name(name)))


def install() -> None:
    """Put the finder first on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _MovedFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _MovedFinder())


install()
