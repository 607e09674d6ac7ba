"""``pendulab lab`` against ``pendulab rig-emulator`` through a real pseudo-terminal: the session, its
files, the comparison with ``simulate --delay N``, and every fault the issue lists."""

from __future__ import annotations

import json
import os
import signal
import sys
import time

import numpy as np
import pytest
import scipy.io
from hil_helpers import angle_error_against_simulate, emulator, lab, lab_process, last_line, read_log, until_the_link_holds

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX (Windows uses --tcp)")

#: A big poke (a 220 rad/s^2 one makes the demo controller, which does not hold the cart, drift to the track
#: limit about 12 s later, in simulation as on the rig); 150 keeps the cart within 0.3 m.
POKE = "150,0.005,1"
#: The old lab's poke, for the comparison with simulation (over the first second after it, so no drift).
BIG_POKE = "220,0.005,1"


@pytest.fixture(scope="module", autouse=True)
def _fmus():
    from pendulab.fmu.build import ensure_fmu

    for name in ("Plant", "Controller", "Supervisor"):
        ensure_fmu(name)


def _demo_session(out):
    """Raised, started, poked, 12 s of balancing, ended with the end key; whether the lab ended before the key."""
    with emulator("--raise-after", "0.3", "--poke", POKE) as emu:
        # (--max-delay 8: on a loaded machine the measured delay may exceed the default limit of 4)
        proc = lab_process("--port", emu.port, "--demo", "--max-delay", "8", "--out", str(out))
        proc.stdin.write("s\n")  # type: ignore[union-attr]
        proc.stdin.flush()  # type: ignore[union-attr]
        emu.wait_for("hand released", timeout=20)
        time.sleep(12.0)
        early = proc.poll() is not None
        try:
            proc.stdin.write("e\n")  # type: ignore[union-attr]
            proc.stdin.flush()  # type: ignore[union-attr]
        except BrokenPipeError:  # the lab already ended (its reason is in its output)
            early = True
        stdout, stderr = proc.communicate(timeout=30)
        emu_text = emu.text
    return proc.returncode, stdout, stderr, emu_text, early


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    """One full session; up to two more if one ended before the end key.

    The emulator and the lab share this machine's two cores with whatever else runs: a session on a
    loaded CI host can lose its real-time link (the lab then ends, motor off, log kept, as on a rig). That
    is printed, and the session is run again; the test fails if the third one also ends early.
    """

    def session(attempt: int):
        out = tmp_path_factory.mktemp("lab") / "demo"
        return (out, *_demo_session(out))

    def lost(run) -> str | None:
        _, status, stdout, stderr, _, early = run
        return f"ended before the end key (status {status}): {last_line(stdout)} {stderr.strip()[-300:]}" if early else None

    out, status, stdout, stderr, emu_text, _ = until_the_link_holds(session, lost)
    return out, status, stdout, stderr, emu_text


def test_demo_session_balances_and_writes_a_complete_run(demo_run):
    out, status, stdout, stderr, emu_text = demo_run
    assert status == 0, stderr
    assert "ended by the operator (e)" in stdout
    for name in ("rig_log.csv", "run.mat", "run.csv", "metrics.json", "timing.json"):
        assert (out / name).is_file(), name
    log = read_log(out / "rig_log.csv")
    # Held for more than 10 s before any trip (the demo controller does not hold the cart's position, so in a
    # long session the cart may drift to the track limit, which the supervisor cuts, as on the rig).
    tripped = np.flatnonzero(log["supervisor_state"] == 4)
    end = tripped[0] if tripped.size else log.size
    running = np.zeros(log.size, dtype=bool)
    running[:end] = log["supervisor_state"][:end] == 2
    assert running.any()
    t_run = log["t"][running]
    assert t_run[-1] - t_run[0] > 10.0, "the supervisor tripped within 10 s"
    assert np.max(np.abs(log["alpha"][running])) < np.radians(12)
    # Every sample of the session is in the log, once, in order.
    assert np.all(np.diff(log["tick"]) == 1)
    # The metrics come from the rig's log: the poke found where the emulator gave it.
    metrics = json.loads((out / "metrics.json").read_text())
    release = log["t"][np.argmax(log["voltage"] != 0)]
    assert metrics["poke_start_detected_s"] == pytest.approx(release + 1.0, abs=0.02)
    assert metrics["natural_frequency_rad_s"] is not None and 3 < metrics["natural_frequency_rad_s"] < 20
    assert metrics["peak_time_s"] is not None and 0.02 < metrics["peak_time_s"] < 0.5
    mat = scipy.io.loadmat(out / "run.mat", squeeze_me=True, struct_as_record=False)
    assert mat["t"].size == log.size and mat["meta"].source == "rig"
    timing = json.loads((out / "timing.json").read_text())
    assert timing["samples"] == log.size and timing["delay_periods"] >= 1
    assert timing["answer_latency_ms"]["p50"] < 1.0
    assert "motor enabled" in emu_text


