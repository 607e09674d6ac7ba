"""The rig's firmware and its digital twin: build them, and run the twin as a rig on a pseudo-terminal.

``firmware/`` (a checkout of pendulab) holds the C firmware for the Arduino Mega 2560 and
``firmware/twin/``, a simavr board program that runs that firmware instruction by instruction with
its pins wired to the plant (Plant.fmu's own CasADi-generated C code, or Seesaw.fmu's for the seesaw:
its tilt encoder on the pendulum's channel, the board's seesaw jumper grounded). Linux only (simavr).

Examples
--------
>>> from pendulab.hil.emulator import EmulatorOptions
>>> from pendulab.hil.firmware import build_firmware, build_twin, twin_command
>>> # skipped: building needs make, gcc-avr and simavr (tests/test_firmware*.py build them)
>>> hex_path, twin = build_firmware(), build_twin()     # doctest: +SKIP
>>> twin_command(Path("rig.hex"), EmulatorOptions(raise_after=2.0))[1:3]
['rig.hex', '--params']
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from pendulab.errors import UserError

if TYPE_CHECKING:
    from pendulab.hil.emulator import EmulatorOptions

REPO = Path(__file__).resolve().parents[3]
FIRMWARE_DIR = REPO / "firmware"
DEFAULT_HEX = FIRMWARE_DIR / "build" / "pendulab-rig.hex"
TWIN = FIRMWARE_DIR / "twin" / "build" / "pendulab-twin"


def _need_checkout() -> None:
    if not (FIRMWARE_DIR / "Makefile").is_file():
        raise UserError("the firmware sources are not here: the twin needs a checkout of pendulab (its firmware/ folder)")
    if sys.platform == "win32":
        raise UserError("the firmware twin runs on Linux only (simavr); on Windows use 'pendulab rig-emulator' without --firmware")


def _make(directory: Path, *extra: str, what: str, packages: str) -> None:
    if shutil.which("make") is None:
        raise UserError(f"building the {what} needs 'make': apt-get install make {packages}")
    result = subprocess.run(["make", "-C", str(directory), *extra], capture_output=True, text=True)
    if result.returncode != 0:
        lines = (result.stderr or result.stdout).strip().splitlines()
        tail = lines[-1] if lines else "no output"
        raise UserError(f"building the {what} failed ({tail}); install {packages} and run 'make -C {directory}' to see why")


def build_firmware(force: bool = False) -> Path:
    """``firmware/build/pendulab-rig.hex``, built with ``make -C firmware`` if missing (or if ``force``)."""
    _need_checkout()
    if force or not DEFAULT_HEX.is_file():
        _make(FIRMWARE_DIR, what="firmware", packages="gcc-avr avr-libc")
    return DEFAULT_HEX


def build_twin() -> Path:
    """The twin's executable, built (plant code generated from the CasADi model) if missing or stale."""
    _need_checkout()
    _make(FIRMWARE_DIR / "twin", f"PYTHON={sys.executable}", what="firmware twin", packages="gcc simavr libsimavr-dev libelf-dev")
    return TWIN


def idle_loop_range(elf: Path | None = None) -> tuple[int, int]:
    """Byte addresses ``[begin, end)`` of the firmware's idle loop (symbols ``idle_begin``/``idle_end``).

    The twin counts cycles spent there as idle (``--idle BEGIN,END``) when it measures the CPU load.
    """
    elf = elf or DEFAULT_HEX.with_suffix(".elf")
    out = subprocess.run(["avr-nm", str(elf)], capture_output=True, text=True, check=True).stdout
    symbols = {parts[2]: int(parts[0], 16) for parts in (line.split() for line in out.splitlines()) if len(parts) == 3}
    return symbols["idle_begin"], symbols["idle_end"]


#: Emulator options (:class:`~pendulab.hil.emulator.EmulatorOptions`) that model a host-side link the twin
#: does not have, by the command line's names.
UNSUPPORTED = {"latency": "--latency", "jitter": "--jitter", "stall_after": "--stall-after"}


def check_twin_options(options: EmulatorOptions) -> None:
    """Refuse (UserError) the options the twin does not model: a latency, jitter or stall of the link."""
    defaults = type(options)()
    for name, option in UNSUPPORTED.items():
        if getattr(options, name) != getattr(defaults, name):
            raise UserError(f"{option} is not available with --firmware (the twin's link is the firmware's own UART); drop it")


def twin_command(hex_path: Path, options: EmulatorOptions) -> list[str]:
    """The twin's command line for the firmware ``hex_path`` and the rig ``options``.

    ``options`` are the rig emulator's (the plant's parameters and what a person does); the twin's
    link is the firmware's own UART, so a latency, jitter or stall is refused (UserError).

    Examples
    --------
    >>> from pendulab.hil.emulator import EmulatorOptions
    >>> command = twin_command(Path("rig.hex"), EmulatorOptions(raise_after=2.0, seed=7))
    >>> command[1:3], command[4:]
    (['rig.hex', '--params'], ['--raise-after', '2.0', '--seed', '7'])
    >>> from pendulab.model.seesaw import SeesawParameters
    >>> twin_command(Path("rig.hex"), EmulatorOptions(params=SeesawParameters(), plant="seesaw"))[-2:]
    ['--plant', 'seesaw']
    """
    import dataclasses

    check_twin_options(options)
    command = [str(TWIN), str(hex_path), "--params", ",".join(repr(float(v)) for v in options.params.as_vector())]
    for field in dataclasses.fields(options):
        if field.name in ("raise_after", "restart_after", "fault_after", "close_after") and getattr(options, field.name) is not None:
            command += ["--" + field.name.replace("_", "-"), repr(float(getattr(options, field.name)))]
    if options.poke is not None:
        command += ["--poke", ",".join(repr(float(v)) for v in options.poke)]
    if options.byte_error_rate:
        command += ["--byte-error-rate", repr(options.byte_error_rate)]
    if options.seed is not None:
        command += ["--seed", str(options.seed)]
    for which, (kind, after) in options.encoder_faults.items():
        command += [f"--{kind}-encoder", f"{which},{after!r}"]
    if options.plant != "pendulum":
        command += ["--plant", options.plant]
    return command


def run_twin(hex_path: Path | None, options: EmulatorOptions) -> int:
    """Run the firmware in the twin in the foreground (``pendulab rig-emulator --firmware [HEX]``).

    Builds the firmware (``make -C firmware``) if ``hex_path`` is None and it is missing, builds the twin,
    gives it the plant and person ``options`` (:func:`twin_command`), and returns the twin's exit status. The twin
    prints the pseudo-terminal's path alone on the first line of stdout and one line per change of
    state on stderr.
    """
    check_twin_options(options)
    if hex_path is None:
        hex_path = build_firmware()
    elif not Path(hex_path).is_file():
        raise UserError(f"firmware {hex_path} not found; build it with 'make -C firmware' or leave --firmware without a file")
    command = twin_command(Path(hex_path), options)
    build_twin()
    import signal

    process = subprocess.Popen(command)
    # A SIGTERM to us (the lab's tests, a process manager) ends the twin too; the twin itself also asks
    # the kernel for SIGTERM when its parent dies.
    previous = signal.signal(signal.SIGTERM, lambda *_: process.terminate())
    try:
        return process.wait()
    except KeyboardInterrupt:
        process.terminate()
        process.wait()
        return 0
    finally:
        signal.signal(signal.SIGTERM, previous)
