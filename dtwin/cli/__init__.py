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
    except Exception as e:  # click's usage errors are handled by typer; keep others visible
        import click

        if isinstance(e, click.exceptions.ClickException):
            e.show()
            raise SystemExit(e.exit_code) from None
        if isinstance(e, click.exceptions.Abort):
            raise SystemExit(1) from None
        raise


__all__ = ["app", "main"]
