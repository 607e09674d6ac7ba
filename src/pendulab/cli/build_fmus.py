"""``pendulab build-fmus``: build the native FMUs."""

from __future__ import annotations

import argparse
from pathlib import Path

from pendulab.errors import FmuBuildError, UserError
from pendulab.fmu.build import build_all, default_fmu_dir
from pendulab.fmu.models import ALL_FMUS
from pendulab.outputs import check_folder


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "build-fmus", help="build the plant, controller and supervisor FMUs",
        description="Build the native FMUs: Plant, Controller, Supervisor (FMI 2.0) and Plant3 (the plant as FMI 3.0)."
    )
    parser.add_argument("names", nargs="*", metavar="NAME", help=f"FMUs to build (default all: {', '.join(ALL_FMUS)})")
    parser.add_argument("--out", type=Path, metavar="DIR", help=f"output folder (default {default_fmu_dir()})")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    unknown = [n for n in args.names if n not in ALL_FMUS]
    if unknown:
        raise UserError(f"unknown FMU {unknown[0]!r}; choose from {', '.join(ALL_FMUS)}")
    try:
        if args.out is not None:
            check_folder(args.out)
        paths = build_all(args.out, args.names or None)
    except FmuBuildError as exc:
        raise UserError(str(exc).splitlines()[0]) from exc
    for path in paths:
        print(f"built {path}")
    return 0
