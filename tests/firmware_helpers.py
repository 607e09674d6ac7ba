"""Test helpers: the rig firmware in its simavr twin, as a real process on a real pseudo-terminal."""

from __future__ import annotations

import contextlib
import json
from pathlib import Path
from typing import Iterator

import numpy as np
from hil_helpers import PortProcess


def twin_available() -> bool:
    import shutil

    return all(shutil.which(tool) for tool in ("avr-gcc", "make")) and Path("/usr/include/simavr/sim_avr.h").is_file()


class Twin(PortProcess):
    """The twin binary on the built firmware; stderr is collected while it runs."""

    name = "twin"

    def __init__(self, *args: str, trace: Path | None = None, profile: Path | None = None, params: dict | None = None,
                 plant: str = "pendulum") -> None:
        from pendulab.hil.firmware import build_firmware, build_twin
        from pendulab.model.parameters import PlantParameters
        from pendulab.model.seesaw import SeesawParameters

        hex_path, twin = build_firmware(), build_twin()
        p = (SeesawParameters() if plant == "seesaw" else PlantParameters.preset()).with_values(**(params or {}))
        command = [str(twin), str(hex_path), "--plant", plant, "--params", ",".join(repr(v) for v in p.as_vector()), *args]
        if trace is not None:
            command += ["--trace", str(trace)]
        if profile is not None:
            command += ["--profile", str(profile)]
        self.trace_path, self.profile_path = trace, profile
        super().__init__(command)

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
