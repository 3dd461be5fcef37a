"""Command-line interface: ``dtwin COMMAND ...`` (see :mod:`dtwin.cli.app`)."""

from __future__ import annotations

import importlib
import pkgutil
import sys

from .app import app


def _load_commands() -> None:
    for mod in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if mod.name.startswith("cmd_"):
            importlib.import_module(f"{__name__}.{mod.name}")


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``dtwin`` console script."""
    from ..errors import DtwinError

    _load_commands()
    try:
        app(args=argv, standalone_mode=False)
    except DtwinError as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    except SystemExit:
        raise
    except Exception as e:  # usage errors (click's, bundled in typer) print their message
        show = getattr(e, "show", None)
        code = getattr(e, "exit_code", None)
        if callable(show) and isinstance(code, int):
            show()
            raise SystemExit(code) from None
        if type(e).__name__ == "Abort":
            raise SystemExit(1) from None
        raise


__all__ = ["app", "main"]
