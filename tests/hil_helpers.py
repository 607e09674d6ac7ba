"""Test helpers: the rig emulator and ``pendulab lab`` as real processes on a real pseudo-terminal."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Iterator

PYTHON = sys.executable
ENV = {**os.environ, "MPLBACKEND": "Agg", "PYTHONUNBUFFERED": "1"}


class Emulator:
    """``pendulab rig-emulator`` in a subprocess; its stderr is collected while it runs."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen(
            [PYTHON, "-m", "pendulab", "rig-emulator", *args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV,
        )
        line = self.proc.stdout.readline().strip()  # type: ignore[union-attr]
        if not line:
            raise RuntimeError(f"the emulator printed no port: {self.proc.stderr.read()}")  # type: ignore[union-attr]
        self.port = line
        self.lines: list[str] = []
        self._thread = threading.Thread(target=self._collect, daemon=True)
        self._thread.start()

    def _collect(self) -> None:
        for line in self.proc.stderr:  # type: ignore[union-attr]
            self.lines.append(line.rstrip("\n"))

    @property
    def text(self) -> str:
        return "\n".join(self.lines)

    def wait_for(self, fragment: str, timeout: float = 10.0) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in list(self.lines):
                if fragment in line:
                    return line
            time.sleep(0.02)
        raise AssertionError(f"the emulator never said {fragment!r}; it said:\n{self.text}")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._thread.join(2)


@contextlib.contextmanager
def emulator(*args: str) -> Iterator[Emulator]:
    emu = Emulator(*args)
    try:
        yield emu
    finally:
        emu.stop()


def lab(*args: str, stdin: str | None = "", timeout: float = 60.0) -> subprocess.CompletedProcess:
    """``pendulab lab`` to completion, keys as stdin lines."""
    return subprocess.run([PYTHON, "-m", "pendulab", "lab", *args], input=stdin, capture_output=True, text=True,
                          timeout=timeout, env=ENV)


def lab_process(*args: str) -> subprocess.Popen:
    return subprocess.Popen([PYTHON, "-m", "pendulab", "lab", *args], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=ENV)


def read_log(path: Path):
    import numpy as np

    return np.genfromtxt(path, delimiter=",", names=True)
