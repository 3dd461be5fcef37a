"""Execute the notebooks in a folder and write them as HTML with their outputs (``make notebooks``).

    python notebooks/render.py NOTEBOOKS_DIR OUT_DIR [--full] [--timeout S] [NAME ...]

Each ``*.ipynb`` in `NOTEBOOKS_DIR` (sorted; names starting with ``_`` are skipped; or only the
given NAMEs) is executed with nbclient in a fresh kernel of *this* interpreter (the kernel spec
``dtwin``, installed into ``sys.prefix`` on first use), working directory = the notebooks folder,
``MPLBACKEND=Agg``. ``--full`` injects ``FULL = True`` after the cell tagged ``parameters``
(paper-length records). The executed notebook is written as ``OUT_DIR/NAME.html`` (nbconvert's
HTML exporter, outputs embedded); a notebook that fails is still written, with the error in its
output, and the command exits with status 1 after trying all of them. The stored notebooks are
never modified (they are kept without outputs).

The tests (``tests/test_notebooks.py``) use :func:`execute_notebook` from here, so CI and
``make notebooks`` run the notebooks the same way.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

KERNEL_NAME = "dtwin"
#: Per-cell time limit (s); the notebooks' slowest cell simulates a few seconds of signal.
CELL_TIMEOUT = 900


def kernel_dir() -> Path:
    """The Jupyter data folder of this interpreter's prefix (where the kernel spec goes)."""
    return Path(sys.prefix) / "share" / "jupyter"


def _kernel_is_ours(spec: Path) -> bool:
    """Whether the kernel spec at `spec` runs this interpreter (same file after symlinks)."""
    import json

    try:
        argv0 = json.loads(spec.read_text(encoding="utf-8"))["argv"][0]
    except (OSError, ValueError, KeyError, IndexError):
        return False
    return Path(argv0).resolve() == Path(sys.executable).resolve()


def ensure_kernel() -> str:
    """Install the kernel spec ``dtwin`` (this interpreter) into ``sys.prefix`` if missing, and
    put that folder first on ``JUPYTER_PATH`` so no other ``dtwin`` kernel shadows it.

    **Returns:** the kernel name for nbclient.
    """
    spec = kernel_dir() / "kernels" / KERNEL_NAME / "kernel.json"
    if not _kernel_is_ours(spec):
        cmd = [sys.executable, "-m", "ipykernel", "install", "--prefix", sys.prefix,
               "--name", KERNEL_NAME, "--display-name", f"Python ({KERNEL_NAME})"]
        # a fresh `.venv` under load has failed this once, transiently (CI-like run, 2 cores
        # busy): retry, and accept a spec that another process wrote meanwhile
        for attempt in range(3):
            res = subprocess.run(cmd, capture_output=True, text=True)
            if res.returncode == 0 or _kernel_is_ours(spec):
                break
            time.sleep(1.0 + 2.0 * attempt)
        else:
            raise RuntimeError(
                f"could not install the Jupyter kernel {KERNEL_NAME!r} ({' '.join(cmd)}, exit "
                f"{res.returncode}): {(res.stderr or res.stdout)[-2000:]}; install ipykernel "
                "into this environment (`make venv`) and retry"
            )
    paths = [p for p in os.environ.get("JUPYTER_PATH", "").split(os.pathsep) if p]
    first = str(kernel_dir())
    if not paths or paths[0] != first:
        os.environ["JUPYTER_PATH"] = os.pathsep.join([first] + [p for p in paths if p != first])
    return KERNEL_NAME


def inject_full(nb) -> None:
    """Insert ``FULL = True`` after the cell tagged ``parameters`` (paper-length runs)."""
    import nbformat

    for i, cell in enumerate(nb.cells):
        if "parameters" in cell.get("metadata", {}).get("tags", []):
            new = nbformat.v4.new_code_cell("FULL = True  # injected by --full")
            new.metadata["tags"] = ["injected-parameters"]
            nb.cells.insert(i + 1, new)
            return
    raise ValueError("the notebook has no cell tagged 'parameters' to override")


def execute_notebook(path: Path, *, full: bool = False, timeout: int = CELL_TIMEOUT):
    """Execute the notebook at `path` in a fresh ``dtwin`` kernel (cwd = its folder).

    **Returns:** ``(nb, error)``: the executed notebook node and the
    ``nbclient.exceptions.CellExecutionError`` (or other exception) that stopped it, or None.
    """
    import nbformat
    from nbclient import NotebookClient

    os.environ.setdefault("MPLBACKEND", "Agg")
    os.environ.setdefault("JAX_ENABLE_X64", "1")
    path = Path(path)
    nb = nbformat.read(path, as_version=4)
    if full:
        inject_full(nb)
    client = NotebookClient(nb, timeout=timeout, kernel_name=ensure_kernel(),
                            resources={"metadata": {"path": str(path.parent.resolve())}})
    try:
        client.execute()
    except Exception as exc:  # noqa: BLE001  (reported to the caller, the notebook kept)
        return nb, exc
    return nb, None


def write_html(nb, out: Path) -> None:
    """Write an executed notebook as HTML (outputs embedded)."""
    from nbconvert import HTMLExporter

    body, _ = HTMLExporter().from_notebook_node(nb)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".html.tmp")
    tmp.write_text(body, encoding="utf-8")
    tmp.replace(out)


def notebook_paths(folder: Path, names: list[str] | None = None) -> list[Path]:
    """The notebooks of `folder` to run: all ``*.ipynb`` not starting with ``_`` (or `names`)."""
    paths = sorted(p for p in folder.glob("*.ipynb") if not p.name.startswith("_"))
    if names:
        wanted = {n.removesuffix(".ipynb") for n in names}
        paths = [p for p in paths if p.stem in wanted]
        missing = wanted - {p.stem for p in paths}
        if missing:
            raise SystemExit(f"no such notebook(s) in {folder}: {', '.join(sorted(missing))}")
    return paths


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("notebooks", type=Path, help="folder holding the *.ipynb files")
    ap.add_argument("out", type=Path, help="folder for the HTML files")
    ap.add_argument("names", nargs="*", help="only these notebooks (stem or file name)")
    ap.add_argument("--full", action="store_true", help="paper-length runs (FULL = True)")
    ap.add_argument("--timeout", type=int, default=CELL_TIMEOUT, help="per-cell limit (s)")
    args = ap.parse_args(argv)
    paths = notebook_paths(args.notebooks, args.names)
    if not paths:
        print(f"no notebooks in {args.notebooks}", file=sys.stderr)
        return 1
    failed = []
    for p in paths:
        t0 = time.time()
        print(f"[notebooks] {p.name} ...", flush=True)
        nb, err = execute_notebook(p, full=args.full, timeout=args.timeout)
        out = args.out / f"{p.stem}.html"
        write_html(nb, out)
        status = "ok" if err is None else f"FAILED ({type(err).__name__})"
        print(f"[notebooks] {p.name}: {status} in {time.time() - t0:.0f} s -> {out}", flush=True)
        if err is not None:
            failed.append(p.name)
            print(str(err)[-3000:], file=sys.stderr)
    if failed:
        print(f"[notebooks] failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
