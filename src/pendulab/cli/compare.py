"""``pendulab compare``: simulation and rig runs overlaid at the poke, with the old lab's table."""

from __future__ import annotations

import argparse
from pathlib import Path

from pendulab.cli.options import add_overwrite_option
from pendulab.errors import UserError
from pendulab.outputs import check_output_file


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "compare",
        help="overlay runs (simulation, rig, the old lab's logs) aligned at the poke, with the old lab's table",
        description=(
            "Overlay angle, tip, cart and voltage of several runs aligned at the poke (detected from the measured angle "
            "on a rig run) and print the old lab's table side by side: natural frequency, peak time, settling time, "
            "overshoot, final value, cart speed change, and the angle's NRMSE against the first run. Writes "
            "comparison.txt and comparison.png."
        ),
        epilog="example:\n  pendulab compare runs/sim-demo runs/lab-demo --out runs/comparison",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("runs", nargs="+", metavar="RUN", help="run folders or run.mat/run.csv files, or folders of the old lab's .mat logs")
    parser.add_argument("--out", type=Path, default=Path("."), metavar="DIR", help="where comparison.txt and comparison.png go (default: here)")
    parser.add_argument("--pendulum", default="long", choices=("long", "short"), help="pendulum of the old lab's logs (for the tip); default long")
    add_overwrite_option(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pendulab.analysis.compare import compare_runs
    from pendulab.model.parameters import PlantParameters

    if args.out.exists() and not args.out.is_dir():
        raise UserError(f"--out {args.out} is a file; give a folder")
    for name in ("comparison.txt", "comparison.png"):
        check_output_file(args.out / name, "--out", overwrite=args.overwrite)
    Lp = PlantParameters.preset(pendulum=args.pendulum).Lp
    text, written = compare_runs(args.runs, args.out, Lp=Lp)
    print(text)
    print(f"written: {', '.join(str(p) for p in written)}")
    return 0
