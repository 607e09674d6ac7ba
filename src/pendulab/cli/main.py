"""The ``pendulab`` console command: one entry point, one module per subcommand.

Each subcommand module under :mod:`pendulab.cli` exposes ``register(subparsers)``, which adds its
parser and sets ``func`` to a callable taking the parsed arguments and returning an exit status.
User mistakes raise :class:`~pendulab.errors.UserError`: one line on stderr, exit status 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from pathlib import Path
from typing import Sequence

from pendulab import __version__
from pendulab.errors import UserError

#: Subcommand modules, in the order ``--help`` lists them.
SUBCOMMANDS = ("simulate", "tf", "lqr", "build_fmus", "calibrate", "fit", "lab", "rig_emulator", "compare", "gui", "sweep", "docs")


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line and exit status 2 (argparse prints the usage too)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise UserError(f"{self.prog}: {message} (see '{self.prog} --help')")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="pendulab", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"pendulab {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in SUBCOMMANDS:
        try:
            module = importlib.import_module(f"pendulab.cli.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"pendulab.cli.{name}":
                raise
            continue
        module.register(subparsers)
    for name, sub in subparsers.choices.items():
        if name in FMU_COMMANDS:
            sub.add_argument("--fmus", metavar="DIR", help="use the FMUs in DIR instead of the installed ones (e.g. your own Controller.fmu)")
    return parser


#: Subcommands that load FMUs, and so take ``--fmus DIR``.
FMU_COMMANDS = frozenset({"simulate", "calibrate", "lab", "rig-emulator", "gui", "sweep"})


def _use_fmu_dir(folder: str | None) -> None:
    """``--fmus DIR``: every FMU found there replaces the installed one, here and in worker processes."""
    if folder is None:
        return
    path = Path(folder).expanduser()
    if not path.is_dir():
        raise UserError(f"--fmus {folder}: no such folder; give the folder that holds your .fmu files")
    os.environ["PENDULAB_FMU_DIR"] = str(path.resolve())


#: Options whose values often start with a minus sign ("--zeros -3,-6"): argparse would take such a
#: value for an option, so it is joined to its option ("--zeros=-3,-6") before parsing.
SIGNED_VALUE_OPTIONS = frozenset({"--zeros", "--poles", "--gain", "--compensator", "--pid", "--poke", "--friction"})


def _join_signed_values(argv: Sequence[str]) -> list[str]:
    out: list[str] = []
    it = iter(argv)
    for arg in it:
        if arg in SIGNED_VALUE_OPTIONS:
            value = next(it, None)
            if value is not None and value.startswith("-") and value[1:2] not in ("-", ""):
                out.append(f"{arg}={value}")
                continue
            out.append(arg)
            if value is not None:
                out.append(value)
            continue
        out.append(arg)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        raw = list(sys.argv[1:] if argv is None else argv)
        args = parser.parse_args(_join_signed_values(raw))
        _use_fmu_dir(getattr(args, "fmus", None))
        if not getattr(args, "func", None):
            parser.print_help()
            return 2
        return int(args.func(args) or 0)
    except UserError as exc:
        print(f"pendulab: error: {exc}", file=sys.stderr)
        return exc.exit_status
    except KeyboardInterrupt as exc:
        from pendulab.hil.realtime import Terminated

        if isinstance(exc, Terminated):
            print(f"pendulab: {exc}", file=sys.stderr)
            return exc.exit_status
        print("pendulab: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into 'head' and the like
        return 0


if __name__ == "__main__":
    raise SystemExit(main())
