"""The Windows code paths that are pure Python, run on Linux by faking the platform's modules (issue 23).

``sys.platform`` is set to ``"win32"`` and the Windows-only modules (``msvcrt``, ``ctypes.windll``, the COM
ports pyserial lists) are replaced by fakes that record what pendulab asks of them.
"""

from __future__ import annotations

import ctypes
import sys
import types

import pytest

from pendulab.errors import UserError


class _Console:
    """A stdin that is a console (what ``msvcrt`` reads from on Windows)."""

    def isatty(self) -> bool:
        return True

    def fileno(self) -> int:
        raise AssertionError("a Windows console is not read through a file descriptor")


def test_keys_on_a_windows_console_come_from_msvcrt(monkeypatch):
    from pendulab.hil.keys import KeySource

    pressed = list("S1p\x1be")  # a capital, a digit and Escape among the keys
    fake = types.SimpleNamespace(kbhit=lambda: bool(pressed), getwch=lambda: pressed.pop(0))
    monkeypatch.setitem(sys.modules, "msvcrt", fake)
    monkeypatch.setattr(sys, "platform", "win32")
    with KeySource(_Console()) as keys:
        assert keys._mode == "msvcrt"
        assert keys.poll() == ["s", "p", "e"]
        assert keys.poll() == [] and not pressed


@pytest.mark.parametrize("granted, expected", [(1, "high priority class"), (0, "normal priority")])
def test_windows_priority_is_high_priority_class(monkeypatch, granted, expected):
    from pendulab.hil.realtime import raise_priority

    calls = []
    kernel32 = types.SimpleNamespace(GetCurrentProcess=lambda: -1,
                                     SetPriorityClass=lambda handle, cls: calls.append((handle, cls)) or granted)
    monkeypatch.setattr(ctypes, "windll", types.SimpleNamespace(kernel32=kernel32), raising=False)
    monkeypatch.setattr(sys, "platform", "win32")
    assert raise_priority() == expected
    assert calls == [(-1, 0x00000080)], "HIGH_PRIORITY_CLASS for this process (no real-time class: it needs admin rights)"


def test_a_wrong_com_port_names_the_ports_there_are(monkeypatch):
    """A TA gives COM5; the rig is on COM10 (the number follows the USB socket): the one line says so."""
    import serial.tools.list_ports

    from pendulab.hil.link import RigLink

    ports = [types.SimpleNamespace(device=d, description=t) for d, t in
             (("COM10", "USB Serial Device (COM10)"), ("COM1", "Communications Port (COM1)"), ("COM3", "n/a"))]
    monkeypatch.setattr(serial.tools.list_ports, "comports", lambda: ports)
    with pytest.raises(UserError) as info:
        RigLink.open("COM5")
    line = str(info.value)
    assert "\n" not in line and line.startswith("cannot open port 'COM5'")
    assert line.endswith("serial ports here: COM1 (Communications Port (COM1)), COM3, COM10 (USB Serial Device (COM10))")
    monkeypatch.setattr(serial.tools.list_ports, "comports", lambda: [])
    with pytest.raises(UserError, match=r"no serial port found here \(is the rig plugged in\?\)$"):
        RigLink.open("COM5")


def test_windows_has_no_pseudo_terminals_or_firmware_twin(monkeypatch, capsys):
    """rig-emulator without --tcp, and --firmware, say what to do instead (one line, exit 2)."""
    from pendulab.cli.main import build_parser, main

    build_parser()  # imports every subcommand (fmpy reads sys.platform when imported: it must see Linux's)
    monkeypatch.setattr(sys, "platform", "win32")
    assert main(["rig-emulator"]) == 2
    assert "use --tcp PORT and 'pendulab lab --port socket://127.0.0.1:PORT'" in capsys.readouterr().err
    from pendulab.hil import firmware

    monkeypatch.setattr(firmware, "FIRMWARE_DIR", firmware.REPO / "firmware")
    with pytest.raises(UserError, match="runs on Linux only"):
        firmware._need_checkout()
