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

import os
import sys


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
