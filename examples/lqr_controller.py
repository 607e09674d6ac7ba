"""Worked example: a full-state-feedback (LQR) controller as a Python block, run in pendulab's master.

The controller is the class :class:`pendulab.blocks.lqr.LQRController` (read it: about thirty lines,
the template for a block of your own). This script

1. designs the gains on the linearized plant (``control.lqr``),
2. builds the block into ``LQRController.fmu`` with pythonfmu (patched to pass ``fmpy validate``),
3. runs the lab's poke experiment with it in place of the generic Controller FMU, the Plant and
   Supervisor FMUs around it, and writes ``run.mat``, ``run.csv`` and ``metrics.json``.

Usage::

    python examples/lqr_controller.py [--pendulum long|short] [--stop-time 5] [--out runs/lqr]

Writing your own block: subclass :class:`pendulab.blocks.Block` in a file of its own, declare
``inputs``, ``outputs`` and ``parameters`` with :class:`pendulab.blocks.Var`, implement
``step(self, t, h)``, and build it with ``pendulab.blocks.build_block("my_block.py", "fmus/")``.
A controller for the loop needs the input ``alpha_measured``, the output ``V_command`` and the
parameters ``Lp`` and ``h`` (every block has ``h``); inputs named like plant outputs
(``x_measured``, ...) are connected too.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import pendulab
from pendulab.blocks.build import build_block
from pendulab.blocks.lqr import DEFAULT_TAU, GAIN_NAMES, LQRController, design_lqr
from pendulab.errors import UserError


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pendulum", choices=("long", "short"), default="long")
    parser.add_argument("--stop-time", type=float, default=5.0, help="simulated time in s (default 5)")
    parser.add_argument("--tau", type=float, default=DEFAULT_TAU, help="velocity filter time constant in s")
    parser.add_argument("--out", type=Path, default=Path("runs") / "lqr", help="output folder (FMU and run files)")
    args = parser.parse_args(argv)

    try:
        plant = pendulab.Plant(pendulum=args.pendulum)
        params = pendulab.RunSpec(plant=plant).parameters()
        design = design_lqr(params)
        print("LQR gains (V = -K [x, xdot, alpha, alphadot]):")
        for name, k in zip(GAIN_NAMES, design.K):
            print(f"  {name:11s} = {k:9.3f}")
        print("closed-loop poles:", np.array2string(design.closed_loop_poles, precision=2))

        fmu = build_block(LQRController, args.out, start_values=design.start_values(tau=args.tau))
        print(f"built {fmu}")

        # The block takes the generic Controller FMU's place in the lab's loop.
        spec = pendulab.RunSpec(pendulab.ControllerSpec(fmu=str(fmu)), plant=plant, timing=pendulab.Timing(stop_time=args.stop_time))
        result = pendulab.simulate(spec)
        columns = result.columns
        paths = result.write(args.out)
    except UserError as exc:
        print(f"lqr_controller: error: {exc}", file=sys.stderr)
        return 2

    cut = result.metrics["safety_cut_time_s"]
    print("\n".join(result.verdict.lines()))  # the verdict of pendulab.analysis.verdict, as 'simulate' prints it
    print(f"max |alpha| = {np.degrees(np.abs(columns['alpha']).max()):.2f} deg, "
          f"max |x| = {100 * np.abs(columns['x']).max():.1f} cm, final x = {1000 * columns['x'][-1]:.1f} mm, "
          f"max |V| = {np.abs(columns['voltage_command']).max():.2f} V")
    print("supervisor:", f"tripped at {cut:.3f} s" if cut is not None else "never tripped")
    print("results:", ", ".join(str(p) for p in paths.values()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
