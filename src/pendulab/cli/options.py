"""Command-line options shared by several subcommands."""

from __future__ import annotations

import argparse
from typing import Any

from pendulab.errors import UserError
from pendulab.model.parameters import CARTS, PlantParameters


def add_plant_options(parser: argparse.ArgumentParser, *, pendulums: tuple[str, ...] = ("long", "short")) -> None:
    """``--pendulum``, ``--cart`` and ``--calibration``."""
    parser.add_argument("--pendulum", default="long", metavar="|".join(pendulums), help="pendulum (default long)")
    parser.add_argument("--cart", default="ip02", metavar="|".join(CARTS), help="cart (default ip02, no load)")
    parser.add_argument("--calibration", metavar="FILE", help="calibration file (JSON, or the old lab's .mat)")


def plant_parameters_from_args(args: argparse.Namespace) -> PlantParameters:
    """Parameters of the preset named by the options, with the calibration file applied."""
    params = PlantParameters.preset(pendulum=args.pendulum, cart=args.cart)
    if getattr(args, "calibration", None):
        from pendulab.calibration.files import load_calibration

        params = load_calibration(args.calibration).apply(params)
    return params


def add_controller_options(parser: argparse.ArgumentParser) -> None:
    """The controller flags: kernel, compensators, PID, a controller file or the demo controller."""
    given = parser.add_argument_group("controller (kernel G1 and compensators G2..G6)")
    given.add_argument("--zeros", metavar="LIST", help="kernel zeros, e.g. '-3,-6' or '-2+1j,-2-1j' ('' for none)")
    given.add_argument("--poles", metavar="LIST", help="kernel poles, e.g. '-30,-0.1'")
    given.add_argument("--gain", metavar="K", help="kernel gain")
    given.add_argument("--compensator", action="append", default=[], metavar="ZEROS;POLES[;GAIN]",
                       help="add a compensator (repeatable), e.g. '-2;-20'")
    given.add_argument("--pid", metavar="KP,KI,KD", help="PID controller Kp + Ki/(s+1/Ti) + Kd*wf*s/(s+wf)")
    given.add_argument("--controller", metavar="FILE", help="controller file (TOML or JSON)")
    given.add_argument("--demo", action="store_true", help="a good default controller for the chosen pendulum")


def controller_from_args(args: argparse.Namespace) -> Any | None:
    """The controller the flags describe, or None when none was given."""
    from pendulab import control as ctl

    sources = [
        name
        for name, present in (
            ("--zeros/--poles/--gain", args.zeros is not None or args.poles is not None or args.gain is not None),
            ("--pid", args.pid is not None),
            ("--controller", args.controller is not None),
            ("--demo", args.demo),
        )
        if present
    ]
    if len(sources) > 1:
        raise UserError(f"give one controller, not {' and '.join(sources)}")
    if args.compensator and not (args.zeros is not None or args.poles is not None or args.gain is not None or args.controller or args.demo):
        raise UserError("--compensator needs a kernel: give --zeros, --poles and --gain (or --controller FILE)")
    if args.demo:
        base = ctl.demo_controller(args.pendulum)
    elif args.controller:
        base = ctl.load_controller_file(args.controller)
    elif args.pid is not None:
        parts = args.pid.split(",")
        try:
            kp, ki, kd = (float(p) for p in parts)
        except ValueError:
            raise UserError(f"--pid {args.pid!r} must be three numbers KP,KI,KD, e.g. --pid 40,5,4") from None
        return ctl.Controller.pid(kp, ki, kd)
    elif args.zeros is not None or args.poles is not None or args.gain is not None:
        if args.gain is None:
            raise UserError("the kernel needs a gain: add --gain K")
        # Kernel and numbered compensators, so that an error names the factor it is about.
        return ctl.parse_controller(args.zeros or "", args.poles or "", args.gain, args.compensator)
    else:
        return None
    if args.compensator:
        first = len(base.factors)
        extra = [ctl.parse_compensator(c, f"compensator {first + i}") for i, c in enumerate(args.compensator)]
        base = ctl.Controller([*base.factors, *extra])
    return base




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
