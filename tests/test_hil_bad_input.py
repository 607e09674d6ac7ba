"""Bad input to ``pendulab lab`` and ``pendulab rig-emulator``: one clear line, exit status 2, motor never enabled."""

from __future__ import annotations

import os
import random
import sys
import threading
import tty

import pytest
from hil_helpers import ENV, PYTHON, emulator, lab

from pendulab.hil import protocol as P

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX")


class FakeRig:
    """A pty whose far end does what a test wants: nothing, noise, or another protocol version."""

    def __init__(self, behaviour: str) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self.behaviour = behaviour
        self.enabled_commands = 0
        self.received = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        import select

        reader = P.FrameReader()
        rng = random.Random(5)
        while not self._stop.is_set():
            ready = select.select([self.master], [], [], 0.01)[0]
            if self.behaviour == "noise":
                try:
                    os.write(self.master, bytes(rng.randrange(256) for _ in range(64)))
                except OSError:
                    return
            if not ready:
                continue
            try:
                data = os.read(self.master, 4096)
            except OSError:
                return
            for frame in reader.feed(data):
                self.received += 1
                if isinstance(frame, P.Command) and frame.flags & P.ENABLE:
                    self.enabled_commands += 1
                if isinstance(frame, P.Identify) and self.behaviour == "version2":
                    reply = P.Identity(0, protocol=2, boot_id=1)
                    os.write(self.master, P.encode(reply))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        os.close(self.master)
        os.close(self.slave)


def _one_line_exit_2(result) -> str:
    assert result.returncode == 2, result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr
    return lines[0]


def test_port_that_does_not_exist(tmp_path):
    line = _one_line_exit_2(lab("--port", str(tmp_path / "ttyNOPE"), "--demo", "--out", str(tmp_path / "run")))
    assert "cannot open port" in line and "COM3" in line
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("behaviour, expected", [
    ("silent", "no reply from"),
    ("noise", "is not a pendulab rig"),
    ("version2", "protocol version 2"),
])
def test_port_that_is_not_a_rig_of_our_protocol(tmp_path, behaviour, expected):
    rig = FakeRig(behaviour)
    try:
        line = _one_line_exit_2(lab("--port", rig.path, "--demo", "--out", str(tmp_path / "run")))
    finally:
        rig.close()
    assert expected in line
    if behaviour == "version2":
        assert "speaks version 1" in line
    assert rig.enabled_commands == 0


def test_controller_the_rules_refuse_never_touches_the_rig(tmp_path):
    with emulator() as emu:
        line = _one_line_exit_2(lab("--port", emu.port, "--zeros", "0", "--poles", "-5", "--gain", "10", "--out", str(tmp_path / "run")))
        text = emu.text
    assert "zero" in line.lower() and "s/(s+62.8)" in line.replace(" ", "")
    assert "host connected" not in text and "motor enabled" not in text


@pytest.mark.parametrize("args, fragment", [
    (["--delay", "0"], "--delay 0"),
    (["--stop-time", "-1"], "--stop-time"),
    (["--max-delay", "20"], "--max-delay"),
    (["--poke", "a,b,c"], "--poke"),
])
def test_bad_lab_options(tmp_path, args, fragment):
    line = _one_line_exit_2(lab("--port", "loop://", "--demo", *args, "--out", str(tmp_path / "run")))
    assert fragment in line


@pytest.mark.parametrize("args, fragment", [
    (["--byte-error-rate", "2"], "--byte-error-rate"),
    (["--latency", "-1"], "--latency"),
    (["--poke", "1,2"], "--poke"),
    (["--friction", "1,2"], "--friction"),
    (["--pendulum", "medium"], "pendulum"),
])
def test_bad_emulator_options(args, fragment):
    import subprocess

    result = subprocess.run([PYTHON, "-m", "pendulab", "rig-emulator", *args], capture_output=True, text=True, timeout=30, env=ENV)
    line = _one_line_exit_2(result)
    assert fragment in line
    assert result.stdout == ""  # no port announced for an emulator that does not run


def test_existing_run_folder_is_kept_when_the_rig_is_missing(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    _one_line_exit_2(lab("--port", str(tmp_path / "none"), "--demo", "--out", str(out)))
    assert (out / "notes.txt").read_text() == "mine"


def test_lab_refuses_a_link_too_slow_for_any_allowed_delay(tmp_path):
    with emulator("--latency", "4") as emu:  # 4 ms added: needs N >= 5
        result = lab("--port", emu.port, "--demo", "--max-delay", "2", "--out", str(tmp_path / "run"))
        text = emu.text
    line = _one_line_exit_2(result)
    assert "too slow" in line and "--max-delay" in line
    assert "motor enabled" not in text


def test_lab_picks_a_longer_delay_behind_a_usb_bridge(tmp_path):
    """1 ms +- 0.3 ms of added latency: N = 1 cannot hold; lab measures it and picks a longer delay."""
    from pendulab.hil.link import RigLink
    from pendulab.hil.session import choose_delay

    with emulator("--latency", "1", "--jitter", "0.3") as emu, RigLink.open(emu.port) as link:
        link.identify()
        said: list[str] = []
        n = choose_delay(link, 8, samples=500, announce=said.append)
    assert n >= 2, said  # (2 or 3 on a quiet machine; a loaded one may need more)
    assert "N = 1 is too short" in said[0]
