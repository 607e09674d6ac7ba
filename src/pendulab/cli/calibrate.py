"""``pendulab calibrate``: the ramp test, friction extraction and the calibration file (SPEC §8)."""

from __future__ import annotations

import argparse
import dataclasses
import datetime as _dt
import math
import sys
from pathlib import Path

from pendulab.cli.options import add_overwrite_option, check_baud
from pendulab.errors import CalibrationError
from pendulab.hil.protocol import DEFAULT_MAX_DELAY
from pendulab.model.parameters import CARTS, FRICTION_NAMES, PlantParameters
from pendulab.outputs import check_output_file


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "calibrate",
        help="run the friction ramp test and write a calibration file",
        description=(
            "Ramp test with the pendulum removed: centre the cart, ramp the voltage slowly in both directions "
            "until the cart breaks away, release, probe; extract the friction vector [F1, v1, F2, v2, B] "
            "(forces scaled by the mass ratio for the pendulum's weight), average it over the iterations and "
            "write it as a calibration file."
        ),
    )
    parser.add_argument("--virtual", action="store_true", help="run against the virtual rig (the plant FMU without the pendulum)")
    parser.add_argument("--port", metavar="PORT", help="run on the rig at this serial port or pyserial URL (COM3, /dev/ttyACM0, socket://HOST:PORT)")
    parser.add_argument("--baud", type=int, default=1_000_000, metavar="BAUD", help="--port: baud rate (default 1000000)")
    parser.add_argument("--delay", type=int, metavar="N", help="--port: transport delay in periods (default: measured)")
    parser.add_argument("--max-delay", type=int, default=DEFAULT_MAX_DELAY, metavar="N",
                        help=f"--port: largest delay to accept when measuring (default {DEFAULT_MAX_DELAY})")
    parser.add_argument("--iterations", type=_positive_int, default=5, metavar="N", help="iterations, each in both directions (default 5)")
    parser.add_argument(
        "--friction", metavar="F1,v1,F2,v2,B", type=_friction,
        help="the virtual rig's true friction vector (N, m/s, N, m/s, kg/s); default the lab table",
    )
    parser.add_argument("--pendulum", default="long", choices=("long", "short", "none"), help="pendulum the file is for: sets the mass ratio (default long)")
    parser.add_argument("--cart", default="ip02", choices=CARTS, help="cart (default ip02, no load)")
    parser.add_argument("--out", metavar="FILE", help="calibration file to write (default calibration/<date>-<rig>.json)")
    parser.add_argument("--log", metavar="CSV", help="also save the ramp-test log (t, V, x) for 'pendulab fit'")
    parser.add_argument("--x0", type=float, default=0.05, metavar="M", help="virtual rig: where the cart starts (default 0.05 m)")
    add_overwrite_option(parser)
    parser.add_argument("--backend", default="auto", choices=("auto", "fmu", "casadi"), help=argparse.SUPPRESS)
    parser.set_defaults(func=run)


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} must be at least 1")
    return value


def _friction(text: str) -> tuple[float, ...]:
    from pendulab.calibration.files import Calibration

    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 5:
        raise argparse.ArgumentTypeError(f"{text!r} needs 5 numbers F1,v1,F2,v2,B (got {len(parts)})")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not 5 comma-separated numbers F1,v1,F2,v2,B") from None
    try:
        Calibration(values)  # the same checks as a calibration file (>= 0, v1 <= v2, F1 <= F2)
    except CalibrationError as exc:
        raise argparse.ArgumentTypeError(str(exc).replace("calibration: ", "")) from None
    return values


