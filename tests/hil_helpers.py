"""Test helpers: the rig emulator and ``pendulab lab`` as real processes on a real pseudo-terminal."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Callable, Iterator, TypeVar

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


T = TypeVar("T")


def until_the_link_holds(session: Callable[[int], T], lost: Callable[[T], str | None], attempts: int = 3) -> T:
    """``session(attempt)`` run again while ``lost(result)`` says (a line) that this machine's load, not pendulab, ended it: on a
    loaded host a 1 kHz link over a pseudo-terminal can be lost (the lab then ends, motor off, log kept, as on a rig). Each
    loss is printed; the last result is returned for the test to judge, so a fault that is not the host's fails at once.

    In a module's fixture the retries must be here: pytest's reruns of a test would look at the same session again.
    """
    for attempt in range(attempts):
        result = session(attempt)
        why = lost(result)
        if why is None:
            break
        print(f"the host was too slow for the link (machine load), attempt {attempt + 1} of {attempts}: {why}")
    return result


def ended_by(text: str, reasons: tuple[str, ...]) -> bool:
    """Whether a session's output names one of ``reasons`` (a test's words for a link lost to the host's load)."""
    return any(why in text for why in reasons)


def last_line(text: str) -> str:
    lines = text.strip().splitlines()
    return lines[-1] if lines else ""


def read_log(path: Path):
    import numpy as np

    return np.genfromtxt(path, delimiter=",", names=True)


def angle_error_against_simulate(run: Path, poke: str, out: Path, *, plant: str = "pendulum", window: float = 1.0) -> tuple[int, float]:
    """``pendulab simulate [--plant seesaw] --demo`` at the rig run's measured delay N and poke (the seesaw's tap), 4 s,
    into ``out``; the angle's (the seesaw's tilt's) NRMSE between the two over ``window`` s after the poke, both aligned
    at their poke as ``pendulab compare`` aligns them. Returns ``(N, nrmse)``."""
    import json

    from pendulab.analysis.compare import load_compared, nrmse
    from pendulab.cli.main import main

    n = json.loads((run / "timing.json").read_text())["delay_periods"]
    assert main(["simulate", "--plant", plant, "--demo", "--delay", str(n), "--poke", poke, "--stop-time", "4", "--out", str(out)]) == 0
    return n, nrmse(load_compared(run), load_compared(out), window=window)


#: The seesaw's tap in the rig tests (rad/s^2, s, s after the hand lets go): about 5 degrees of tilt under Quanser's LQR.
SEESAW_TAP = "3.3,0.1,1"
#: The seesaw's tilt encoder step: 4096 counts per turn behind the 3:1 gear.
SEESAW_COUNT = 2 * 3.141592653589793 / 4096 / 3


def check_seesaw_held(out: Path, stop: float) -> dict:
    """The checks of a ``lab --plant seesaw --demo`` session of ``stop`` s with the tap: held level with no trip for
    10 s, the tap's peak and the return near level, the cart inside the supervisor's limit, every sample in the log,
    the tilt in steps of the geared encoder. Returns the figures (printed by the caller)."""
    import json

    import numpy as np

    log = read_log(out / "rig_log.csv")
    running = log["supervisor_state"] == 2
    assert not (log["supervisor_state"] == 4).any(), "the supervisor tripped"
    assert log["t"][running][-1] - log["t"][running][0] >= 10.0
    assert np.all(np.diff(log["tick"]) == 1)
    # The tilt: the tap's peak (5.1 deg simulated), then back near level; the cart within the supervisor's 0.35 m.
    tilt = np.degrees(np.abs(log["theta"]))
    assert 2.5 < tilt.max() < 8.0
    metrics = json.loads((out / "metrics.json").read_text())
    tap = metrics["poke_start_detected_s"]
    assert tap is not None and 0.95 < tap - metrics["hand_release_s"] < 1.2
    # The lab judges the session as a seesaw (the verdict's words and numbers, as simulate's).
    assert metrics["verdict"]["plant"] == "seesaw" and metrics["verdict"]["headline"].startswith("HELD LEVEL for ")
    assert metrics["tilt_settling_time_s"] is not None and metrics["tilt_settling_time_s"] < 3.0
    after = float(tilt[log["t"] > tap + 3.0].max())
    assert after < 1.0
    assert np.abs(log["x"]).max() < 0.3
    steps = np.unique(np.round(np.abs(np.diff(log["theta"])) / SEESAW_COUNT, 6))
    assert set(steps) <= {0.0, 1.0, 2.0, 3.0}, steps
    return {"peak_deg": float(tilt.max()), "after_3s_deg": after, "max_abs_x_m": float(np.abs(log["x"]).max())}
