"""Test helpers: the rig firmware in its simavr twin, as a real process on a real pseudo-terminal."""

from __future__ import annotations

import contextlib
import json
import subprocess
import threading
import time
from pathlib import Path
from typing import Iterator

import numpy as np


def twin_available() -> bool:
    import shutil

    return all(shutil.which(tool) for tool in ("avr-gcc", "make")) and Path("/usr/include/simavr/sim_avr.h").is_file()


class Twin:
    """The twin binary on the built firmware; stderr is collected while it runs."""

    def __init__(self, *args: str, trace: Path | None = None, profile: Path | None = None, params: dict | None = None) -> None:
        from pendulab.hil.firmware import build_firmware, build_twin
        from pendulab.model.parameters import PlantParameters

        hex_path, twin = build_firmware(), build_twin()
        p = PlantParameters.preset().with_values(**(params or {}))
        command = [str(twin), str(hex_path), "--params", ",".join(repr(v) for v in p.as_vector()), *args]
        if trace is not None:
            command += ["--trace", str(trace)]
        if profile is not None:
            command += ["--profile", str(profile)]
        self.trace_path, self.profile_path = trace, profile
        self.proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.port = self.proc.stdout.readline().strip()  # type: ignore[union-attr]
        if not self.port:
            raise RuntimeError(f"the twin printed no port: {self.proc.stderr.read()}")  # type: ignore[union-attr]
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
        raise AssertionError(f"the twin never said {fragment!r}; it said:\n{self.text}")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._thread.join(2)

    def events(self) -> dict[str, np.ndarray]:
        """The trace after the twin ended: rows per kind (tick, volt, rx, tx, reset), cycles first."""
        rows: dict[str, list[list[float]]] = {}
        for line in self.trace_path.read_text().splitlines():  # type: ignore[union-attr]
            kind, *values = line.split(",")
            rows.setdefault(kind, []).append([float(v) for v in values])
        return {k: np.asarray(v) for k, v in rows.items()}

    def profile(self) -> dict:
        return json.loads(self.profile_path.read_text())  # type: ignore[union-attr]


@contextlib.contextmanager
def twin(*args: str, **kwargs) -> Iterator[Twin]:
    t = Twin(*args, **kwargs)
    try:
        yield t
    finally:
        t.stop()