def run(args: argparse.Namespace) -> int:
    from pendulab.calibration.extract import extract_friction, mass_ratio
    from pendulab.calibration.files import save_calibration
    from pendulab.calibration.logs import write_log
    from pendulab.calibration.ramp import RampSettings, run_ramp_test
    from pendulab.hil.realtime import EndingSignals

    if args.virtual == bool(args.port):
        raise CalibrationError("give the rig: --port PORT for the real rig (or 'pendulab rig-emulator'), or --virtual for the virtual rig")
    if args.port and args.friction:
        raise CalibrationError("--friction sets the virtual rig's friction; the real rig has its own (drop --friction or use --virtual)")
    from pendulab.hil.protocol import MAX_DELAY

    if args.port:
        check_baud(args.baud)
    if args.delay is not None and not 1 <= args.delay <= MAX_DELAY:
        raise CalibrationError(f"--delay {args.delay} must be 1 to {MAX_DELAY} periods")
    if not 1 <= args.max_delay <= MAX_DELAY:
        raise CalibrationError(f"--max-delay {args.max_delay} must be 1 to {MAX_DELAY} periods")
    limit = RampSettings().track_limit
    if not (math.isfinite(args.x0) and abs(args.x0) < limit):
        raise CalibrationError(f"--x0 {args.x0} must be a position on the track, between {-limit:g} and {limit:g} m (the virtual cart starts there)")
    from pendulab.calibration.rig import VirtualRig

    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    out = args.out if args.out is not None else Path("calibration") / f"{stamp}-{'rig' if args.port else 'virtual'}.json"
    out = check_output_file(out, "--out", suffixes=(".json",), overwrite=args.overwrite)
    # On the rig the log always streams to disk (a ramp test is expensive to repeat): beside the
    # calibration when --log is not given.
    log_path = args.log if args.log is not None else (out.with_name(out.stem + "-log.csv") if args.port else None)
    if log_path is not None:
        log_path = check_output_file(log_path, "--log", suffixes=(".csv",), overwrite=args.overwrite)
    nominal = PlantParameters.preset(pendulum="none", cart=args.cart)
    ratio = mass_ratio(PlantParameters.preset(pendulum=args.pendulum, cart=args.cart))
    true = nominal.with_values(**dict(zip(FRICTION_NAMES, args.friction))) if args.friction else nominal

    def announce(i: int, n: int) -> None:
        print(f"iteration {i}/{n}: centring, ramps in both directions, probes", flush=True)

    def note(text: str) -> None:
        print(f"  {text}", flush=True)

    with EndingSignals() as ending:
        if args.port:
            log, rig_text = _ramp_test_on_the_rig(args, log_path, announce, note)  # type: ignore[arg-type]
            true_friction = None
        else:
            with VirtualRig(true, x0=args.x0, backend=args.backend, progress=lambda text: print(text, flush=True)) as rig:
                print(f"ramp test on the {rig.description}, {args.iterations} iteration(s) (Ctrl-C stops and keeps what was measured)", flush=True)
                log = run_ramp_test(rig, iterations=args.iterations, on_iteration=announce, on_progress=note)
            rig_text = "virtual rig (plant FMU, pendulum removed)" if rig.backend == "fmu" else "virtual rig (CasADi plant, pendulum removed)"
            true_friction = dict(zip(FRICTION_NAMES, true.friction))
        # What was measured is written even when a signal arrives now; the signal then sets the status.
        ending.disarm()
        if log_path is not None and not args.port:
            write_log(log, log_path)
        if log_path is not None:
            print(f"log written to {log_path}" + (f" ({len(log.t)} samples, streamed while measuring)" if args.port else ""), flush=True)
        status = 0
        if log.interrupted and log.iterations_done == args.iterations:
            # Every iteration had finished (the test was ending, centring the cart): a complete calibration.
            print(f"note: the test ended after its last iteration ({log.end_reason}); the calibration is complete", flush=True)
            log = dataclasses.replace(log, interrupted=False)
        if log.interrupted:
            status = 128 + ending.received if ending.received else (130 if log.end_reason == "interrupted (Ctrl-C)" else 1)
            if not log.iterations_done:
                kept = f"; the log is kept in {log_path}" if log_path is not None else ""
                print(f"ended early: {log.end_reason}; no iteration finished, so no calibration was written{kept}", flush=True)
                return status
            log = log.between(log.t[0], log.iterations_done_at + 0.5 * log.period)
        try:
            estimate = extract_friction(log, mass_ratio=ratio, params=nominal)
        except CalibrationError as exc:
            kept = f"; the log is kept in {log_path}" if log_path is not None else ""
            raise CalibrationError(f"{exc}{kept}") from None
        print(f"friction vector for the {args.pendulum} pendulum (mass ratio {ratio:.3f}), mean ± spread over the iterations:")
        print(estimate.summary())
        for text in estimate.notes:
            print(f"note: {text}")
        partial = {"partial": True, "iterations_planned": args.iterations, "end_reason": log.end_reason} if log.interrupted else {}
        calibration = estimate.to_calibration(
            date=_dt.datetime.now().isoformat(timespec="seconds"),
            rig=rig_text,
            **({"rig_true_friction": true_friction} if true_friction else {}),
            iterations=log.iterations_done if log.interrupted else args.iterations,
            interrupted=log.interrupted,
            **partial,
            **({"log": str(log_path)} if log_path is not None else {}),
            pendulum=args.pendulum,
            cart=args.cart,
        )
        save_calibration(calibration, out)
        if log.interrupted:
            print(f"PARTIAL calibration written to {out}: from the {log.iterations_done} of {args.iterations} iteration(s) "
                  f"finished before the test ended ({log.end_reason})", flush=True)
        else:
            print(f"calibration written to {out}")
    return status


