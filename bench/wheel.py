#!/usr/bin/env python3
"""The wheel on a machine without a compiler: sizes, pip install to the first run.mat, and the fit's cost
without a compiler against with one, all measured in this run (issue 23).

1. ``build_wheels.py`` (or ``--dist DIR`` with wheels already built): the wheels' and the sdist's sizes.
2. A fresh venv; ``pip install <linux wheel>`` with its dependencies from the registry (or pip's cache),
   then the README's ``pendulab simulate --demo --out runs/demo --plot``: seconds from the start of
   ``pip install`` to ``run.mat``.
3. ``pendulab calibrate --virtual --iterations 1 --log``, then ``pendulab fit`` on that log three times:
   compiled with an empty cache (the first fit on a machine), compiled again (cache warm), and with no
   compiler on the PATH (CasADi's virtual machine). CPU time (user + system of the process and its
   children) is the figure that a shared machine does not distort; wall time is printed beside it.

Usage: python bench/wheel.py [--dist DIR] [--keep DIR]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def timed(command: list[str], **kw) -> tuple[float, float, subprocess.CompletedProcess]:
    """(wall s, CPU s of the children, result) of running ``command`` to completion."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    result = subprocess.run(command, capture_output=True, text=True, **kw)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if result.returncode != 0:
        sys.exit(f"{' '.join(map(str, command))} failed:\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dist", type=Path, help="use the wheels in DIR instead of building them")
    parser.add_argument("--keep", type=Path, help="work in DIR (kept) instead of a temporary folder")
    args = parser.parse_args()
    root = Path(args.keep or tempfile.mkdtemp(prefix="pendulab-bench-wheel-"))
    root.mkdir(parents=True, exist_ok=True)
    print(f"machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}; folder {root}")

    dist = args.dist
    if dist is None:
        dist = root / "dist"
        wall, cpu, _ = timed([sys.executable, str(REPO / "build_wheels.py"), "--no-isolation", "--out", str(dist)])
        print(f"build_wheels.py: {wall:.1f} s wall, {cpu:.1f} s CPU")
    for path in sorted(dist.iterdir()):
        print(f"  {path.stat().st_size / 1e6:5.2f} MB  {path.name}")
    wheel = next(dist.glob("pendulab-*-manylinux*_x86_64.whl"))

    venv, work = root / "venv", root / "work"
    work.mkdir(exist_ok=True)
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    hidden = {**os.environ, "PATH": str(venv / "bin"), "MPLBACKEND": "Agg", "XDG_CACHE_HOME": str(root / "cache")}
    hidden.pop("CC", None)
    hidden.pop("PENDULAB_CACHE", None)
    start = time.perf_counter()
    wall_pip, cpu_pip, _ = timed([str(venv / "bin" / "pip"), "install", "-q", str(wheel)], env=hidden)
    wall_run, cpu_run, _ = timed(["pendulab", "simulate", "--demo", "--out", "runs/demo", "--plot"], env=hidden, cwd=work)
    assert (work / "runs" / "demo" / "run.mat").is_file()
    print(f"pip install (with dependencies) {wall_pip:.1f} s + first simulate {wall_run:.1f} s: "
          f"{time.perf_counter() - start:.1f} s from pip install to run.mat (CPU {cpu_pip + cpu_run:.1f} s)")

    timed(["pendulab", "calibrate", "--virtual", "--iterations", "1", "--out", "cal.json", "--log", "ramp.csv"], env=hidden, cwd=work)
    compiler_path = {**hidden, "PATH": f"{venv / 'bin'}{os.pathsep}{os.environ['PATH']}", "PENDULAB_CACHE": str(root / "fit-cache")}
    shutil.rmtree(root / "fit-cache", ignore_errors=True)
    fits = {}
    for label, env in (("compiled, cache empty", compiler_path), ("compiled, cache warm", compiler_path), ("no compiler (CasADi VM)", hidden)):
        wall, cpu, result = timed(["pendulab", "fit", "ramp.csv", "--pendulum", "none", "--out", f"fit-{len(fits)}.json", "--overwrite"],
                                  env=env, cwd=work)
        said = "virtual machine" in result.stdout + result.stderr
        fits[label] = (wall, cpu)
        print(f"fit, {label:24s}: {wall:6.1f} s wall, {cpu:6.1f} s CPU{'  (said: virtual machine)' if said else ''}")
    vm, warm, cold = fits["no compiler (CasADi VM)"], fits["compiled, cache warm"], fits["compiled, cache empty"]
    print(f"no compiler / compiled (warm): {vm[1] / warm[1]:.1f}x CPU, {vm[0] / warm[0]:.1f}x wall; "
          f"/ compiled (cold): {vm[1] / cold[1]:.1f}x CPU")
    if args.keep is None:
        shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
