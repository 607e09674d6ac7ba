"""``pendulab rig-emulator``: a rig on a pseudo-terminal (Plant.fmu speaking the rig protocol in real time)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

from pendulab.cli.options import add_plant_options, plant_from_args
from pendulab.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "rig-emulator",
        help="a virtual rig on a serial port (pseudo-terminal), for 'pendulab lab' without hardware",
        description=(
            "Run Plant.fmu behind a pseudo-terminal, speaking the rig protocol (docs/protocol.md) in real time, with "
            "the rig's watchdog and track limits. Prints the port's path alone on the first line of stdout, then runs "
            "until stopped (Ctrl-C); every change of state is one line on stderr. The pendulum hangs down at start."
        ),
        epilog=(
            "examples:\n"
            "  pendulab rig-emulator --raise-after 2 --poke 220,0.005,1\n"
            "  pendulab rig-emulator --latency 1 --jitter 0.3          # a USB-serial bridge\n"
            "  pendulab rig-emulator --pendulum none --friction 2,0.004,3.5,0.04,25   # for 'pendulab calibrate --port'\n"
            "  pendulab rig-emulator --tcp 5555                        # serve socket://127.0.0.1:5555 (Windows)\n"
            "  pendulab rig-emulator --plant seesaw --raise-after 0.3 --poke 3.3,0.1,1   # the seesaw, tapped 1 s after the start"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_plant_options(parser, pendulums=("long", "short", "none"))
    parser.add_argument("--plant", choices=("pendulum", "seesaw"), default="pendulum",
                        help="the rig (default pendulum); seesaw: Seesaw.fmu, its tilt on the pendulum encoder's channel "
                             "(3 x 4096 counts per turn: the 3:1 gear), resting on its tilt stop until the hand lifts it level")
    parser.add_argument("--friction", metavar="F1,v1,F2,v2,B", help="the rig's true friction vector (overrides the calibration)")
    person = parser.add_argument_group("what a person does")
    person.add_argument("--raise-after", type=float, metavar="S",
                        help="raise the pendulum (lift the seesaw level) by hand S s after the host connects (held until the motor is enabled)")
    person.add_argument("--poke", metavar="MAG,DUR,START",
                        help="poke (the seesaw: tap) (rad/s^2, s, s); START counts from the moment the controller takes the pendulum")
    link = parser.add_argument_group("what a real link and rig do")
    link.add_argument("--latency", type=float, default=0.0, metavar="MS", help="added host->rig latency in ms (default 0)")
    link.add_argument("--jitter", type=float, default=0.0, metavar="MS", help="uniform +- jitter on that latency in ms")
    link.add_argument("--byte-error-rate", type=float, default=0.0, metavar="P", help="probability of a bit flip in each byte, both directions")
    link.add_argument("--restart-after", type=float, metavar="S", help="reset the firmware (new boot id) S s after the host connects")
    link.add_argument("--stall-after", type=float, metavar="S", help="stall the link S s after the host connects")
    link.add_argument("--stall-for", type=float, default=0.5, metavar="S", help="length of the stall (default 0.5 s)")
    link.add_argument("--close-after", type=float, metavar="S", help="close the port S s after the host connects")
    link.add_argument("--fault-after", type=float, metavar="S", help="report an amplifier fault S s after the host connects")
    link.add_argument("--dead-encoder", action="append", default=[], metavar="WHICH,S",
                      help="the cart or pendulum encoder dies (power or cable lost: no more counts) S s after the host connects")
    link.add_argument("--frozen-encoder", action="append", default=[], metavar="WHICH,S",
                      help="the cart or pendulum encoder's count freezes S s after the host connects")
    parser.add_argument("--tcp", type=int, metavar="PORT", help="serve one host on TCP 127.0.0.1:PORT instead of a pty (prints socket://...)")
    parser.add_argument("--firmware", nargs="?", const="", metavar="HEX",
                        help="run the real firmware in simavr with the digital twin (pendulum or seesaw) instead (default: the .hex 'make -C firmware' builds)")
    parser.add_argument("--seed", type=int, help="random seed (byte errors, jitter, boot id)")
    parser.set_defaults(func=run)


def _non_negative(value: float | None, option: str) -> None:
    if value is not None and not (math.isfinite(value) and value >= 0):
        raise UserError(f"{option} {value} must be a number >= 0")


def encoder_faults(dead: list[str], frozen: list[str]) -> dict[str, tuple[str, float]]:
    """``--dead-encoder`` / ``--frozen-encoder`` values (``WHICH,S``) as ``{which: (kind, after)}``."""
    faults: dict[str, tuple[str, float]] = {}
    for kind, values in (("dead", dead), ("frozen", frozen)):
        for text in values:
            which, _, after = text.partition(",")
            try:
                seconds = float(after)
            except ValueError:
                seconds = float("nan")
            if which not in ("cart", "pendulum") or not (math.isfinite(seconds) and seconds >= 0):
                raise UserError(f"--{kind}-encoder {text!r} must be cart or pendulum and a time >= 0 in s, e.g. --{kind}-encoder pendulum,3")
            if which in faults:
                raise UserError(f"the {which} encoder is given two faults; give one")
            faults[which] = (kind, seconds)
    return faults


def emulator_options(args: argparse.Namespace):  # -> EmulatorOptions
    """The emulator's options from the parsed command line (also used by tests)."""
    from pendulab.cli.simulate import parse_poke
    from pendulab.hil.emulator import EmulatorOptions

    for option in ("raise_after", "latency", "jitter", "restart_after", "stall_after", "stall_for", "close_after", "fault_after"):
        _non_negative(getattr(args, option), "--" + option.replace("_", "-"))
    if not 0 <= args.byte_error_rate < 0.5:
        raise UserError(f"--byte-error-rate {args.byte_error_rate} must be a probability from 0 to below 0.5, e.g. 1e-3")
    friction = {}
    if args.friction:
        from pendulab.cli.calibrate import _friction

        try:
            friction = dict(zip(("F1", "v1", "F2", "v2", "B"), _friction(args.friction)))
        except argparse.ArgumentTypeError as exc:
            raise UserError(f"--friction {exc}") from None
    if args.plant == "seesaw":
        from pendulab.spec import Plant

        if args.pendulum != "long":
            raise UserError(f"--pendulum {args.pendulum} is the pendulum rig's; the seesaw has none: drop it")
        plant = Plant(kind="seesaw", cart=args.cart, calibration=str(args.calibration) if args.calibration else None,
                      overrides=friction)
    else:
        plant = plant_from_args(args, **friction)
    return EmulatorOptions(
        encoder_faults=encoder_faults(args.dead_encoder, args.frozen_encoder),
        params=plant.parameters(),
        plant=args.plant,
        raise_after=args.raise_after,
        poke=parse_poke(args.poke) if args.poke else None,
        latency=args.latency / 1000.0,
        jitter=args.jitter / 1000.0,
        byte_error_rate=args.byte_error_rate,
        restart_after=args.restart_after,
        stall_after=args.stall_after,
        stall_for=args.stall_for,
        close_after=args.close_after,
        fault_after=args.fault_after,
        seed=args.seed,
    )


