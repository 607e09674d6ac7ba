"""``pendulab fit``: least-squares refit of friction, Beq and force gain from logs (SPEC §8)."""

from __future__ import annotations

import argparse
import datetime as _dt

from pendulab.cli.options import add_overwrite_option
from pendulab.errors import CalibrationError, FitRejected
from pendulab.model.parameters import CARTS, FRICTION_NAMES, PlantParameters
from pendulab.outputs import check_output_file


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "fit",
        help="refit friction, Beq and force gain to logged runs (least squares on the replay of the logged voltage)",
        description=(
            "Replay the logged voltage through the CasADi plant and fit the friction vector, Beq and the force gain "
            "(optionally M_cart) to the logged positions (and angles): a search on an observer of the replay, then a "
            "polish on the replay under the true stick-slip law. "
            "Logs: CSV with columns t, V, x (alpha optional), the run.csv / run.mat of 'pendulab simulate', or a folder "
            "of the old MATLAB lab's logs (one .mat per signal). The answer is checked by a forward simulation of the "
            "whole log under the true stick-slip law; exit status 3 when it misses by far more than the encoder step "
            "or the logs cannot identify the parameters (e.g. a constant voltage), and no calibration is written."
        ),
    )
    parser.add_argument("logs", nargs="+", metavar="LOG", help="log files (CSV or run.mat) or old-lab log folders")
    parser.add_argument("--pendulum", default="none", choices=("long", "short", "none"), help="configuration the logs were taken in (default none: ramp tests)")
    parser.add_argument("--cart", default="ip02", choices=CARTS, help="cart (default ip02, no load)")
    parser.add_argument("--calibration", metavar="FILE", help="start from this calibration instead of the lab defaults")
    parser.add_argument(
        "--fit", default="F1,v1,F2,v2,B,Beq,force_gain", metavar="NAMES",
        help="comma-separated parameters to fit (default F1,v1,F2,v2,B,Beq,force_gain)",
    )
    parser.add_argument("--fit-mass", action="store_true", help="also fit M_cart")
    parser.add_argument(
        "--start", choices=("auto", "defaults"), default="auto",
        help="auto: start the friction from the ramp-test extraction where the logs are ramp tests (as the Python API's "
        "fit_parameters does by default); defaults: from the lab defaults or --calibration",
    )
    parser.add_argument("--scale-for", choices=("long", "short"), metavar="PENDULUM",
                        help="scale the fitted F1, F2 by the mass ratio for this pendulum (logs taken without it)")
    parser.add_argument("--out", metavar="FILE", help="write the fitted values as a calibration file (JSON)")
    parser.add_argument("--plot", metavar="PNG", help="plot measured against refitted motion")
    add_overwrite_option(parser)
    parser.add_argument("--voltage-lag", type=int, default=0, metavar="SAMPLES",
                        help="samples by which the logged voltage leads the cart's motion (negative: lags it); default 0, and the fit "
                        "looks for a sample either way itself")
    parser.add_argument("--interval", type=float, default=0.01, metavar="S", help="spacing of the fit's state estimates, where an upright pendulum's replay restarts (default 0.01 s)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pendulab.calibration.extract import mass_ratio
    from pendulab.calibration.files import load_calibration, save_calibration
    from pendulab.calibration.fit import FITTABLE, fit_parameters, plot_fit
    from pendulab.calibration.logs import read_log

    names = [n.strip() for n in args.fit.split(",") if n.strip()]
    unknown = [n for n in names if n not in FITTABLE]
    if unknown or not names:
        raise CalibrationError(f"--fit: {f'cannot fit {unknown[0]!r}' if unknown else 'no parameter named'}; choose among {', '.join(FITTABLE)}")
    if not (0 < args.interval <= 1.0):
        raise CalibrationError(f"--interval {args.interval} must be in (0, 1] s")
    out = check_output_file(args.out, "--out", suffixes=(".json",), overwrite=args.overwrite) if args.out is not None else None
    plot = check_output_file(args.plot, "--plot", suffixes=(".png",), overwrite=args.overwrite) if args.plot is not None else None

    params0 = PlantParameters.preset(pendulum=args.pendulum, cart=args.cart)
    if args.calibration:
        params0 = load_calibration(args.calibration).apply(params0)
    logs = [read_log(path) for path in args.logs]
    result = fit_parameters(
        logs, params0, fit=names, fit_mass=args.fit_mass, interval=args.interval, start="auto" if args.start == "auto" else "given",
        on_progress=lambda text: print(text, flush=True), voltage_lag=args.voltage_lag,
    )
    print(result.summary())
    if not result.forward_ok:
        total = sum(log.duration for log in logs)
        if plot:  # the picture of the mismatch helps to see why; no calibration is written
            plot_fit(result, plot)
            print(f"plot written to {plot}")
        raise FitRejected(
            f"the fitted values do not reproduce the logs: a forward simulation misses them by {result.forward_rms * 1e3:.3g} mm RMS "
            f"({result.forward_rms / max(result.encoder_step, 1e-12):.0f} encoder steps; accepted up to {result.forward_limit * 1e3:.3g} mm), "
            f"{result.where_it_misses()}; no calibration written. Check the logs (units, --pendulum, the voltage column is the applied voltage, "
            "logged at the time of its row's x: else --voltage-lag), "
            + (f"fit a part of about {result.searched_seconds:.0f} s of them (the search saw that much of their {total:.0f} s, where the cart stops "
               "and starts most)" if result.searched_seconds < 0.95 * total else "give longer or richer logs (ramps in both directions, steps)")
            + ", or start from --calibration"
        )

    if out:
        metadata = {
            "date": _dt.datetime.now().isoformat(timespec="seconds"),
            "logs": [str(p) for p in args.logs],
            "pendulum": args.pendulum,
            "cart": args.cart,
        }
        calibration = result.to_calibration(**metadata)
        if args.scale_for:
            ratio = mass_ratio(PlantParameters.preset(pendulum=args.scale_for, cart=args.cart)) / mass_ratio(params0)
            friction = dict(zip(FRICTION_NAMES, calibration.friction))
            friction["F1"] *= ratio
            friction["F2"] *= ratio
            calibration = type(calibration)(
                friction=tuple(friction[n] for n in FRICTION_NAMES),
                Beq=calibration.Beq, force_gain=calibration.force_gain, M_cart=calibration.M_cart,
                metadata={**calibration.metadata, "mass_ratio": ratio, "scaled_for": args.scale_for},
            )
        save_calibration(calibration, out)
        print(f"calibration written to {out}")
        if args.pendulum == "none" and not args.scale_for:
            ratio = mass_ratio(PlantParameters.preset(pendulum="long", cart=args.cart)) / mass_ratio(params0)
            print(f"note: {out} holds the bare cart's friction (logs taken with --pendulum none); with the pendulum on, the "
                  f"cart presses harder on the track: F1 and F2 are about {ratio:.2f} times higher for the long pendulum. "
                  f"For simulations with a pendulum, fit with --scale-for long (or short)", flush=True)
    if plot:
        plot_fit(result, plot)
        print(f"plot written to {plot}")
    return 0
