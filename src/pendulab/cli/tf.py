"""``pendulab tf``: the linearized plant's transfer function."""

from __future__ import annotations

import argparse
import json

import numpy as np

from pendulab.cli.options import add_plant_options, plant_parameters_from_args
from pendulab.model.linear import linearize


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "tf",
        help="print the linearized transfer function of the plant",
        description="Linearize the plant about the upright equilibrium and print the minimal transfer function.",
    )
    add_plant_options(parser)
    parser.add_argument("--output", choices=("alpha", "x", "tip"), default="alpha", help="output signal (default alpha)")
    parser.add_argument("--json", action="store_true", help='print one JSON object {"zeros", "poles", "gain"}')
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
    zeros, poles, gain = linearize(params).zpk(args.output)
    if args.json:
        print(json.dumps({"zeros": [_number(z) for z in zeros], "poles": [_number(p) for p in poles], "gain": gain}))
    else:
        print(f"{args.output}/V = {format_zpk(zeros, poles, gain)}")
    return 0
