"""``pendulab lab``: run your controller on the rig (or the rig emulator) over the serial link."""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

from pendulab.cli.options import (
    add_controller_options,
    add_overwrite_option,
    add_plant_options,
    check_baud,
    controller_from_args,
    plant_from_args,
)
from pendulab.errors import UserError
from pendulab.hil.protocol import DEFAULT_MAX_DELAY
from pendulab.outputs import run_folder


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "lab",
        help="run your controller on the rig over the serial link (hardware in the loop)",
        description=(
            "Connect to the rig (or 'pendulab rig-emulator'), then run the same Controller.fmu and Supervisor.fmu as in "
            "simulation with the rig as the plant, clocked by the rig. Keys while running: s start, p pause, e end, "
            "r re-arm after a trip (single keys on a terminal, or lines on stdin when scripted). The log streams to "
            "DIR/rig_log.csv; at the end DIR holds run.mat, run.csv, metrics.json and timing.json."
        ),
        epilog=(
            "examples:\n"
            "  pendulab lab --port COM3 --demo\n"
            "  pendulab lab --port /dev/ttyACM0 --controller my_controller.toml --plot --compare\n"
            "  pendulab lab --port socket://labpc7:5555 --pid 300,100,100 --compensator 'none;4' --stop-time 30\n"
            "  pendulab lab --port /dev/ttyACM0 --plant seesaw --demo     # hold the seesaw level, press s, let go"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--port", required=True, metavar="PORT", help="the rig's serial port or pyserial URL (COM3, /dev/ttyACM0, socket://HOST:PORT)")
    parser.add_argument("--baud", type=int, default=1_000_000, metavar="BAUD", help="baud rate (default 1000000)")
    add_controller_options(parser)
    from pendulab.cli.options import add_mode_options

    add_mode_options(parser, start=False)
    add_plant_options(parser)
    parser.add_argument("--plant", choices=("pendulum", "seesaw"), default="pendulum",
                        help="the rig (default pendulum); the seesaw runs a state feedback: --demo (Quanser's LQR) or "
                             "--controller FILE from 'pendulab lqr --plant seesaw --out FILE'")
    parser.add_argument("--delay", type=int, metavar="N", help="transport delay in periods (default: measured at connection)")
    parser.add_argument("--max-delay", type=int, default=DEFAULT_MAX_DELAY, metavar="N", help=f"largest delay to accept when measuring (default {DEFAULT_MAX_DELAY})")
    parser.add_argument("--stop-time", type=float, metavar="T", help="end the session by itself T s after streaming starts")
    parser.add_argument("--method", choices=("tustin", "zoh"), default="tustin", help="discretization (default tustin)")
    parser.add_argument("--out", type=Path, metavar="DIR", help="run folder (default: a new folder under runs/)")
    add_overwrite_option(parser)
    parser.add_argument("--plot", action="store_true", help="also write PNG plots")
    parser.add_argument("--compare", action="store_true", help="also simulate the same controller at the same delay and write the comparison")
    parser.add_argument("--poke", metavar="MAG,DUR,START", help="the poke (the seesaw: tap) to simulate for --compare (default 50,0.005,1; the seesaw's 3.3,0.1,1; the rig's is detected)")
    parser.set_defaults(func=run)


def check_rig_plant(counts_per_rad: float, *, seesaw: bool, port: str) -> None:
    """Refuse (UserError) a rig whose angle channel is the other plant's encoder.

    The seesaw's pivot encoder sits on the pendulum's channel behind a 3:1 gear: its rig says so in the IDENTITY,
    3 x 4096 counts per turn (the firmware's seesaw jumper, or ``rig-emulator --plant seesaw``).

    Examples
    --------
    >>> check_rig_plant(1955.7, seesaw=True, port="COM3")
    >>> check_rig_plant(651.9, seesaw=True, port="COM3")
    Traceback (most recent call last):
    pendulab.errors.UserError: the rig at COM3 reads its angle at 651.9 counts per rad, the pendulum's encoder; the seesaw's is ...
    >>> check_rig_plant(1955.7, seesaw=False, port="COM3")
    Traceback (most recent call last):
    pendulab.errors.UserError: the rig at COM3 is the seesaw (1955.7 counts per rad on its angle channel: ...
    """
    from pendulab.model.seesaw import SEESAW_COUNT

    on_seesaw = abs(counts_per_rad * SEESAW_COUNT - 1.0) < 0.01
    if seesaw and not on_seesaw:
        raise UserError(f"the rig at {port} reads its angle at {counts_per_rad:.1f} counts per rad, the pendulum's encoder; the seesaw's "
                        f"is {1 / SEESAW_COUNT:.1f} (3 x 4096 per turn behind its 3:1 gear): fit the seesaw's jumper (firmware/README.md) "
                        "or run --plant pendulum")
    if on_seesaw and not seesaw:
        raise UserError(f"the rig at {port} is the seesaw ({counts_per_rad:.1f} counts per rad on its angle channel: the pivot encoder "
                        "behind the 3:1 gear); run 'pendulab lab --plant seesaw', or remove the seesaw's jumper on a pendulum rig")


def run(args: argparse.Namespace) -> int:
    if args.stop_time is not None and not (math.isfinite(args.stop_time) and args.stop_time > 0):
        raise UserError(f"--stop-time {args.stop_time} must be a positive number of seconds")
    from pendulab.hil.protocol import MAX_DELAY

    if args.delay is not None and not 1 <= args.delay <= MAX_DELAY:
        raise UserError(f"--delay {args.delay} must be 1 to {MAX_DELAY} periods (the answer to sample k is applied at tick k + N)")
    if not 1 <= args.max_delay <= MAX_DELAY:
        raise UserError(f"--max-delay {args.max_delay} must be 1 to {MAX_DELAY} periods")
    seesaw = args.plant == "seesaw"
    controller = None if seesaw else controller_from_args(args)
    if controller is None and not seesaw:
        if not sys.stdin.isatty():
            raise UserError("no controller given: use --demo, --zeros/--poles/--gain, --pid or --controller FILE (or run on a terminal to be asked)")
        from pendulab.control.prompt import prompt_controller

        controller = prompt_controller()
    from pendulab.spec import Poke, RunSpec, Supervisor, Timing

    # The poke is the one --compare simulates (the rig's is detected); the supervisor waits for 's' and
    # reads the rig's encoder (0 hanging down).
    if seesaw:
        from pendulab.cli.simulate import seesaw_spec_from_args

        # The same loop as simulated; the supervisor waits for 's' (the seesaw held level) and reads the tilt as it
        # is (no rig_mode: its encoder reads 0 level, not the pendulum's 0 hanging).
        spec = seesaw_spec_from_args(args, Timing(method=args.method), Poke.parse(args.poke) if args.poke else None)
        spec = spec.replace(supervisor=Supervisor(auto_start=False)).validate()
    else:
        spec = RunSpec(controller, plant=plant_from_args(args), poke=Poke.parse(args.poke) if args.poke else Poke(),
                       timing=Timing(method=args.method),
                       supervisor=Supervisor(rig_mode=True, auto_start=False, recentre=args.recentre, swing_up=args.swing_up)).validate()
    params = spec.parameters()
    Lp = getattr(params, "Lp", 0.0)  # (the seesaw has no pendulum: no tip column)
    check_baud(args.baud)
    folder = run_folder(args.out, "lab-seesaw" if seesaw else f"lab-{args.pendulum}", overwrite=args.overwrite)
    out_dir = folder.path

    from pendulab.hil.keys import KeySource
    from pendulab.hil.link import LinkLost, RigLink
    from pendulab.hil.session import LabSession, choose_delay, write_lab_results
    from pendulab.simulation import build_system, run_meta

    def say(text: str) -> None:
        print(text, flush=True)

    from pendulab.hil.realtime import EndingSignals

    # SIGTERM/SIGHUP end the session as the end key does (motor off, reason recorded, results written).
    with EndingSignals() as ending:
        with RigLink.open(args.port, args.baud) as link:
            identity = link.identify()
            period = identity.period_us * 1e-6
            say(f"rig at {args.port}: protocol {identity.protocol}, firmware {identity.fw_major}.{identity.fw_minor}.{identity.fw_patch}, "
                f"boot id {identity.boot_id:#010x}, period {identity.period_us} us")
            check_rig_plant(identity.pend_counts_per_rad, seesaw=seesaw, port=args.port)
            # The controller is realized before anything moves: a controller the rules refuse never enables the motor.
            # The rig's own transport delay is physical: the system has none (timing.delay = 0 here).
            spec = spec.replace(timing=Timing(stop_time=spec.poke.start + 4.0, step=period, method=args.method)).validate()
            system = build_system(spec, params)
            from pendulab.hil.realtime import raise_priority

            priority = raise_priority()  # before the delay is measured: the session runs at this priority
            round_trips = link.round_trips()
            try:
                if args.delay is None:
                    delay = choose_delay(link, args.max_delay, announce=say)
                else:
                    delay = args.delay
                x_limit = float(system.components["supervisor"].start_values.get("x_max", 0.40)) + 0.03
                link.configure(delay=delay, x_limit=x_limit)
                link.zero()
            except LinkLost as exc:
                raise UserError(f"{exc} (while setting up the session)") from None
            pose = "seesaw held level" if seesaw else "pendulum hanging"
            say(f"transport delay N = {delay} ({priority}); encoders zeroed ({pose}, cart centred); log streams to {out_dir / 'rig_log.csv'}")
            folder.prepare(announce=say)
            with KeySource() as keys:
                session = LabSession(link, system, out_dir=out_dir, keys=keys, Lp=Lp, stop_time=args.stop_time, announce=say,
                                     priority=priority)
                reason, status = session.run()
        ending.disarm()  # the session has ended: its files are written whatever arrives now
        # As simulated: the rig's delay, the supervisor as in simulation (for --compare and the files' meta).
        spec = spec.replace(timing=dataclasses.replace(spec.timing, delay=delay),
                            supervisor=Supervisor() if seesaw else Supervisor(recentre=args.recentre, swing_up=args.swing_up))
        meta = {**run_meta(spec, params), "recentre": bool(args.recentre), "swing_up": bool(args.swing_up),
                "port": args.port, "rig_boot_id": identity.boot_id}
        metrics, timing = write_lab_results(session, Lp=Lp, q_alpha=1.0 / identity.pend_counts_per_rad, meta=meta, round_trips=round_trips)
        if args.plot:
            from pendulab.analysis.plots import plot_run
            from pendulab.analysis.results import read_run

            columns, _ = read_run(out_dir)
            plot_run(columns, out_dir, title="rig, seesaw" if seesaw else f"rig, {args.pendulum} pendulum",
                     poke_start=metrics.get("poke_start_detected_s") or 0.0)
        if args.compare:
            from pendulab.analysis.compare import compare_with_simulation

            compare_with_simulation(out_dir, spec, metrics=metrics)
        lat = timing["answer_latency_ms"]
        say(f"session: {timing['samples']} samples, answer latency p50 {lat['p50'] or 0:.3f} ms, p99 {lat['p99'] or 0:.3f} ms, "
            f"{timing['late_commands']} late, {timing['missed_samples']} missed, {timing['crc_errors']} CRC errors")
        say(f"results in {out_dir}/ (rig_log.csv, run.mat, run.csv, metrics.json, timing.json); ended: {reason}")
        return status