def _ramp_test_on_the_rig(args: argparse.Namespace, log_path: Path, announce, note):  # -> (RampLog, str)
    """The ramp test over the link, with lab's real-time measures; the log streams to ``log_path`` on every ending."""
    from pendulab.analysis.results import RunLog
    from pendulab.calibration.ramp import run_ramp_test
    from pendulab.hil.link import LinkLost, RigLink
    from pendulab.hil.realtime import no_garbage_collection, raise_priority
    from pendulab.hil.rig import LOG_COLUMNS, HilRig
    from pendulab.hil.session import choose_delay

    with RigLink.open(args.port, args.baud) as link:
        identity = link.identify()
        print(f"rig at {args.port}: firmware {identity.fw_major}.{identity.fw_minor}.{identity.fw_patch}, boot id {identity.boot_id:#010x}", flush=True)
        priority = raise_priority()  # before the delay is measured: the test runs at this priority
        try:
            delay = args.delay or choose_delay(link, args.max_delay, announce=lambda text: print(text, flush=True))
            link.configure(delay=delay, x_limit=0.40)
            print(f"transport delay N = {delay} ({priority}); pendulum removed and cart centred by hand? zeroing the encoders here", flush=True)
            link.zero()
        except LinkLost as exc:
            raise CalibrationError(f"{exc} (while setting up the ramp test)") from None
        stream = RunLog(log_path, LOG_COLUMNS, flush_every=10)
        try:
            with HilRig(link, log=stream) as rig, no_garbage_collection():
                print(f"ramp test on the {rig.description}, {args.iterations} iteration(s) (Ctrl-C stops and keeps what was measured); "
                      f"the log streams to {log_path}", flush=True)
                log = run_ramp_test(rig, iterations=args.iterations, on_iteration=announce, on_progress=note)
                log = dataclasses.replace(log, V=rig.acting_voltages(len(log.t)))
        finally:
            stream.close()
    if log.interrupted:
        print(f"motor off; the ramp test ended early: {log.end_reason}", flush=True)
    return log, f"rig at {args.port} (boot id {identity.boot_id:#010x})"


if __name__ == "__main__":  # pragma: no cover
    from pendulab.cli.main import main

    sys.exit(main(["calibrate", *sys.argv[1:]]))
