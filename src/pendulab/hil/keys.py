"""The operator's keys while the rig runs: single keys on a terminal, or lines on stdin when scripted.

POSIX terminals are read in cbreak mode with ``select``; Windows consoles through ``msvcrt``; a stdin
that is not a terminal (a pipe, a file, a test) is read line by line in a thread. Each gives the
same single-character keys (``s``, ``p``, ``e``, ``r``).
"""

from __future__ import annotations

import queue
import sys
import threading
from typing import Any


class KeySource:
    """Non-blocking key reader; use as a context manager (restores the terminal)."""

    def __init__(self, stream: Any = None) -> None:
        self.stream = stream if stream is not None else sys.stdin
        self._queue: "queue.Queue[str]" = queue.Queue()
        self._mode = "none"
        self._saved: Any = None
        self.closed = False  # stdin reached its end (scripted runs)

    def __enter__(self) -> "KeySource":
        stream = self.stream
        try:
            is_tty = stream is not None and stream.isatty()
        except (ValueError, AttributeError):
            is_tty = False
        if is_tty and sys.platform == "win32":
            self._mode = "msvcrt"
        elif is_tty:
            import termios
            import tty

            fd = stream.fileno()
            self._saved = termios.tcgetattr(fd)
            tty.setcbreak(fd)
            self._mode = "termios"
        elif stream is not None:
            self._mode = "lines"
            threading.Thread(target=self._read_lines, daemon=True).start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._mode == "termios" and self._saved is not None:
            import termios

            termios.tcsetattr(self.stream.fileno(), termios.TCSADRAIN, self._saved)

    def _read_lines(self) -> None:
        try:
            for line in self.stream:
                for key in line.strip().lower().split():
                    self._queue.put(key[:1])
        except (OSError, ValueError):
            pass
        self.closed = True

    def poll(self) -> list[str]:
        """Keys pressed since the last call (lower case)."""
        keys: list[str] = []
        if self._mode == "termios":
            import os
            import select

            fd = self.stream.fileno()
            while select.select([fd], [], [], 0)[0]:
                data = os.read(fd, 64)
                if not data:
                    break
                keys += [chr(b).lower() for b in data if chr(b).isalpha()]
        elif self._mode == "msvcrt":
            import msvcrt

            while msvcrt.kbhit():  # type: ignore[attr-defined]
                ch = msvcrt.getwch()  # type: ignore[attr-defined]
                if ch.isalpha():
                    keys.append(ch.lower())
        else:
            while True:
                try:
                    keys.append(self._queue.get_nowait())
                except queue.Empty:
                    break
        return keys
