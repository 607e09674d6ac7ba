"""``pendulab tf``: the linearized plant's transfer function."""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from pendulab.cli.options import (
    add_controller_options,
    add_overwrite_option,
    add_plant_options,
    controller_from_args,
    plant_parameters_from_args,
)
from pendulab.errors import UserError
from pendulab.outputs import check_output_file


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "tf",
        help="print the linearized transfer function of the plant",
        description="Linearize the plant about the upright equilibrium and print the minimal transfer function.",
    )
    parser.add_argument("--plant", choices=("pendulum", "seesaw"), default="pendulum",
                        help="plant (default pendulum); the seesaw prints theta/V, x/V and the open-loop poles")
    add_plant_options(parser)
    parser.add_argument("--output", choices=("alpha", "x", "tip"), default="alpha", help="output signal (default alpha)")
    parser.add_argument("--json", action="store_true", help='print one JSON object {"zeros", "poles", "gain"}')
    parser.add_argument("--root-locus", metavar="FILE", help="write the root locus of the loop Lp*C(s)*G(s) as PNG (needs a controller)")
    add_overwrite_option(parser)
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


def _polynomial(coefficients: np.ndarray) -> list[float]:
    c = np.atleast_1d(np.asarray(coefficients, dtype=float))
    c = np.where(np.abs(c) > 1e-9 * np.max(np.abs(c)), c, 0.0)  # round-off, not a coefficient
    first = int(np.argmax(c != 0)) if np.any(c != 0) else len(c) - 1
    return [float(v) for v in c[first:]]


def run_seesaw(args: argparse.Namespace) -> int:
    """The seesaw's linear model: theta/V and x/V, and the open-loop poles."""
    if args.root_locus or controller_from_args(args) is not None or args.output != "alpha" or args.calibration:
        raise UserError("--plant seesaw takes no controller, --output, --calibration or --root-locus: it prints theta/V, x/V and the poles")
    from pendulab.model.seesaw import linearize_seesaw

    plant = linearize_seesaw()
    poles = plant.poles
    result: dict = {"plant": "seesaw", "poles": [[float(p.real), float(p.imag)] for p in poles]}
    lines = []
    for output in ("theta", "x"):
        g = plant.tf(output)
        num, den = _polynomial(g.num[0][0]), _polynomial(g.den[0][0])
        zeros = np.roots(num) if len(num) > 1 else np.array([])
        result[output] = {"num": num, "den": den, "zeros": [[float(z.real), float(z.imag)] for z in zeros]}
        lines.append(f"{output}/V = {format_zpk(np.sort_complex(zeros), poles, num[0] / den[0])}")
    if args.json:
        print(json.dumps(result))
    else:
        print("\n".join(lines))
        print("open-loop poles: " + ", ".join(f"{p.real:.4g}" if p.imag == 0 else f"{p.real:.4g}{p.imag:+.4g}j" for p in poles))
    return 0


def calibration_note(path: str) -> str:
    """What a calibration file changes in the linear model, and what it cannot (friction)."""
    from pendulab.calibration.files import FITTED_NAMES, load_calibration

    cal = load_calibration(path)
    used = [f"{name} = {getattr(cal, name):.4g}" for name in FITTED_NAMES if getattr(cal, name) is not None]
    friction = ", ".join(f"{v:.4g}" for v in cal.friction)
    uses = (f"it uses {', '.join(used)} from {path}" if used
            else f"{path} holds friction only, so this is the default linear model (Beq, force gain and M_cart as the preset)")
    return (f"linear model: {uses}; the friction vector [F1, v1, F2, v2, B] = [{friction}] is not in it "
            "(stick-slip friction has no linearization at rest: it acts in 'pendulab simulate')")


def run(args: argparse.Namespace) -> int:
    if args.plant == "seesaw":
        return run_seesaw(args)
    if args.root_locus:
        check_output_file(args.root_locus, "--root-locus", suffixes=(".png",), overwrite=args.overwrite)
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
    note = calibration_note(args.calibration) if args.calibration else None
    if args.json:
        print(json.dumps({"zeros": [_number(z) for z in zeros], "poles": [_number(p) for p in poles], "gain": gain}))
        if note:
            print(note, file=sys.stderr)  # stdout stays one JSON object
    else:
        print(f"{args.output}/V = {format_zpk(zeros, poles, gain)}")
        if note:
            print(note)
        if args.root_locus:
            print(f"root locus written to {args.root_locus}")
    return 0
