"""The Ray engine of a fleet run: each task a Ray task, results written as they finish.

Ray is an optional extra (``dtwin[fleet]``): it is imported when the engine runs, not with the
package."""

from __future__ import annotations

from typing import Any

from dtwin.errors import DtwinError

from .identity import RecordJob
from .local_engine import _progress
from .plan import _Plan
from .store import _Writer
from .tasks import discover_task, failure_entry, fit_task


def ray_available() -> bool:
    """Whether Ray can be imported (the optional extra ``dtwin[fleet]``)."""
    try:
        import ray  # noqa: F401  (optional extra, imported only to test for it)
    except ImportError:
        return False
    return True


def _run_ray(pl: _Plan, spec_data, settings, fp, writer: _Writer, inject, attempts_dir,
             progress: bool, address: str | None, num_cpus: int | None, notes: list[str]) -> None:
    import ray

    started = False
    if not ray.is_initialized():
        kw: dict[str, Any] = dict(include_dashboard=False, log_to_driver=False,
                                  configure_logging=False)
        if address is not None:
            ray.init(address=address, **kw)
        else:
            ray.init(num_cpus=num_cpus, **kw)
        started = True
    notes.append(f"ray {ray.__version__}: {ray.cluster_resources().get('CPU', 0):g} CPUs"
                 + (f" at {address}" if address else " (local)"))
    opts = dict(num_cpus=1, max_retries=settings.max_retries, retry_exceptions=True)
    remote_fit = ray.remote(fit_task).options(**opts)
    remote_disc = ray.remote(discover_task).options(**opts)
    try:
        spec_ref = ray.put(dict(spec_data))
        pending: dict[Any, tuple[str, Any]] = {}
        for task in pl.fit_tasks:
            payload = [j.to_dict() for j in task]
            ref = remote_fit.remote(payload, spec_ref, settings, fingerprint=fp, engine="ray",
                                    inject=inject, attempts_dir=attempts_dir)
            pending[ref] = ("fit", task)

        def submit_discovery(job: RecordJob, entry: dict[str, Any]) -> None:
            ref = remote_disc.remote(job.to_dict(), spec_ref, settings, entry, fingerprint=fp,
                                     engine="ray", inject=inject, attempts_dir=attempts_dir)
            pending[ref] = ("discover", job)

        for job, entry in pl.discover_jobs:
            submit_discovery(job, entry)
        n_fit = sum(map(len, pl.fit_tasks))
        n_disc = len(pl.discover_jobs) + (n_fit if settings.discover else 0)
        with _progress(n_fit + n_disc, progress) as bar:
            tid = bar.add_task("fleet fits (ray)", total=n_fit)
            did = bar.add_task("discovery (ray)", total=n_disc, visible=settings.discover)
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1)
                for ref in done:
                    what, item = pending.pop(ref)
                    if what == "fit":
                        try:
                            entries = ray.get(ref)
                        except (ray.exceptions.RayError, DtwinError) as e:
                            entries = [failure_entry(j.to_dict(), _cause(e), stage="task",
                                                     fingerprint=fp,
                                                     attempts=settings.max_retries + 1)
                                       for j in item]
                        for job, entry in zip(item, entries, strict=True):
                            writer(entry)
                            if settings.discover and entry["status"] == "ok":
                                submit_discovery(job, entry)
                            elif settings.discover:
                                bar.advance(did)
                        bar.advance(tid, len(item))
                    else:
                        try:
                            entry = ray.get(ref)
                        except (ray.exceptions.RayError, DtwinError) as e:
                            entry = failure_entry(item.to_dict(), _cause(e), stage="discover",
                                                  fingerprint=fp, kind="discover",
                                                  attempts=settings.max_retries + 1)
                        writer(entry)
                        bar.advance(did)
    finally:
        if started:
            ray.shutdown()


def _cause(e: BaseException) -> BaseException:
    """The user exception inside a `RayTaskError`, else the error itself."""
    cause = getattr(e, "cause", None)
    return cause if isinstance(cause, BaseException) else e

