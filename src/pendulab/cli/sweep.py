"""``pendulab sweep SPEC.toml --out DIR``: a grid of controllers over plausible rigs, locally or on Dask."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from pendulab.cli.options import add_overwrite_option
from pendulab.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "sweep",
        help="run a grid of controllers over samples of plausible rigs (results.parquet, plots)",
        description=(
            "Run every controller of the spec's grid on the same random samples of plausible rigs, in batches on local "
            "worker processes or a Dask cluster. Writes DIR/results.parquet (one row per run: inputs, metrics, status, "
            "time) in parts with a journal, so that --resume continues a stopped sweep, and plots in DIR/plots/. "
            "The spec format is in the README (section 'Sweeps')."
        ),
        epilog=(
            "examples:\n"
            "  pendulab sweep pid_grid.toml --out runs/pid-grid\n"
            "  pendulab sweep pid_grid.toml --out runs/pid-grid --resume\n"
            "  pendulab sweep pid_grid.toml --out runs/pid-grid --scheduler tcp://10.0.0.5:8786\n"
            "  pendulab sweep pid_grid.toml --out runs/pid-grid --scheduler local:4"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("spec", type=Path, metavar="SPEC.toml", help="the sweep spec (TOML)")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder (must be new, unless --resume)")
    parser.add_argument("--resume", action="store_true", help="continue the sweep in DIR: run only what its journal lacks")
    add_overwrite_option(parser)
    parser.add_argument("--scheduler", metavar="tcp://HOST:PORT|local:N", help="run on a Dask cluster (pip install 'pendulab[dask]')")
    parser.add_argument("--workers", type=int, metavar="N", help="local worker processes (default: one per core)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.set_defaults(func=run)


class ProgressBar:
    """One line on stderr: runs, throughput, time left, running balanced share (redrawn on a terminal)."""

    def __init__(self, stream: Any = None, every: float = 5.0) -> None:
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty()
        self.every = every
        self._last = 0.0

    def line(self, p: Any) -> str:
        width = 24
        filled = int(width * p.done / max(1, p.total))
        left = p.remaining_s
        eta = "--:--" if left is None else time.strftime("%H:%M:%S", time.gmtime(left))
        share = f"{100 * p.balanced / p.done:.0f} %" if p.done else "-"
        return f"[{'#' * filled}{'.' * (width - filled)}] {p.done}/{p.total} runs  {p.rate:.1f} runs/s  {eta} left  balanced {share}"

    def __call__(self, p: Any) -> None:
        now = time.monotonic()
        if self.tty:
            print("\r" + self.line(p), end="", file=self.stream, flush=True)
        elif now - self._last >= self.every or p.done == p.total:
            self._last = now
            print(self.line(p), file=self.stream, flush=True)

    def end(self) -> None:
        if self.tty:
            print(file=self.stream)


def run(args: argparse.Namespace) -> int:
    from pendulab.sweep import sweep
    from pendulab.sweep.spec import load_sweep_spec
    from pendulab.sweep.store import ResultStore

    spec = load_sweep_spec(args.spec)
    if args.resume and args.overwrite:
        raise UserError("give --resume (continue the sweep in --out) or --overwrite (start it again), not both")
    ResultStore.check(args.out, spec, args.resume, args.overwrite)
    bar = ProgressBar()
    try:
        result = sweep(args.spec, args.out, scheduler=args.scheduler, workers=args.workers, resume=args.resume,
                       overwrite=args.overwrite, plots=not args.no_plots, progress=bar,
                       announce=lambda line: print(line, file=sys.stderr, flush=True))
    except KeyboardInterrupt:
        bar.end()
        raise UserError(f"sweep interrupted; the runs done so far are saved in {args.out}: continue with --resume") from None
    bar.end()
    counts = ", ".join(f"{n} {s}" for s, n in result.counts.items() if n)
    total = sum(result.counts.values())
    print(f"{total} runs on {result.engine} in {result.elapsed:.1f} s: {counts}")
    print(f"results in {result.out / 'results.parquet'}" + (f"; plots in {result.out / 'plots'}" if result.plots else ""))
    return 0
