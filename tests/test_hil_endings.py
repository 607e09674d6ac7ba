"""Every ending of ``calibrate --port`` and ``lab`` keeps what was measured; SIGTERM ends them as the end key
does; ``rig-emulator`` stops on SIGTERM in every state. Against ``pendulab rig-emulator`` on a real pty."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from hil_helpers import ENV, PYTHON, emulator, lab_process, read_log

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX")

#: The rig's friction (not the lab's default), for a cart without the pendulum.
FRICTION = "2,0.004,3.5,0.04,25"
#: Fixed delay: no measurement (a second per N tried) and the same timing in every run.
DELAY = "3"


def _calibrate(port: str, tmp_path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen(
        [PYTHON, "-m", "pendulab", "calibrate", "--port", port, "--delay", DELAY, "--iterations", "3", "--pendulum", "none",
         "--out", str(tmp_path / "c.json"), *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV,
    )


def _on_a_steady_host(scenario, tries: int = 2):
    """``scenario()`` -> (stdout, ...), again if the rig's watchdog ended it first.

    The emulator and calibrate share this machine's two cores with whatever else runs; on a loaded host
    the real-time link can be lost (the watchdog trips) before the event under test. That is printed and
    the scenario runs again; the test fails if every try is cut so.
    """
    for _ in range(tries):
        result = scenario()
        if "watchdog tripped" not in result[0]:
            return result
        print(f"the rig's watchdog ended the run before the event under test; trying again:\n{result[0][-400:]}")
    raise AssertionError(f"the watchdog ended all {tries} runs before the event under test")


def _rig_time(emu, fragment: str) -> float:
    """The emulator's clock (s) on its last line holding ``fragment``."""
    line = [line for line in emu.lines if fragment in line][-1]
    return float(re.match(r"\[rig\s+([0-9.]+) s\]", line).group(1))


def _event_tick(emu, fragment: str) -> float:
    """The event's tick counted from the start of the ramp test's stream (the rig's last 'streaming samples' before it)."""
    event = _rig_time(emu, fragment)
    starts = [float(re.match(r"\[rig\s+([0-9.]+) s\]", line).group(1)) for line in emu.lines if "streaming samples" in line]
    start = max(s for s in starts if s <= event)
    return (event - start) * 1000.0


