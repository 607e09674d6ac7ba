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


class PortProcess:
    """A program that prints its port alone on its first stdout line and announces on stderr (collected)."""

    #: Who speaks, for messages.
    name = "process"

    def __init__(self, command: list[str], **popen: object) -> None:
        self.proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen)  # type: ignore[call-overload]
        line = self.proc.stdout.readline().strip()  # type: ignore[union-attr]
        if not line:
            raise RuntimeError(f"the {self.name} printed no port: {self.proc.stderr.read()}")  # type: ignore[union-attr]
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
        raise AssertionError(f"the {self.name} never said {fragment!r}; it said:\n{self.text}")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._thread.join(2)


class Emulator(PortProcess):
    """``pendulab rig-emulator`` in a subprocess."""

    name = "emulator"

    def __init__(self, *args: str) -> None:
        super().__init__([PYTHON, "-m", "pendulab", "rig-emulator", *args], env=ENV)


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


def angle_error_against_simulate(run: Path, poke: str, out: Path) -> tuple[int, float]:
    """``pendulab simulate --demo`` at the rig run's measured delay N and poke, 4 s, into ``out``; the
    angle's NRMSE between the two over 1 s after the poke. Returns ``(N, nrmse)``."""
    import json

    from pendulab.analysis.compare import load_compared, nrmse
    from pendulab.cli.main import main

    n = json.loads((run / "timing.json").read_text())["delay_periods"]
    assert main(["simulate", "--demo", "--delay", str(n), "--poke", poke, "--stop-time", "4", "--out", str(out)]) == 0
    return n, nrmse(load_compared(run), load_compared(out), "alpha", window=1.0)
