"""The rig's firmware and its digital twin: build them, and run the twin as a rig on a pseudo-terminal.

``firmware/`` (a checkout of pendulab) holds the C firmware for the Arduino Mega 2560 and
``firmware/twin/``, a simavr board program that runs that firmware instruction by instruction with
its pins wired to the plant (Plant.fmu's own CasADi-generated C code). Linux only (simavr).

Examples
--------
>>> from pendulab.hil.firmware import build_twin, twin_command
>>> hex_path, twin = build_firmware(), build_twin()                     # doctest: +SKIP
>>> twin_command(hex_path, ["--raise-after", "2"])                      # doctest: +SKIP
['.../pendulab-twin', '.../pendulab-rig.hex', '--params', '0.23,...', '--raise-after', '2']
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

from pendulab.errors import UserError

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


def twin_parser() -> argparse.ArgumentParser:
    """The options the twin takes from ``pendulab rig-emulator``: the plant and the person."""
    from pendulab.cli.options import add_plant_options

    parser = argparse.ArgumentParser(prog="pendulab rig-emulator --firmware", add_help=False)
    add_plant_options(parser, pendulums=("long", "short", "none"))
    parser.add_argument("--friction", metavar="F1,v1,F2,v2,B")
    parser.add_argument("--raise-after", type=float)
    parser.add_argument("--poke")
    parser.add_argument("--seed", type=int)
    parser.add_argument("--restart-after", type=float)
    parser.add_argument("--fault-after", type=float)
    parser.add_argument("--close-after", type=float)
    parser.add_argument("--byte-error-rate", type=float, default=0.0)
    return parser


#: rig-emulator options that model a host-side link the twin does not have.
UNSUPPORTED = ("--latency", "--jitter", "--stall-after", "--stall-for", "--tcp")


def twin_command(hex_path: Path, argv: list[str]) -> list[str]:
    """The twin's command line for the firmware ``hex_path`` and rig-emulator options ``argv``."""
    import math

    from pendulab.cli.options import plant_parameters_from_args

    for option in UNSUPPORTED:
        if any(a == option or a.startswith(option + "=") for a in argv):
            raise UserError(f"{option} is not available with --firmware (the twin's link is the firmware's own UART); drop it")
    # '--firmware HEX' may leave the path behind as a positional: it is the firmware, not an option.
    argv = [a for a in argv if a != str(hex_path)]
    args, rest = twin_parser().parse_known_args(argv)
    if rest:
        raise UserError(f"unknown option {rest[0]!r} for the firmware twin; see 'pendulab rig-emulator --help'")
    params = plant_parameters_from_args(args)
    if args.friction:
        try:
            values = [float(v) for v in args.friction.split(",")]
        except ValueError:
            values = []
        if len(values) != 5 or not all(math.isfinite(v) and v >= 0 for v in values):
            raise UserError(f"--friction {args.friction!r} must be five numbers >= 0: F1,v1,F2,v2,B")
        params = params.with_values(**dict(zip(("F1", "v1", "F2", "v2", "B"), values)))
    command = [str(TWIN), str(hex_path), "--params", ",".join(repr(float(v)) for v in params.as_vector())]
    for name in ("raise_after", "restart_after", "fault_after", "close_after"):
        value = getattr(args, name)
        if value is not None:
            if not (math.isfinite(value) and value >= 0):
                raise UserError(f"--{name.replace('_', '-')} {value} must be a number >= 0")
            command += ["--" + name.replace("_", "-"), repr(value)]
    if args.poke:
        from pendulab.cli.simulate import parse_poke

        command += ["--poke", ",".join(repr(v) for v in parse_poke(args.poke))]
    if not 0 <= args.byte_error_rate < 0.5:
        raise UserError(f"--byte-error-rate {args.byte_error_rate} must be a probability from 0 to below 0.5, e.g. 1e-3")
    if args.byte_error_rate:
        command += ["--byte-error-rate", repr(args.byte_error_rate)]
    if args.seed is not None:
        command += ["--seed", str(args.seed)]
    return command


def run_twin(hex_path: Path | None, argv: list[str]) -> int:
    """Run the firmware in the twin in the foreground (``pendulab rig-emulator --firmware [HEX]``).

    Builds the firmware (``make -C firmware``) if ``hex_path`` is None and it is missing, builds the twin,
    passes the plant and person options in ``argv`` through, and returns the twin's exit status. The twin
    prints the pseudo-terminal's path alone on the first line of stdout and one line per change of
    state on stderr.
    """
    if hex_path is None:
        hex_path = build_firmware()
    elif not Path(hex_path).is_file():
        raise UserError(f"firmware {hex_path} not found; build it with 'make -C firmware' or leave --firmware without a file")
    command = twin_command(Path(hex_path), argv)
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