def test_rig_run_matches_simulate_with_the_same_delay(tmp_path):
    """Must-show 4: the same controller and poke in simulate --delay N: angle NRMSE < 5 % over 1 s."""
    from pendulab.cli.main import main

    out = tmp_path / "rig"
    with emulator("--raise-after", "0.3", "--poke", BIG_POKE) as emu:
        result = lab("--port", emu.port, "--demo", "--max-delay", "8", "--stop-time", "4", "--out", str(out), stdin="s\n")
    assert result.returncode == 0, result.stdout + result.stderr
    sim = tmp_path / "sim"
    n, error = angle_error_against_simulate(out, BIG_POKE, sim)
    print(f"angle NRMSE rig emulator vs simulate --delay {n}: {100 * error:.2f} %")
    assert error < 0.05
    # The comparison command on the pair: the table and the PNG.
    assert main(["compare", str(sim), str(out), "--out", str(tmp_path / "cmp")]) == 0
    png = (tmp_path / "cmp" / "comparison.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert "natural frequency" in (tmp_path / "cmp" / "comparison.txt").read_text()


def test_watchdog_drops_to_zero_volts_when_the_host_stops_answering():
    from pendulab.hil import protocol as P
    from pendulab.hil.link import RigLink

    with emulator() as emu, RigLink.open(emu.port) as link:
        link.identify()
        link.configure(delay=1)
        link.stream(True)
        last_tick = None
        for k in range(300):
            sample, _ = link.next_sample(0.5)
            link.command(sample.seq, 3.0, enable=True, clear=k == 0)
            last_tick = sample.tick
        # Stop answering; watch the applied voltage.
        zero_tick = None
        for _ in range(200):
            sample, _ = link.next_sample(0.5)
            if sample.voltage_mv == 0:
                zero_tick = sample.tick
                assert sample.status & P.ST_WATCHDOG
                break
            assert sample.voltage_mv == 3000  # the last voltage is held until the watchdog
        assert zero_tick is not None
        # The last answer (to last_tick) arrived within its period: 0 V within 20 ms + one period of it.
        assert 19 <= zero_tick - last_tick <= 20 + 2
        emu.wait_for("watchdog tripped")


def test_kill_9_of_lab_keeps_every_sample_up_to_100_ms_before(tmp_path):
    out = tmp_path / "killed"
    with emulator("--raise-after", "0.2") as emu:
        proc = lab_process("--port", emu.port, "--demo", "--delay", "1", "--out", str(out))
        while True:
            line = proc.stdout.readline()  # type: ignore[union-attr]
            assert line, proc.stderr.read()  # type: ignore[union-attr]
            if line.startswith("streaming"):
                started = time.monotonic()
                break
        proc.stdin.write("s\n")  # type: ignore[union-attr]
        proc.stdin.flush()  # type: ignore[union-attr]
        time.sleep(2.5)
        killed = time.monotonic()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    log = read_log(out / "rig_log.csv")
    elapsed = killed - started
    assert log["t"][-1] >= elapsed - 0.100 - 0.02  # 20 ms: the pipe between 'streaming' and this test
    assert np.all(np.diff(log["tick"]) == 1)


def test_emulator_closing_the_port_ends_lab_with_link_lost(tmp_path):
    out = tmp_path / "lost"
    # The port closes 6 s after the host connects: a slow machine's lab took 2.4 s from connecting to
    # streaming (89 samples logged before a close at 2.5 s), and the log must show streaming ended by it.
    with emulator("--raise-after", "0.2", "--close-after", "6") as emu:
        result = lab("--port", emu.port, "--demo", "--delay", "1", "--out", str(out), stdin="s\n")
    assert result.returncode != 0
    assert "link lost" in result.stdout
    meta = scipy.io.loadmat(out / "run.mat", squeeze_me=True, struct_as_record=False)["meta"]
    assert "link lost" in meta.end_reason
    assert read_log(out / "rig_log.csv").size > 1000


def test_byte_errors_are_counted_and_never_reach_the_controller(tmp_path):
    out = tmp_path / "noisy"
    with emulator("--raise-after", "0.2", "--byte-error-rate", "1e-3", "--seed", "7") as emu:
        result = lab("--port", emu.port, "--demo", "--delay", "1", "--stop-time", "5", "--out", str(out), stdin="s\n")
    assert result.returncode == 0, result.stdout + result.stderr
    timing = json.loads((out / "timing.json").read_text())
    log = read_log(out / "rig_log.csv")
    assert timing["crc_errors"] > 0
    # Each corrupt sample frame is a missed sample, counted; the loop ran on through all of them.
    assert timing["missed_samples"] > 0 and timing["crc_errors"] >= timing["missed_samples"] // 2
    assert log["t"][-1] >= 5.0
    assert log["tick"][-1] - log["tick"][0] + 1 == log.size + timing["missed_samples"]
    # A corrupt frame that got through would show as an impossible jump of the encoders.
    assert np.max(np.abs(np.diff(log["x"]))) < 2e-3
    state = log["supervisor_state"]
    running = (state[1:] == 2) & (state[:-1] == 2)  # (before that the hand raises the pendulum in one step)
    assert running.sum() > 3000
    assert np.max(np.abs(np.diff(log["theta"])[running])) < 0.05
    assert not (log["supervisor_state"] == 4).any()


def test_rig_restart_stops_the_motor_and_ends(tmp_path):
    out = tmp_path / "restart"
    # 6 s after the host connects, as the close above: on a slow machine a restart at 2.5 s came while lab was
    # still setting up (after its IDENTIFY, before CONFIGURE), so lab configured the new firmware and ran on.
    with emulator("--raise-after", "0.2", "--restart-after", "6") as emu:
        result = lab("--port", emu.port, "--demo", "--delay", "1", "--out", str(out), stdin="s\n")
        emu.wait_for("restart")
    assert result.returncode != 0
    assert "restarted" in result.stdout
    assert (out / "run.mat").is_file() and (out / "timing.json").is_file()


def test_stalled_link_trips_the_rig_watchdog_and_ends_the_session(tmp_path):
    out = tmp_path / "stall"
    # (6 s: a stall during lab's set-up is retried there, and the session then runs on; see the restart above)
    with emulator("--raise-after", "0.2", "--stall-after", "6", "--stall-for", "0.1") as emu:
        result = lab("--port", emu.port, "--demo", "--delay", "1", "--out", str(out), stdin="s\n", timeout=30)
        emu.wait_for("watchdog tripped")
    assert result.returncode != 0
    assert "watchdog" in result.stdout


def test_rig_over_tcp_the_path_windows_uses(tmp_path):
    """``rig-emulator --tcp`` and ``lab --port socket://...``: no pseudo-terminal anywhere."""
    out = tmp_path / "tcp"
    with emulator("--tcp", "0", "--raise-after", "0.2", "--poke", POKE) as emu:
        assert emu.port.startswith("socket://127.0.0.1:")
        result = lab("--port", emu.port, "--demo", "--delay", "2", "--stop-time", "3", "--out", str(out), "--plot", stdin="s\n")
    assert result.returncode == 0, result.stdout + result.stderr
    timing = json.loads((out / "timing.json").read_text())
    assert timing["samples"] > 2900 and timing["crc_errors"] == 0
    assert any(p.suffix == ".png" for p in out.iterdir())
    log = read_log(out / "rig_log.csv")
    assert (log["supervisor_state"] == 2).sum() > 1000  # the controller engaged and held it through the poke


def test_rig_fault_ends_the_session_with_the_motor_off(tmp_path):
    out = tmp_path / "fault"
    with emulator("--raise-after", "0.2", "--fault-after", "2.0") as emu:
        result = lab("--port", emu.port, "--demo", "--delay", "1", "--out", str(out), stdin="s\n")
        emu.wait_for("fault")
    assert result.returncode != 0 and "fault" in result.stdout
    meta = scipy.io.loadmat(out / "run.mat", squeeze_me=True, struct_as_record=False)["meta"]
    assert "fault" in meta.end_reason


def test_ctrl_c_turns_the_motor_off_and_keeps_the_log(tmp_path):
    out = tmp_path / "ctrl_c"
    with emulator("--raise-after", "0.2") as emu:
        proc = lab_process("--port", emu.port, "--demo", "--delay", "1", "--out", str(out))
        proc.stdin.write("s\n")  # type: ignore[union-attr]
        proc.stdin.flush()  # type: ignore[union-attr]
        emu.wait_for("motor enabled", timeout=20)
        time.sleep(1.0)
        proc.send_signal(signal.SIGINT)
        stdout, _ = proc.communicate(timeout=20)
        emu.wait_for("motor off")
    assert proc.returncode == 130 and "interrupted (Ctrl-C)" in stdout
    # Every sample measured up to the interrupt is kept, in all three files. How many there are is the host's business:
    # about 1000 after the 1 s sleep on an idle machine, 868 on a loaded CI host.
    log = read_log(out / "rig_log.csv")
    mat = scipy.io.loadmat(out / "run.mat", squeeze_me=True, struct_as_record=False)
    timing = json.loads((out / "timing.json").read_text())
    assert log.size > 400 and mat["t"].size == log.size == timing["samples"]
    assert "interrupt" in mat["meta"].end_reason.lower()


def test_single_keys_from_a_real_terminal(tmp_path):
    """On a terminal, s / p / e act as single key presses (no Enter), each announced."""
    import pexpect

    out = tmp_path / "keys"
    with emulator("--raise-after", "0.2") as emu:
        child = pexpect.spawn(sys.executable, ["-m", "pendulab", "lab", "--port", emu.port, "--demo", "--delay", "1", "--out", str(out)],
                              encoding="utf-8", timeout=30, env={**os.environ, "MPLBACKEND": "Agg"})
        child.expect("streaming")
        child.send("s")
        child.expect(r"key 's': start")
        child.expect("running")
        time.sleep(0.5)
        child.send("p")
        child.expect(r"key 'p': pause")
        child.expect("paused")
        child.send("e")
        child.expect(r"key 'e': end")
        child.expect("ended by the operator")
        child.expect(pexpect.EOF)
        child.close()
    assert child.exitstatus == 0
    assert (out / "metrics.json").is_file()
