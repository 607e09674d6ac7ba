"""``pendulab lqr``: an LQR state feedback for the pendulum or the seesaw."""

from __future__ import annotations

import argparse
import json

from pendulab.cli.options import add_overwrite_option
from pendulab.outputs import check_output_file


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "lqr",
        help="design an LQR state feedback for the pendulum or the seesaw",
        description="Design V = -K state by LQR on the plant's linear model; print K and the closed-loop poles. "
        "The state is ordered positions first: x, angle, xdot, angledot (and the angle's integral with --integral).",
    )
    parser.add_argument("--plant", choices=("pendulum", "seesaw"), default="pendulum", help="plant (default pendulum)")
    parser.add_argument("--pendulum", default="long", choices=("long", "short"), help="pendulum, for --plant pendulum (default long)")
    parser.add_argument("--q", metavar="Q1,Q2,...", help="diagonal of Q, one weight per state (default: Quanser's for the seesaw)")
    parser.add_argument("--r", metavar="R", help="weight of the voltage, > 0")
    integral = parser.add_mutually_exclusive_group()
    integral.add_argument("--integral", dest="integral", action="store_true", default=None, help="add the angle's integral to the state (seesaw default)")
    integral.add_argument("--no-integral", dest="integral", action="store_false", help="no integral state (pendulum default)")
    parser.add_argument("--json", action="store_true", help='print one JSON object {"plant", "states", "K", "closed_loop_poles"}')
    parser.add_argument("--out", metavar="FILE", help="write the design as a controller file (TOML)")
    add_overwrite_option(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pendulab.control.state_feedback import design_from_text

    params = None
    if args.plant == "pendulum":
        from pendulab.model.parameters import PlantParameters

        params = PlantParameters.preset(args.pendulum)
    if args.out is not None:
        check_output_file(args.out, "--out", suffixes=(".toml",), overwrite=args.overwrite)
    design = design_from_text(args.plant, args.q, args.r, args.integral, params)
    poles = [[float(p.real), float(p.imag)] for p in design.closed_loop_poles]
    if args.json:
        print(json.dumps({"plant": design.plant, "states": list(design.states), "K": [float(k) for k in design.K],
                          "closed_loop_poles": poles, "q": list(design.q), "r": design.r}))
    else:
        print(f"LQR for the {design.plant}, V = -K [{', '.join(design.states)}]")
        print(f"Q = diag({', '.join(f'{v:g}' for v in design.q)}), R = {design.r:g}")
        for name, k in zip(design.states, design.K):
            print(f"  K_{name:<16} {k: .6g}")
        print("closed-loop poles: " + ", ".join(f"{p.real:.4g}{p.imag:+.4g}j" if p.imag else f"{p.real:.4g}" for p in design.closed_loop_poles))
    if args.out is not None:
        from pendulab.control.state_feedback import save_state_feedback_file

        save_state_feedback_file(design, args.out)
        if not args.json:
            print(f"controller file written to {args.out}")
    return 0
