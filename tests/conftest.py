"""Shared pytest fixtures: the FMUs, built once per session (only when missing or out of date)."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def plant_fmu() -> Path:
    """Path of ``fmus/Plant.fmu``, built first if it is missing or older than its sources."""
    from pendulab.fmu.build import ensure_fmu

    return ensure_fmu("Plant")


@pytest.fixture(scope="session")
def plant_unzipdir(plant_fmu: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``Plant.fmu`` extracted once per session (for tests that load the binary many times)."""
    from fmpy import extract

    return Path(extract(str(plant_fmu), unzipdir=str(tmp_path_factory.mktemp("Plant"))))


@pytest.fixture(scope="session")
def controller_fmu() -> Path:
    """Path of ``fmus/Controller.fmu``, built first if it is missing or older than its sources."""
    from pendulab.fmu.build import ensure_fmu

    return ensure_fmu("Controller")


@pytest.fixture(scope="session")
def supervisor_fmu() -> Path:
    """Path of ``fmus/Supervisor.fmu``, built first if it is missing or older than its sources."""
    from pendulab.fmu.build import ensure_fmu

    return ensure_fmu("Supervisor")


@pytest.fixture(scope="session")
def loop_fmus(plant_fmu: Path, controller_fmu: Path, supervisor_fmu: Path) -> dict[str, Path]:
    """The three FMUs of the lab's loop (built once), by component name."""
    return {"plant": plant_fmu, "controller": controller_fmu, "supervisor": supervisor_fmu}
