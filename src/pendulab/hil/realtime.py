"""Best-effort real-time scheduling for the rig-clocked loops (lab host and rig emulator).

A 1 kHz loop answers each sample within a period; a process that the operating system leaves waiting
for a millisecond now and then (another program, a background service) makes late commands. Each loop
asks for a higher priority where the system allows it without special set-up, and says what it got:

* Linux: ``SCHED_FIFO`` at a low real-time priority (needs root or CAP_SYS_NICE), else ``nice -5``;
* Windows: ``HIGH_PRIORITY_CLASS`` (allowed for any user);
* elsewhere, or when refused: the normal priority.

The loops block on the serial port between samples, so a real-time priority never starves the machine.
"""

from __future__ import annotations

import contextlib
import gc
import os
import signal
import sys
import threading
from typing import Any, Iterator


def raise_priority() -> str:
    """Raise this process's scheduling priority as far as allowed; returns what it got, in words."""
    if sys.platform == "win32":
        try:
            import ctypes

            kernel32 = ctypes.windll.kernel32  # type: ignore[attr-defined]
            HIGH_PRIORITY_CLASS = 0x00000080
            if kernel32.SetPriorityClass(kernel32.GetCurrentProcess(), HIGH_PRIORITY_CLASS):
                return "high priority class"
        except (AttributeError, OSError):
            pass
        return "normal priority"
    if hasattr(os, "sched_setscheduler"):
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
            return "real-time scheduling (SCHED_FIFO 10)"
        except (PermissionError, OSError):
            pass
    try:
        os.nice(-5)
        return "nice -5"
    except (PermissionError, OSError, AttributeError):
        return "normal priority"


@contextlib.contextmanager
def no_garbage_collection() -> Iterator[None]:
    """No cyclic garbage collection inside the block (the real-time loops of lab, calibrate, the emulator).

    A full collection of everything the FMUs and libraries loaded takes milliseconds, more than a
    period, and a log held in lists makes it longer as the run goes on. What exists now is collected
    and frozen; the loops make no reference cycles (what they allocate is freed by reference counting).
    """
    gc.collect()
    gc.freeze()
    gc.disable()
    try:
        yield
    finally:
        gc.enable()
        gc.unfreeze()


class Terminated(KeyboardInterrupt):
    """The process was told to stop by a signal other than Ctrl-C (SIGTERM, SIGHUP); ``signal`` names it.

    A :class:`KeyboardInterrupt`, so every loop that ends cleanly on Ctrl-C (motor off, log kept,
    results written) ends the same way on it.
    """

    def __init__(self, signum: int) -> None:
        self.signum = signum
        self.signal = signal.Signals(signum).name
        super().__init__(f"stopped by {self.signal}")

    @property
    def exit_status(self) -> int:
        return 128 + self.signum


#: Signals that end a session as the end key does: a closed terminal (SIGHUP), 'timeout', a process manager.
ENDING_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP", "SIGBREAK") if hasattr(signal, name))


class EndingSignals:
    """While armed, SIGTERM and SIGHUP (SIGBREAK on Windows) raise :class:`Terminated` in the main thread.

    Disarmed (while results are written, and after the first signal), a signal is only remembered in
    ``received``, so that the files of a session that is ending are still written.

    Examples
    --------
    >>> import os, signal
    >>> # skipped: doctest lets a KeyboardInterrupt (Terminated is one) stop the whole test run
    >>> with EndingSignals() as ending:                                     # doctest: +SKIP
    ...     os.kill(os.getpid(), signal.SIGTERM)
    Traceback (most recent call last):
    pendulab.hil.realtime.Terminated: stopped by SIGTERM
    """

    def __init__(self) -> None:
        self.armed = True
        self.received: int | None = None
        self._previous: dict[int, Any] = {}

    def _handle(self, signum: int, frame: Any) -> None:
        self.received = signum
        if self.armed:
            # Raised once: a second signal (coreutils 'timeout' signals the child and then its whole
            # process group) must not interrupt the ending it started.
            self.armed = False
            raise Terminated(signum)

    def disarm(self) -> None:
        self.armed = False

    def __enter__(self) -> "EndingSignals":
        if threading.current_thread() is threading.main_thread():
            for signum in ENDING_SIGNALS:
                try:
                    self._previous[signum] = signal.signal(signum, self._handle)
                except (OSError, ValueError):
                    pass
        return self

    def __exit__(self, *exc: object) -> None:
        for signum, previous in self._previous.items():
            signal.signal(signum, previous)
        self._previous.clear()
