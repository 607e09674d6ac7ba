"""A worker process that runs batches of a sweep, and the parent's handle on it.

The runs execute in a child process (``python -m pendulab.sweep.sandbox``) holding one
:class:`~pendulab.sweep.runner.BatchRunner`, so that a run that crashes its process (a fault in
native code) or hangs inside an FMU costs that run alone: :meth:`Sandbox.run_batch` records it
(``error`` for a crash, ``timeout`` for a hang), starts a new child and goes on with the rest of the
batch. Nothing else of the batch is lost or run twice. Both engines use it: the local engine holds one
per worker, a Dask worker one per thread.

The child and the parent speak pickles over the child's standard input and output: the parent sends
``("batch", spec, runs)``; the child answers ``("start", run_id)`` before each run, ``("row", row)``
after it, and ``("done",)`` at the end of the batch. Pipes and ``subprocess`` work alike on Windows.
"""

from __future__ import annotations

import os
import pickle
import queue
import subprocess
import sys
import threading
from typing import Any, Sequence

from pendulab.errors import UserError

#: Seconds a child may take beyond the run's own time budget before it is taken for hung and killed
#: (the run's budget is checked inside the run every simulated second; this catches a hang in C).
GRACE_S = 30.0
#: Seconds a new child may take to start (imports) and to answer its first batch.
STARTUP_S = 300.0
#: Children that die outside any run (at start-up) before the batch is given up.
MAX_RESTARTS = 3


class SweepWorkerError(UserError):
    """The worker processes cannot run (they die at start-up)."""


#: Fault injection for the tests of the crash and hang paths: ``"RUN_ID:crash,RUN_ID:hang"`` makes the
#: child die (SIGKILL-like, no clean-up) or block forever as it starts that run.
FAULTS_VARIABLE = "PENDULAB_SWEEP_FAULTS"


def _faults() -> dict[int, str]:
    text = os.environ.get(FAULTS_VARIABLE, "")
    return {int(k): v for k, _, v in (item.partition(":") for item in text.split(",") if item)}


def _child_main() -> int:
    """The child's loop: batches in, rows out, until its standard input closes."""
    import time

    import pendulab.simulation  # noqa: F401 - imported before the first run, not inside its time budget
    from pendulab.sweep.runner import BatchRunner

    faults = _faults()

    stdin = sys.stdin.buffer
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # whatever else prints (an FMU's log) goes to stderr, never into the protocol
    sys.stdout = sys.stderr

    def send(message: tuple) -> None:
        pickle.dump(message, out, protocol=pickle.HIGHEST_PROTOCOL)
        out.flush()

    with BatchRunner() as runner:
        while True:
            try:
                message = pickle.load(stdin)
            except (EOFError, OSError):
                return 0
            _, spec, runs = message
            try:
                for run in runs:
                    send(("start", run[0]))
                    if faults.get(run[0]) == "crash":
                        os._exit(137)
                    if faults.get(run[0]) == "hang":
                        parent = os.getppid()
                        while os.getppid() == parent:  # until the parent is gone (killed, or killed us)
                            time.sleep(0.1)
                        return 1
                    send(("row", runner.run(spec, *run)))
                send(("done",))
            except (BrokenPipeError, OSError):
                return 0


class Sandbox:
    """The parent's handle on one worker child process (started on first use, restarted after a crash)."""

    def __init__(self, stderr: Any = subprocess.DEVNULL, grace: float = GRACE_S) -> None:
        self.grace = grace
        self._proc: subprocess.Popen | None = None
        self._messages: queue.Queue = queue.Queue()
        self._stderr = stderr

    @property
    def pid(self) -> int | None:
        """The child's process id (None before the first batch)."""
        return self._proc.pid if self._proc is not None else None

    def _start(self) -> None:
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "pendulab.sweep.sandbox"], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._stderr
        )
        self._messages = queue.Queue()
        threading.Thread(target=_reader, args=(self._proc.stdout, self._messages), daemon=True).start()

    def close(self) -> None:
        """End the child (closing its input ends its loop; killed if it does not end)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            proc.stdin.close()  # type: ignore[union-attr]
            proc.wait(timeout=10)
        except (OSError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait()

    def _kill(self) -> None:
        proc, self._proc = self._proc, None
        if proc is not None:
            proc.kill()
            proc.wait()

    def run_batch(self, spec: Any, runs: Sequence[tuple[int, int, int, dict[str, Any]]]) -> list[dict[str, Any]]:
        """Every run of ``runs`` as a row, in order; a crash or a hang costs only the run it happened in."""
        from pendulab.sweep.runner import blank_row

        rows: list[dict[str, Any]] = []
        pending = list(runs)
        restarts = 0
        while pending:
            if self._proc is None or self._proc.poll() is not None:
                self._start()
            try:
                pickle.dump(("batch", spec, pending), self._proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)  # type: ignore[union-attr, arg-type]
                self._proc.stdin.flush()  # type: ignore[union-attr]
            except OSError:
                self._kill()
                restarts += 1
                if restarts > MAX_RESTARTS:
                    raise SweepWorkerError("the sweep's worker process dies as it starts; run 'python -m pendulab.sweep.sandbox' to see why") from None
                continue
            current: int | None = None
            while True:
                wait = spec.timeout + self.grace if current is not None else STARTUP_S
                try:
                    message = self._messages.get(timeout=wait)
                except queue.Empty:
                    message = "hung"
                if message is None or message == "hung":
                    code = self._proc.poll() if self._proc is not None else None
                    self._kill()
                    if current is None:
                        restarts += 1
                        if restarts > MAX_RESTARTS:
                            raise SweepWorkerError("the sweep's worker process dies outside any run; run 'python -m pendulab.sweep.sandbox' to see why")
                        pending = [r for r in pending if r[0] not in {row["run_id"] for row in rows}]
                        break
                    run = next(r for r in pending if r[0] == current)
                    if message == "hung":
                        rows.append(blank_row(spec, *run, "timeout", f"hung for over {wait:g} s; its worker process was killed", wait))
                    else:
                        rows.append(blank_row(spec, *run, "error", f"the run crashed its worker process (exit status {code})"))
                    done = {row["run_id"] for row in rows}
                    pending = [r for r in pending if r[0] not in done]
                    break
                if message[0] == "start":
                    current = message[1]
                elif message[0] == "row":
                    rows.append(message[1])
                    current = None
                elif message[0] == "done":
                    pending = []
                    break
        return rows


def _reader(stream: Any, messages: queue.Queue) -> None:
    try:
        while True:
            messages.put(pickle.load(stream))
    except Exception:  # noqa: BLE001 - EOF or a broken stream: the child is gone
        messages.put(None)


if __name__ == "__main__":
    raise SystemExit(_child_main())