class ScriptedLink:
    """A rig link that plays samples (cart creeping one count each) and then an ending: a status flag on the last
    sample, silence with a cause, or a tick that goes back."""

    def __init__(self, samples: int, *, status: int = 0, silence: Exception | None = None, tick_back: bool = False,
                 read_error: Exception | None = None) -> None:
        from pendulab.hil import protocol as P

        self.P = P
        self.identity = P.Identity(0, boot_id=1)
        self.name, self.delay = "scripted", 1
        self.samples, self.status, self.silence, self.tick_back = samples, status, silence, tick_back
        self.read_error = read_error
        self.k = 0
        self.motor_offs = 0

    def next_sample(self, timeout: float):
        k, P = self.k, self.P
        self.k += 1
        if k < self.samples:
            return P.Sample(k & 0xFFFF, tick=100 + k, cart=k // 10, voltage_mv=500), 0.0
        if self.read_error is not None:
            raise self.read_error
        if self.silence is not None:
            return None
        tick = 50 if self.tick_back else 100 + k
        return P.Sample(k & 0xFFFF, tick=tick, cart=k // 10, voltage_mv=500, status=self.status), 0.0

    def silence_cause(self, silent_ms: float) -> Exception:
        return self.silence  # type: ignore[return-value]

    def command(self, *args, **kwargs) -> None:
        pass

    def stream(self, on: bool) -> None:
        pass

    def motor_off(self, answers: int = 0) -> None:
        self.motor_offs += 1


@pytest.mark.parametrize("ending, words", [
    ({"status": 0x08}, "the rig reports a fault"),        # P.ST_FAULT
    ({"status": 0x02}, "the rig's watchdog tripped"),     # P.ST_WATCHDOG
    ({"silence": "restart"}, "the rig restarted (boot id 0x00000001 -> 0x00000002)"),
    ({"tick_back": True}, "the rig restarted (its tick went back"),
    ({"silence": "lost"}, "link lost"),
    ({"read_error": "closed"}, "link lost: reading from scripted failed"),  # the port closed (it was a traceback)
])
def test_every_rig_ending_keeps_the_streamed_log_to_its_last_sample(tmp_path, ending, words):
    from pendulab.analysis.results import RunLog
    from pendulab.calibration.ramp import run_ramp_test
    from pendulab.hil import protocol as P
    from pendulab.hil.link import LinkLost, RigRestarted
    from pendulab.hil.rig import LOG_COLUMNS, HilRig

    assert (P.ST_FAULT, P.ST_WATCHDOG) == (0x08, 0x02)
    silence = {"restart": RigRestarted("the rig restarted (boot id 0x00000001 -> 0x00000002)"),
               "lost": LinkLost("link lost: no data from the rig for 550 ms")}.get(ending.pop("silence", None))
    read_error = LinkLost("link lost: reading from scripted failed (read failed: [Errno 5] Input/output error)") if ending.pop("read_error", None) else None
    link = ScriptedLink(400, silence=silence, read_error=read_error, **ending)
    log_file = tmp_path / "log.csv"
    stream = RunLog(log_file, LOG_COLUMNS, flush_every=10)
    with HilRig(link, log=stream) as rig:  # type: ignore[arg-type]
        log = run_ramp_test(rig, iterations=2)
    stream.close()
    assert log.interrupted and words in log.end_reason and log.iterations_done == 0, log.end_reason
    assert "link lost" not in log.end_reason or words.startswith("link lost")
    kept = read_log(log_file)
    # Every sample that arrived is in the log, the one that carried the ending too.
    last = 100 + 400 if (ending.get("status") and not ending.get("tick_back")) else 100 + 399
    assert kept["tick"][-1] == last and kept.size == last - 99
    assert link.motor_offs >= 1


def test_a_partial_calibration_holds_the_finished_iterations(tmp_path, monkeypatch, capsys):
    """The rig ends the test during the second of three iterations (13 s each): the calibration is written from
    the first, marked partial with the count; the log holds everything measured. (The virtual rig stands in
    for the emulator here: the real-time run of this is in bench/hil_endings.py.)"""
    from pendulab.calibration.rig import RigEnded, VirtualRig
    from pendulab.cli.main import main

    real_step = VirtualRig.step

    def step(self, voltage):
        if self.time >= 16.0:
            raise RigEnded("the rig reports a fault (amplifier or encoder); check the rig")
        return real_step(self, voltage)

    monkeypatch.setattr(VirtualRig, "step", step)
    out, log = tmp_path / "c.json", tmp_path / "log.csv"
    status = main(["calibrate", "--virtual", "--iterations", "3", "--friction", "2,0.004,3.5,0.04,25", "--pendulum", "none",
                   "--out", str(out), "--log", str(log)])
    text = capsys.readouterr().out
    assert status == 1, text
    assert "PARTIAL calibration written" in text and "1 of 3" in text
    data = json.loads(out.read_text())
    meta = data.get("metadata", data)
    assert meta["partial"] is True and meta["iterations"] == 1 and meta["iterations_planned"] == 3
    assert "fault" in meta["end_reason"]
    friction = data["friction"] if isinstance(data["friction"], dict) else dict(zip(("F1", "v1", "F2", "v2", "B"), data["friction"]))
    assert friction["F1"] == pytest.approx(2.0, rel=0.05) and friction["B"] == pytest.approx(25.0, rel=0.1)
    from pendulab.calibration.logs import read_log as read_ramp_log

    t = read_ramp_log(log).t
    assert t[-1] == pytest.approx(16.0, abs=0.002)  # all of it, the unfinished second iteration too


def test_sigterm_ends_calibrate_with_the_motor_off_and_the_log_kept(tmp_path):
    def scenario():
        for old in tmp_path.iterdir():
            old.unlink()
        with emulator("--pendulum", "none", "--friction", FRICTION) as emu:
            proc = _calibrate(emu.port, tmp_path)
            emu.wait_for("motor enabled", timeout=30)
            time.sleep(1.0)
            proc.send_signal(signal.SIGTERM)
            out, err = proc.communicate(timeout=30)
            emu.wait_for("motor off", timeout=5)
            tick = _event_tick(emu, "motor off")
        return out, err, proc.returncode, tick

    out, err, status, tick = _on_a_steady_host(scenario)
    assert status == 128 + signal.SIGTERM, out + err
    assert "stopped by SIGTERM" in out and "motor off" in out and err.strip() == "", (out, err)
    log = read_log(tmp_path / "c-log.csv")
    assert log.size > 500 and abs(log["tick"][-1] - tick) <= 10, (log["tick"][-1], tick)


def test_sigterm_ends_lab_as_the_end_key_does(tmp_path):
    runs = iter(range(3))

    def scenario():
        out_dir = tmp_path / f"run{next(runs)}"
        with emulator("--raise-after", "0.3") as emu:
            proc = lab_process("--port", emu.port, "--demo", "--delay", DELAY, "--out", str(out_dir))
            proc.stdin.write("s\n")  # type: ignore[union-attr]
            proc.stdin.flush()  # type: ignore[union-attr]
            deadline = time.monotonic() + 30
            while "hand released" not in emu.text and proc.poll() is None and time.monotonic() < deadline:
                time.sleep(0.02)
            time.sleep(0.5)
            proc.send_signal(signal.SIGTERM)
            out, err = proc.communicate(timeout=60)
            emu_text = emu.text
        return out, err, proc.returncode, emu_text, out_dir

    out, err, status, emu_text, out_dir = _on_a_steady_host(scenario)
    assert status == 128 + signal.SIGTERM, out + err
    assert "motor off; session ended: ended by SIGTERM" in out, out
    assert "motor off" in emu_text
    for name in ("rig_log.csv", "run.mat", "run.csv", "metrics.json", "timing.json"):
        assert (out_dir / name).is_file(), name
    metrics = json.loads((out_dir / "metrics.json").read_text())
    assert "SIGTERM" in metrics["end_reason"]
    # No poke was given: the controller's catch after the hand let go is not taken for one.
    assert metrics["verdict"]["measures"].get("before_poke") and metrics["stable"] is False, (metrics, out)
    assert metrics["verdict"]["outcome"] == "cut" and "before the poke" in metrics["verdict"]["headline"]


@pytest.mark.parametrize("mode", ["tcp", "pty"])
def test_rig_emulator_stops_on_sigterm_while_waiting_for_a_host(mode):
    args = ["--tcp", "0"] if mode == "tcp" else []
    proc = subprocess.Popen([PYTHON, "-m", "pendulab", "rig-emulator", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=ENV)
    assert proc.stdout.readline().strip()  # type: ignore[union-attr]  # the port: it waits for a host now
    started = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=10)
    assert time.monotonic() - started < 10  # (before: it never stopped while waiting for a TCP client)
    assert proc.returncode == 0 and "emulator stopped (SIGTERM)" in err and "Traceback" not in err


def test_a_session_cut_before_its_poke_has_no_metrics():
    """Synthetic log of the issue's case: the watchdog ended the session at 0.92 s; the hand let go at 0.3 s."""
    from pendulab.fmu.models.supervisor.config import RUNNING
    from pendulab.hil.session import lab_metrics

    t = np.arange(0.0, 0.92, 0.001)
    released = t >= 0.3
    alpha = np.where(released, 0.0087 * np.exp(-(t - 0.3) * 5) * np.cos(12 * (t - 0.3)), 0.0087)
    columns = {"t": t, "alpha": np.round(alpha / 0.0015) * 0.0015, "xdot": 0 * t, "voltage": np.where(released, 0.5, 0.0),
               "supervisor_state": np.where(t >= 0.25, float(RUNNING), 1.0)}
    m = lab_metrics(columns, q_alpha=0.0015, end_reason="the rig's watchdog tripped", ended_early=True)
    assert m["verdict"]["outcome"] == "cut" and m["verdict"]["measures"]["before_poke"] and m["poke_start_detected_s"] is None
    assert m["stable"] is False and m["overshoot_percent"] is None and m["safety_cut_time_s"] == pytest.approx(0.919)
    assert "watchdog" in m["not_reported"]["peak_time_s"] and m["hand_release_s"] == pytest.approx(0.3)
    # The same log, ended by the operator: not a cut, and the hand's release is not a poke.
    m = lab_metrics(columns, q_alpha=0.0015, end_reason="ended by the operator (e)", ended_early=False)
    assert m["poke_start_detected_s"] is None and "no poke found" in m["error"] and m.get("verdict") is None


def test_a_session_that_starts_with_the_pendulum_hanging_is_judged_from_the_hands_release():
    """The rig's log starts before the hand has raised the pendulum (hanging, |alpha| about pi, as the firmware twin's
    sessions do): that is not a fall. A held session with its poke is judged from the release on."""
    from pendulab.fmu.models.supervisor.config import RUNNING
    from pendulab.hil.session import lab_metrics

    t = np.arange(0.0, 8.0, 0.001)
    raised, released, poked = t >= 0.3, t >= 0.5, t >= 2.0
    swing = 0.05 * np.exp(-(t - 2.0) * 1.5) * np.sin(2 * np.pi * 1.2 * (t - 2.0))
    alpha = np.where(poked, swing, np.where(raised, 0.0, np.pi - 0.06))
    columns = {"t": t, "alpha": np.round(alpha / 0.0015) * 0.0015, "x": 0 * t, "xdot": 0 * t,
               "voltage": np.where(released, np.where(poked, -20 * swing, 0.2), 0.0),
               "supervisor_state": np.where(t >= 0.45, float(RUNNING), 1.0)}
    m = lab_metrics(columns, q_alpha=0.0015, end_reason="ended by the operator (e)", ended_early=False)
    assert m["hand_release_s"] == pytest.approx(0.5) and m["poke_start_detected_s"] == pytest.approx(2.0, abs=0.05)
    assert m["verdict"]["outcome"] == "balanced", m["verdict"]["headline"]
    assert not m["verdict"]["headline"].startswith("FELL") and m["stable"] is True
