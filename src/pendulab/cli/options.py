"""Command-line options shared by several subcommands."""

from __future__ import annotations

import argparse
from typing import Any

from pendulab.errors import UserError
from pendulab.model.parameters import CARTS, PlantParameters
from pendulab.spec import Plant


def add_plant_options(parser: argparse.ArgumentParser, *, pendulums: tuple[str, ...] = ("long", "short")) -> None:
    """``--pendulum``, ``--cart`` and ``--calibration``."""
    parser.add_argument("--pendulum", default="long", metavar="|".join(pendulums), help="pendulum (default long)")
    parser.add_argument("--cart", default="ip02", metavar="|".join(CARTS), help="cart (default ip02, no load)")
    parser.add_argument("--calibration", metavar="FILE", help="calibration file (JSON, or the old lab's .mat)")


def plant_from_args(args: argparse.Namespace, *, start: str = "upright", **overrides: float) -> Plant:
    """The plant section of a run: ``--pendulum``, ``--cart``, ``--calibration`` (and parameter overrides)."""
    calibration = getattr(args, "calibration", None)
    return Plant(pendulum=args.pendulum, cart=args.cart, calibration=str(calibration) if calibration else None,
                 overrides=overrides, start=start)


def plant_parameters_from_args(args: argparse.Namespace) -> PlantParameters:
    """Parameters of the preset named by the options, with the calibration file applied."""
    return plant_from_args(args).parameters()


def add_controller_options(parser: argparse.ArgumentParser) -> None:
    """The controller flags: kernel, compensators, PID, a controller file or the demo controller."""
    given = parser.add_argument_group("controller (kernel G1 and compensators G2..G6)")
    given.add_argument("--zeros", metavar="LIST", help="kernel zeros, e.g. '-3,-6' or '-2+1j,-2-1j' ('' for none)")
    given.add_argument("--poles", metavar="LIST", help="kernel poles, e.g. '-30,-0.1'")
    given.add_argument("--gain", metavar="K", help="kernel gain")
    given.add_argument("--compensator", action="append", default=[], metavar="ZEROS;POLES[;GAIN]",
                       help="add a compensator (repeatable), e.g. '-2;-20'")
    given.add_argument("--pid", metavar="KP,KI,KD",
                       help="PID controller Kp + Ki/(s+1/Ti) + Kd*wf*s/(s+wf) as the kernel; alone it cannot balance the pendulum, "
                            "in series with an unstable pole it can: --pid 300,100,100 --compensator 'none;4'")
    given.add_argument("--controller", metavar="FILE", help="controller file (TOML or JSON)")
    given.add_argument("--demo", action="store_true", help="the demo controller: one design that balances both pendulums")


def controller_from_args(args: argparse.Namespace) -> Any | None:
    """The controller the flags describe, or None when none was given."""
    from pendulab.control.entry import controller_from_options

    return controller_from_options(zeros=args.zeros, poles=args.poles, gain=args.gain, compensators=args.compensator,
                                   pid=args.pid, file=args.controller, demo=args.demo, pendulum=args.pendulum)


def add_overwrite_option(parser: argparse.ArgumentParser) -> None:
    """``--overwrite``: replace an earlier result at the output path (refused without it; see :mod:`pendulab.outputs`)."""
    parser.add_argument("--overwrite", action="store_true",
                        help="replace an earlier result at the output path (its files are removed first; without this, refused)")


def add_mode_options(parser: argparse.ArgumentParser, *, start: bool = True) -> None:
    """The supervisor's modes: ``--recentre``, ``--swing-up`` (and ``--start`` where the start pose is chosen)."""
    modes = parser.add_argument_group("supervisor modes")
    modes.add_argument("--recentre", action="store_true",
                       help="re-centre the cart: a slow outer loop on the cart position acts through the controller's "
                            "reference r before the cart nears the track limit (off by default, as in the old lab)")
    modes.add_argument("--swing-up", action="store_true",
                       help="swing the pendulum up from hanging and hand it to the controller inside the catch window")
    if start:
        modes.add_argument("--start", choices=("upright", "hanging"), default="upright",
                           help="the pendulum at t = 0 (default upright; hanging needs --swing-up)")


def check_baud(baud: int) -> None:
    """``--baud`` is a positive whole number of bits per second (UserError otherwise)."""
    if not baud > 0:
        raise UserError(f"--baud {baud} must be a positive number of bits per second, e.g. 1000000 (the rig's default)")
