"""``pendulab calibrate``: the ramp test, friction extraction and the calibration file (SPEC §8)."""

from __future__ import annotations

import argparse
import dataclasses
import datetime as _dt
import sys
from pathlib import Path

from pendulab.cli.options import add_overwrite_option
from pendulab.errors import CalibrationError
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
    from pendulab.calibration.ramp import run_ramp_test

    if args.virtual == bool(args.port):
        raise CalibrationError("give the rig: --port PORT for the real rig (or 'pendulab rig-emulator'), or --virtual for the virtual rig")
    if args.port and args.friction:
        raise CalibrationError("--friction sets the virtual rig's friction; the real rig has its own (drop --friction or use --virtual)")
    from pendulab.hil.protocol import MAX_DELAY

    if args.delay is not None and not 1 <= args.delay <= MAX_DELAY:
        raise CalibrationError(f"--delay {args.delay} must be 1 to {MAX_DELAY} periods")
    from pendulab.calibration.rig import VirtualRig

    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else Path("calibration") / f"{stamp}-{'rig' if args.port else 'virtual'}.json"
    check_output_file(out, "--out", suffixes=(".json",), overwrite=args.overwrite)
    if args.log:
        check_output_file(args.log, "--log", suffixes=(".csv",), overwrite=args.overwrite)
    nominal = PlantParameters.preset(pendulum="none", cart=args.cart)
    ratio = mass_ratio(PlantParameters.preset(pendulum=args.pendulum, cart=args.cart))
    true = nominal.with_values(**dict(zip(FRICTION_NAMES, args.friction))) if args.friction else nominal

    def announce(i: int, n: int) -> None:
        print(f"iteration {i}/{n}: centring, ramps in both directions, probes", flush=True)

    def note(text: str) -> None:
        print(f"  {text}", flush=True)

    if args.port:
        from pendulab.hil.link import RigLink
        from pendulab.hil.protocol import DEFAULT_MAX_DELAY
        from pendulab.hil.rig import HilRig
        from pendulab.hil.session import choose_delay

        link = RigLink.open(args.port, args.baud)
        try:
            identity = link.identify()
            print(f"rig at {args.port}: firmware {identity.fw_major}.{identity.fw_minor}.{identity.fw_patch}, boot id {identity.boot_id:#010x}", flush=True)
            delay = args.delay or choose_delay(link, DEFAULT_MAX_DELAY, announce=lambda text: print(text, flush=True))
            link.configure(delay=delay, x_limit=0.40)
            print("pendulum removed and cart centred by hand? zeroing the encoders here", flush=True)
            link.zero()
            with HilRig(link) as rig:
                print(f"ramp test on the {rig.description}, {args.iterations} iteration(s) (Ctrl-C stops and keeps what was measured)", flush=True)
                log = run_ramp_test(rig, iterations=args.iterations, on_iteration=announce, on_progress=note)
                log = dataclasses.replace(log, V=rig.acting_voltages(len(log.t)))
            rig_text, true_friction = f"rig at {args.port} (boot id {identity.boot_id:#010x})", None
        finally:
            link.close()
    else:
        with VirtualRig(true, x0=args.x0, backend=args.backend, progress=lambda text: print(text, flush=True)) as rig:
            print(f"ramp test on the {rig.description}, {args.iterations} iteration(s) (Ctrl-C stops and keeps what was measured)", flush=True)
            log = run_ramp_test(rig, iterations=args.iterations, on_iteration=announce, on_progress=note)
        rig_text = "virtual rig (plant FMU, pendulum removed)" if rig.backend == "fmu" else "virtual rig (CasADi plant, pendulum removed)"
        true_friction = dict(zip(FRICTION_NAMES, true.friction))
    if args.log:
        write_log(log, args.log)
        print(f"log written to {args.log}")
    estimate = extract_friction(log, mass_ratio=ratio, params=nominal)
    print(f"friction vector for the {args.pendulum} pendulum (mass ratio {ratio:.3f}), mean ± spread over the iterations:")
    print(estimate.summary())
    for text in estimate.notes:
        print(f"note: {text}")
    calibration = estimate.to_calibration(
        date=_dt.datetime.now().isoformat(timespec="seconds"),
        rig=rig_text,
        **({"rig_true_friction": true_friction} if true_friction else {}),
        iterations=args.iterations,
        interrupted=log.interrupted,
        pendulum=args.pendulum,
        cart=args.cart,
    )
    save_calibration(calibration, out)
    print(f"calibration written to {out}" + (" (from the iterations measured before the interruption)" if log.interrupted else ""))
    return 0


if __name__ == "__main__":  # pragma: no cover
    from pendulab.cli.main import main

    sys.exit(main(["calibrate", *sys.argv[1:]]))
