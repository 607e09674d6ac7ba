"""Shared pytest fixtures: the FMUs, built once per session (only when missing or out of date).

On CI (``CI`` set, as ``.ci/run`` runs) nothing may be skipped: ``.ci/run`` installs every system
package the tests need (gcc-avr, simavr, chromium, mingw-w64, wine64, ...), so a test that would skip
for a missing tool fails there instead, loudly, with the reason it would have skipped for. On a
developer's machine without those packages the same tests skip.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

ON_CI = os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


def _fail_instead_of_skip(report) -> None:  # noqa: ANN001 - a pytest TestReport or CollectReport
    if ON_CI and report.skipped and not hasattr(report, "wasxfail") and sys.platform != "win32":
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        report.outcome = "failed"
        report.longrepr = f"would be skipped, but CI must run every test (.ci/run installs what it needs): {reason}"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):  # noqa: ANN001
    outcome = yield
    _fail_instead_of_skip(outcome.get_result())


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):  # noqa: ANN001
    outcome = yield
    _fail_instead_of_skip(outcome.get_result())


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
def plant3_fmu() -> Path:
    """Path of ``fmus/Plant3.fmu`` (the plant as an FMI 3.0 FMU), built first if missing or out of date."""
    from pendulab.fmu.build import ensure_fmu

    return ensure_fmu("Plant3")


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


@pytest.fixture(scope="session")
def seesaw_fmu() -> Path:
    """Path of ``fmus/Seesaw.fmu``, built first if it is missing or older than its sources."""
    from pendulab.fmu.build import ensure_fmu

    return ensure_fmu("Seesaw")