def run(args: argparse.Namespace) -> int:
    options = emulator_options(args)
    if args.firmware is not None:
        try:
            from pendulab.hil.firmware import run_twin
        except ImportError:
            raise UserError("--firmware needs the firmware twin (pendulab.hil.firmware), which this installation lacks") from None
        if args.tcp is not None:
            raise UserError("--tcp is not available with --firmware (the twin's link is the firmware's own UART); drop it")
        return run_twin(Path(args.firmware) if args.firmware else None, options)
    if args.tcp is not None and not 0 <= args.tcp <= 65535:
        raise UserError(f"--tcp {args.tcp} must be a TCP port from 1 to 65535 (or 0 for any free port), e.g. --tcp 5555")
    if sys.platform == "win32" and args.tcp is None:
        raise UserError("pseudo-terminals do not exist on Windows: use --tcp PORT and 'pendulab lab --port socket://127.0.0.1:PORT'")
    from pendulab.hil.emulator import RigEmulator
    from pendulab.hil.realtime import EndingSignals, Terminated, raise_priority

    emulator = RigEmulator(options)
    emulator.say(f"scheduling: {raise_priority()}")
    # SIGTERM (SIGHUP) stops the emulator in every state: waiting for a client too (raised, not a flag).
    with EndingSignals():
        try:
            return _serve(args, emulator)
        except KeyboardInterrupt as exc:
            emulator.say(f"emulator stopped ({'Ctrl-C' if not isinstance(exc, Terminated) else exc.signal})")
            return 0


def _serve(args: argparse.Namespace, emulator: Any) -> int:
    listener = None
    try:
        if args.tcp is not None:
            import socket

            try:
                listener = socket.create_server(("127.0.0.1", args.tcp))
            except OSError as exc:
                raise UserError(f"--tcp {args.tcp}: cannot listen on 127.0.0.1:{args.tcp} ({exc.strerror or exc}); choose another port") from None
            print(f"socket://127.0.0.1:{listener.getsockname()[1]}", flush=True)
            connection, _ = listener.accept()
            connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            emulator.use_socket(connection)
        else:
            print(emulator.open_pty(), flush=True)
        emulator.say("rig emulator ready: " + ("seesaw on its tilt stop" if args.plant == "seesaw" else "pendulum hanging")
                     + ", cart centred, motor off")
        why = emulator.run()
        emulator.say(f"emulator ends ({why})")
    finally:
        emulator.close()
        if listener is not None:
            listener.close()
    return 0
