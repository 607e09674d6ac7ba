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

# Each test process (pytest-xdist runs one per core) runs the fit's compiled replays on one thread: two
# processes with two OpenMP threads each would take the core that the real-time link's process needs
# (a fit beside `calibrate --port` made the rig's answers late). libgomp reads this when it first loads.
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ.setdefault("OMP_NUM_THREADS", "1")


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


#: Test files that run a real-time link (the emulator or the firmware twin at 1 kHz over a pseudo-terminal):
#: a host that is busy for 20 ms (another process, the disk) trips the rig's watchdog or makes a frame late,
#: which these tests rightly count as a failure. Such a test runs up to twice more before it fails; a real
#: fault fails all three times (each run checks the same bounds).
REALTIME_FILES = frozenset({
    "test_hil_lab.py", "test_hil_lab_modes.py", "test_hil_bad_input.py", "test_hil_calibrate.py", "test_hil_endings.py",
    "test_hil_seesaw.py", "test_encoder_faults.py", "test_firmware.py", "test_firmware_lab.py", "test_readme_ta.py",
})


#: Test files that share the session's ``ramp_test_fit`` (a fit of about a minute): one process runs them all,
#: so that the fit is made once.
RAMP_FIT_FILES = frozenset({"test_fit.py", "test_fit_checks.py"})


#: The order in which pytest-xdist hands out its work units (a file, or a group above), as the collection gives them:
#: the real-time group first (300 s on 2 cores, one test after the other) beside the short files, then the minute-long
#: fits, longest first (test_fit_shapes 210 s, the ramp fit's group 170, test_fit_corpus 150, test_calibration_cli 73,
#: test_fit_valleys 40: its replays beside the real-time group made `calibrate --port` fail all three times).
#: A fit beside a real-time test makes the rig's answers late: with the fits first, `calibrate --port` failed all three
#: times (45 of 1000 answers late). xdist's own order, by the number of tests, put test_calibration_cli's fit early.
FIRST = ("realtime",)
#: Every file that fits is one of them: test_fit_reproducible's replays on two OpenMP threads and test_fit_global's fits, left
#: to run beside the real-time group, made the emulator's seesaw lose its link in all three sessions of a CI run (and the lab's
#: demo session twice in another).
LAST = ("test_fit_shapes.py", "ramp_test_fit", "test_fit_global.py", "test_fit_reproducible.py", "test_fit_corpus.py", "test_calibration_cli.py",
        "test_fit_valleys.py", "test_fit_pieces.py", "test_fit_win64.py", "test_fit_ranges.py", "test_fit_regimes.py", "test_fit_scans.py",
        "test_fit_start.py", "test_fit_observer.py", "test_fit_replay.py", "test_old_lab_logs.py", *(
            # and what makes the kernel busy (compilers, Wine, a browser, pip, Dask's processes, Sphinx): this kernel does not preempt
            # its own work (PREEMPT_NONE), so a real-time process waited for it while they ran beside (145 of 1000 answers late).
            "test_native.py", "test_simd.py", "test_fmu_build.py", "test_fmi3_plant.py", "test_readme_fmi.py", "test_docs_command.py",
            "test_fmu_win64.py", "test_gui_browser.py", "test_fmu_metadata.py", "test_wheel.py", "test_sweep.py"))


def work_unit(path: Path) -> str:
    """The pytest-xdist work unit (scope) of a test file: a group's name, or the file's own name."""
    return "realtime" if path.name in REALTIME_FILES else "ramp_test_fit" if path.name in RAMP_FIT_FILES else path.name


#: Niceness of a test process while it runs anything but the real-time group: the rig's emulator and the host answer
#: every millisecond and must win the CPU the moment they wake; a compile, a browser or a fit beside them at the same
#: priority made `calibrate --port` and the USB-bridge example fail on a loaded 2-core CI machine (9 of 1000 answers
#: late even at N = 8). Only under contention does it change anything.
NICE_BESIDE_REALTIME = 10


