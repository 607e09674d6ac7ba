"""``pendulab tf``: the linearized plant's transfer function."""

from __future__ import annotations

import argparse
import json

import numpy as np

from pendulab.cli.options import add_controller_options, add_plant_options, controller_from_args, plant_parameters_from_args
from pendulab.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "tf",
        help="print the linearized transfer function of the plant",
        description="Linearize the plant about the upright equilibrium and print the minimal transfer function.",
    )
    add_plant_options(parser)
    parser.add_argument("--output", choices=("alpha", "x", "tip"), default="alpha", help="output signal (default alpha)")
    parser.add_argument("--json", action="store_true", help='print one JSON object {"zeros", "poles", "gain"}')
    parser.add_argument("--root-locus", metavar="FILE", help="write the root locus of the loop Lp*C(s)*G(s) as PNG (needs a controller)")
    add_controller_options(parser)
    parser.set_defaults(func=run)


def _number(value: complex | float) -> float | list[float]:
    value = complex(value)
    return float(value.real) if value.imag == 0 else [float(value.real), float(value.imag)]


def format_zpk(zeros: np.ndarray, poles: np.ndarray, gain: float) -> str:
    """``5.247 s / ((s + 16.26)(s + 4.561)(s - 4.843))`` style text."""

    def factor(root: complex) -> str:
        root = complex(root)
        if abs(root) < 1e-12:
            return "s"
        if root.imag == 0:
            sign = "-" if root.real > 0 else "+"
            return f"(s {sign} {abs(root.real):.4g})"
        sign = "-" if root.real > 0 else "+"
        return f"(s {sign} {abs(root.real):.4g} {'-' if root.imag > 0 else '+'} {abs(root.imag):.4g}j)"

    def product(roots: np.ndarray) -> str:
        return "".join(factor(r) for r in roots) or "1"

    numerator = product(zeros)
    denominator = product(poles)
    text = f"{gain:.4g} {numerator}" if numerator != "1" else f"{gain:.4g}"
    return f"{text} / ({denominator})" if len(poles) > 1 else f"{text} / {denominator}"


def run(args: argparse.Namespace) -> int:
    params = plant_parameters_from_args(args)
    if params.Mp == 0:
        raise UserError("the cart without a pendulum has no angle to linearize; choose --pendulum long or short")
    from pendulab.model.linear import linearize  # imports python-control: only when needed

    plant = linearize(params)
    zeros, poles, gain = plant.zpk(args.output)
    controller = controller_from_args(args)
    if args.root_locus:
        if controller is None:
            raise UserError("--root-locus needs a controller: add --demo, --zeros/--poles/--gain, --pid or --controller FILE")
        from pendulab.analysis.plots import plot_root_locus

        # The loop the controller closes: e = -Lp*alpha, so the loop gain is Lp*C(s)*G(s).
        loop = controller.transfer_function() * plant.tf("tip")
        plot_root_locus(loop, args.root_locus, title=f"root locus of Lp·C(s)·G(s), {args.pendulum} pendulum")
    if args.json:
        print(json.dumps({"zeros": [_number(z) for z in zeros], "poles": [_number(p) for p in poles], "gain": gain}))
    else:
        print(f"{args.output}/V = {format_zpk(zeros, poles, gain)}")
        if args.root_locus:
            print(f"root locus written to {args.root_locus}")
    return 0
