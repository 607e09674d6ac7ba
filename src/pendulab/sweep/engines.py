"""Where the batches of a sweep run: local worker processes, or a Dask cluster.

Both engines hand out batches (lists of runs, about a second of work each) and give back each
batch's rows as it completes, in any order. Every worker process runs its batches through a
:class:`~pendulab.sweep.sandbox.Sandbox`, whose child holds the FMUs loaded once.

* :class:`LocalEngine`: ``N`` worker processes on this machine (default: one per core); no extra
  dependency.
* :class:`DaskEngine`: a Dask distributed cluster (``pip install pendulab[dask]``): a scheduler's
  address ``tcp://HOST:PORT``, or ``local:N`` for a ``LocalCluster`` of N single-threaded worker
  processes. When a worker dies, the scheduler gives its batches to another worker; a batch's rows
  reach the sweep once, from the one task that completed.

Examples
--------
>>> engine = make_engine(None, workers=2)
>>> engine.describe()
'2 local worker processes'
"""

from __future__ import annotations

import os
import queue
import threading
import uuid
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from typing import Any, Iterator, Sequence

from pendulab.errors import UserError

Batch = Sequence[tuple[int, int, int, dict[str, Any]]]


class LocalEngine:
    """``workers`` worker processes on this machine."""

    def __init__(self, workers: int | None = None) -> None:
        self.workers = max(1, int(workers or os.cpu_count() or 1))
        self._sandboxes: list[Any] = []

    def describe(self) -> str:
        return f"{self.workers} local worker process{'es' if self.workers > 1 else ''}"

    def close(self) -> None:
        for sandbox in self._sandboxes:
            sandbox.close()
        self._sandboxes.clear()

    def __enter__(self) -> "LocalEngine":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def map(self, spec: Any, batches: Sequence[Batch]) -> Iterator[list[dict[str, Any]]]:
        """The rows of each batch, as the batches complete."""
        from pendulab.sweep.sandbox import Sandbox

        free: queue.Queue = queue.Queue()
        for _ in range(min(self.workers, max(1, len(batches)))):
            sandbox = Sandbox()
            self._sandboxes.append(sandbox)
            free.put(sandbox)

        def task(batch: Batch) -> list[dict[str, Any]]:
            sandbox = free.get()
            try:
                return sandbox.run_batch(spec, batch)
            finally:
                free.put(sandbox)

        pool = ThreadPoolExecutor(max_workers=free.qsize(), thread_name_prefix="pendulab-sweep")
        try:
            pending = {pool.submit(task, batch) for batch in batches}
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    yield future.result()
        finally:
            pool.shutdown(wait=False, cancel_futures=True)
            self.close()  # ends the children, which ends a batch still running in a thread


class DaskEngine:
    """A Dask distributed cluster: ``tcp://HOST:PORT`` or ``local:N`` (a LocalCluster)."""

    def __init__(self, address: str) -> None:
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:
            raise UserError("--scheduler needs Dask: pip install 'pendulab[dask]'") from None
        self.address = address
        self._cluster = None
        if address.startswith("local:"):
            count = address.partition(":")[2]
            if not count.isdigit() or int(count) < 1:
                raise UserError(f"--scheduler {address!r}: give local:N with N >= 1 worker processes, e.g. local:2")
            self._cluster = LocalCluster(n_workers=int(count), threads_per_worker=1, processes=True, dashboard_address=None)
            self.client = Client(self._cluster)
        else:
            if "://" not in address:
                raise UserError(f"--scheduler {address!r}: give tcp://HOST:PORT or local:N")
            try:
                self.client = Client(address, timeout="15s")
            except (OSError, TimeoutError) as exc:
                raise UserError(f"--scheduler {address}: cannot reach the Dask scheduler ({' '.join(str(exc).split())[:160]}); start it with 'dask scheduler' or check the address") from None

    def describe(self) -> str:
        workers = len(self.client.scheduler_info().get("workers", {}))
        return f"Dask cluster {self.address} ({workers} worker{'s' if workers != 1 else ''})"

    def close(self) -> None:
        self.client.close()
        if self._cluster is not None:
            self._cluster.close()

    def __enter__(self) -> "DaskEngine":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def map(self, spec: Any, batches: Sequence[Batch]) -> Iterator[list[dict[str, Any]]]:
        """The rows of each batch, as the batches complete (a batch whose worker died runs elsewhere)."""
        from dask.distributed import as_completed

        tag = uuid.uuid4().hex[:8]
        futures = [
            self.client.submit(run_batch_task, spec, list(batch), key=f"pendulab-batch-{tag}-{batch[0][0]}", pure=False, retries=3)
            for batch in batches
        ]
        try:
            for future in as_completed(futures):
                yield future.result()
        finally:
            self.client.cancel(futures)


_LOCAL = threading.local()


def run_batch_task(spec: Any, batch: Batch) -> list[dict[str, Any]]:
    """A Dask task: run ``batch`` in this worker thread's own sandbox (FMUs loaded once per worker)."""
    from pendulab.sweep.sandbox import Sandbox

    sandbox = getattr(_LOCAL, "sandbox", None)
    if sandbox is None:
        sandbox = _LOCAL.sandbox = Sandbox()
    return sandbox.run_batch(spec, batch)


def make_engine(scheduler: str | None, workers: int | None = None) -> LocalEngine | DaskEngine:
    """The engine of ``--scheduler`` (None: local worker processes, ``workers`` of them)."""
    if workers is not None and workers < 1:
        raise UserError(f"--workers {workers} must be >= 1")
    if scheduler is None:
        return LocalEngine(workers)
    if workers is not None and not scheduler.startswith("local:"):
        raise UserError("--workers is for local worker processes; a Dask cluster has the workers its scheduler has")
    return DaskEngine(scheduler if workers is None else f"local:{workers}")