class _RealTimeFirst:
    """The real-time group runs with the machine to itself as far as the heavy files go: its process holds an exclusive
    lock from its first real-time test to its last, and each LAST unit (the fits, and the files that keep the kernel
    busy) takes the lock shared, so it waits until the real-time group is done (on a fast machine the short files keep
    the other process busy until then, and nothing waits). ``flock`` locks are dropped by the kernel when a process dies;
    a unit waits at most :attr:`LONGEST_WAIT` seconds in any case."""

    LONGEST_WAIT = 1200.0

    def __init__(self, path: Path) -> None:
        self.path = path
        self.fd: int | None = None
        self.exclusive = False
        self.niced = False

    def _lock(self, mode: int) -> None:
        import fcntl
        import time

        self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        deadline = time.monotonic() + self.LONGEST_WAIT
        while True:
            try:
                fcntl.flock(self.fd, mode | fcntl.LOCK_NB)
                return
            except BlockingIOError:
                if time.monotonic() > deadline:
                    return  # go on unlocked rather than hang CI: the real-time tests' reruns still stand
                time.sleep(0.5)

    def _unlock(self) -> None:
        if self.fd is not None:
            os.close(self.fd)  # drops the flock
            self.fd, self.exclusive = None, False

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(self, item, nextitem):  # noqa: ANN001
        import fcntl

        unit = work_unit(item.path)
        if unit == "realtime":
            if not self.exclusive:
                self._lock(fcntl.LOCK_EX)
                self.exclusive = True
        else:
            if not self.niced:
                os.nice(NICE_BESIDE_REALTIME)
                self.niced = True
            if unit in LAST:
                self._lock(fcntl.LOCK_SH)
        yield
        if unit != "realtime" or nextitem is None or work_unit(nextitem.path) != "realtime":
            self._unlock()

    def pytest_unconfigure(self, config):  # noqa: ANN001 - the file stays: the controller, which named it, removes it
        self._unlock()


#: The lock file of :class:`_RealTimeFirst`: named by pytest-xdist's controller, which hands it to its processes
#: (:func:`pytest_configure_node`) and removes it when the whole run ends, not when the first of them ends.
_LOCK_FILE = pytest.StashKey[Path]()


def pytest_configure(config):  # noqa: ANN001
    workerinput = getattr(config, "workerinput", None)
    if workerinput is None:
        import tempfile

        config.stash[_LOCK_FILE] = Path(tempfile.gettempdir()) / f"pendulab-tests-{os.getpid()}.lock"
    elif "pendulab_lock" in workerinput and sys.platform != "win32":  # pytest-xdist's processes; no real-time tests on Windows
        config.pluginmanager.register(_RealTimeFirst(Path(workerinput["pendulab_lock"])), "pendulab-realtime-first")


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node):  # noqa: ANN001 - pytest-xdist's controller, for each process it starts
    node.workerinput["pendulab_lock"] = str(node.config.stash[_LOCK_FILE])


def pytest_unconfigure(config):  # noqa: ANN001
    if getattr(config, "workerinput", None) is None and _LOCK_FILE in config.stash:
        config.stash[_LOCK_FILE].unlink(missing_ok=True)


def pytest_collection_modifyitems(config, items):  # noqa: ANN001
    for item in items:
        if item.path.name in REALTIME_FILES:
            item.add_marker(pytest.mark.flaky(reruns=2, reruns_delay=1))
    rank = {**{unit: -len(FIRST) + k for k, unit in enumerate(FIRST)}, **{unit: 1 + k for k, unit in enumerate(LAST)}}
    items.sort(key=lambda item: rank.get(work_unit(item.path), 0))  # stable: within a rank, the collection's order


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):  # noqa: ANN001
    """pytest-xdist (``-n auto`` in pyproject.toml): a file's tests run in one process, which builds the file's
    module fixtures once; the real-time files all run in one process, one after the other, so that no two
    real-time links share the machine; the files that share the ramp test's fit run in one process. (Its own
    ``--dist loadgroup`` marks do not take with pytest 9.)"""
    from xdist.scheduler import LoadScopeScheduling

    class ByFileRealTimeTogether(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            file = nodeid.split("::", 1)[0]
            unit = work_unit(Path(file))
            return unit if unit != Path(file).name else file

    config.option.loadscopereorder = False  # the collection's order (FIRST, the rest, LAST), not the number of tests
    return ByFileRealTimeTogether(config, log)


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


@pytest.fixture(scope="session")
def seesaw3_fmu() -> Path:
    """Path of ``fmus/Seesaw3.fmu`` (the seesaw as an FMI 3.0 FMU), built first if missing or out of date."""
    from pendulab.fmu.build import ensure_fmu

    return ensure_fmu("Seesaw3")


@pytest.fixture(scope="session")
def ramp_test_fit(tmp_path_factory: pytest.TempPathFactory):
    """The calibrate ramp test's log of the test rig (one iteration, 10 um of position noise) as a CSV file,
    and the Python API's fit of it: ``(log, path, result)``. A fit takes tens of seconds, so the fit's test
    files share this one (the command line's fit of the same log must give the same answer: test_fit_checks)."""
    from pendulab.calibration.fit import fit_parameters
    from pendulab.calibration.logs import write_log
    from pendulab.calibration.synthetic import TEST_RIG, calibrate_ramp_log
    from pendulab.model.parameters import PlantParameters

    log = calibrate_ramp_log(TEST_RIG, iterations=1, noise=1e-5, seed=3)
    path = write_log(log, tmp_path_factory.mktemp("ramp_test") / "ramp.csv")
    return log, path, fit_parameters([log], PlantParameters.preset("none"))  # from the lab defaults and the log's ramps
