#!/usr/bin/env python3
"""Build pendulab's sdist and its wheels for linux x86_64 and win_amd64 into dist/.

Each wheel carries the four FMUs (linux64 and win64 binaries, sources) and the step-plan runner for its
platform, prebuilt (setup.py): nothing compiles at install or at first use. Needs a C compiler and the
mingw-w64 cross compiler (Debian: gcc gcc-mingw-w64-x86-64) and the 'build' package
(pip install -e ".[build]").

Usage: python build_wheels.py [--out DIR] [--no-isolation]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent
PLATFORMS = ("linux_x86_64", "win_amd64")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "dist", help="output folder (default dist/)")
    parser.add_argument("--no-isolation", action="store_true", help="build in this environment (its setuptools, casadi, fmpy) instead of a fresh one")
    parser.add_argument("--platform", choices=PLATFORMS, action="append", help="only this platform (repeatable; default both)")
    args = parser.parse_args(argv)
    # --no-isolation: this environment's packages, unchecked (the FMUs' build imports only part of the dependencies)
    common = [sys.executable, "-m", "build", "--outdir", str(args.out)] + (["--no-isolation", "--skip-dependency-check"] if args.no_isolation else [])
    host = "win_amd64" if sys.platform == "win32" else "linux_x86_64"
    platforms = args.platform or list(PLATFORMS)
    # The sdist, and this platform's wheel built from it: proof that the sdist builds everything from source.
    subprocess.run([*common, *([] if host in platforms else ["--sdist"]), str(ROOT)], check=True)
    for plat in platforms:
        if plat != host:  # the other platform's wheel from the source tree (its binaries cross-compiled)
            subprocess.run([*common, "--wheel", f"-C--build-option=--plat-name={plat}", str(ROOT)], check=True)
    for path in sorted(args.out.iterdir()):
        print(f"{path.stat().st_size / 1e6:6.2f} MB  {path.name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
