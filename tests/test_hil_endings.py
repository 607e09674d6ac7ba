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


def _on_a_steady_host(scenario, tries: int = 3):
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


def test_a_rig_fault_keeps_the_log_to_the_fault(tmp_path):
    def scenario():
        for old in tmp_path.iterdir():
            old.unlink()
        with emulator("--pendulum", "none", "--friction", FRICTION, "--fault-after", "3") as emu:
            proc = _calibrate(emu.port, tmp_path)
            out, err = proc.communicate(timeout=60)
            tick = _event_tick(emu, "fault (amplifier") if "fault (amplifier" in emu.text else None
        return out, err, proc.returncode, tick

    out, err, status, tick = _on_a_steady_host(scenario)
    assert status == 1, out + err
    assert "the rig reports a fault" in out and "the log is kept in" in out, out
    log = read_log(tmp_path / "c-log.csv")
    assert abs(log["tick"][-1] - tick) <= 10, (log["tick"][-1], tick)  # the log holds the fault's own sample
    assert not (tmp_path / "c.json").exists()  # no iteration had finished


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


def test_a_rig_restart_is_named_a_restart_and_the_log_is_kept(tmp_path):
    def scenario():
        for old in tmp_path.iterdir():
            old.unlink()
        with emulator("--pendulum", "none", "--friction", FRICTION, "--restart-after", "4") as emu:
            proc = _calibrate(emu.port, tmp_path)
            out, err = proc.communicate(timeout=60)
            tick = _event_tick(emu, "restart: firmware reset") if "restart: firmware reset" in emu.text else None
        return out, err, proc.returncode, tick

    out, err, status, tick = _on_a_steady_host(scenario)
    assert status == 1, out + err
    assert "the rig restarted (boot id" in out and "link lost" not in out, out
    assert "no iteration finished, so no calibration was written; the log is kept" in out
    log = read_log(tmp_path / "c-log.csv")
    assert abs(log["tick"][-1] - tick) <= 10, (log["tick"][-1], tick)
    assert not (tmp_path / "c.json").exists()


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
    out_dir = tmp_path / "run"
    with emulator("--raise-after", "0.3") as emu:
        proc = lab_process("--port", emu.port, "--demo", "--delay", DELAY, "--out", str(out_dir))
        proc.stdin.write("s\n")  # type: ignore[union-attr]
        proc.stdin.flush()  # type: ignore[union-attr]
        emu.wait_for("hand released", timeout=30)
        time.sleep(0.5)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
        emu_text = emu.text
    assert proc.returncode == 128 + signal.SIGTERM, out + err
    assert "motor off; session ended: ended by SIGTERM" in out, out
    assert "motor off" in emu_text
    for name in ("rig_log.csv", "run.mat", "run.csv", "metrics.json", "timing.json"):
        assert (out_dir / name).is_file(), name
    metrics = json.loads((out_dir / "metrics.json").read_text())
    assert "SIGTERM" in metrics["end_reason"]
    # No poke was given: the controller's catch after the hand let go is not taken for one.
    assert metrics.get("verdict") == "cut before the poke" and metrics["stable"] is None, (metrics, out)


@pytest.mark.parametrize("mode", ["tcp", "pty"])
def test_rig_emulator_stops_on_sigterm_while_waiting_for_a_host(mode):
    args = ["--tcp", "0"] if mode == "tcp" else []
    proc = subprocess.Popen([PYTHON, "-m", "pendulab", "rig-emulator", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=ENV)
    assert proc.stdout.readline().strip()  # type: ignore[union-attr]  # the port: it waits for a host now
    started = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=10)
    assert time.monotonic() - started < 3
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
    assert m["verdict"] == "cut before the poke" and m["poke_start_detected_s"] is None
    assert m["stable"] is None and m["overshoot_percent"] is None and m["safety_cut_time_s"] == pytest.approx(0.919)
    assert "watchdog" in m["not_reported"] and m["hand_release_s"] == pytest.approx(0.3)
    # The same log, ended by the operator: not a cut, and the hand's release is not a poke.
    m = lab_metrics(columns, q_alpha=0.0015, end_reason="ended by the operator (e)", ended_early=False)
    assert m["poke_start_detected_s"] is None and "no poke found" in m["error"] and m.get("verdict") is None
