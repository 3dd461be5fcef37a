"""The typer application shared by every command module of the CLI.

Each command lives in its own module ``dtwin/cli/cmd_<name>.py`` that imports :data:`app` and
decorates its function with ``@app.command()`` (or adds a sub-app with ``app.add_typer``).
:func:`dtwin.cli.main` imports every such module, so a new command needs no edit elsewhere.
Commands that need :mod:`dtwin.identify` import it inside the function (the twin never depends on the
identification package).

CLI convention (every command): a readable table on the terminal; ``--json`` prints the results
as JSON on stdout (nothing else on stdout); ``--out DIR`` writes result files (JSON, PNG and a
manifest) atomically into DIR, see :mod:`dtwin.io.output`.
"""

from __future__ import annotations

import typer

app = typer.Typer(
    name="dtwin",
    help="dtwin: a differentiable digital twin of planetary gearboxes.",
    epilog="Compiled programs are kept in ~/.cache/dtwin/jax ($XDG_CACHE_HOME/dtwin/jax), so a "
           "second command does not compile again; DTWIN_JAX_CACHE=FOLDER keeps them elsewhere, "
           "DTWIN_JAX_CACHE=off not at all.",
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _version(value: bool) -> None:
    if value:
        from .._version import __version__

        typer.echo(f"dtwin {__version__}")
        raise typer.Exit()


@app.callback()
def _global_options(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="Print dtwin's version and exit."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Errors only: no warnings, notes "
                               "or progress on stderr (before the command: dtwin -q COMMAND)."),
) -> None:
    """dtwin: a differentiable digital twin of planetary gearboxes."""
    from .logs import set_quiet

    set_quiet(quiet)
