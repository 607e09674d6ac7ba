#!/usr/bin/env python3
"""Build every pendulab FMU into fmus/: Plant, Controller, Supervisor (FMI 2.0) and Plant3 (the plant as FMI 3.0).

Usage: python build_fmus.py [NAME ...]
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "src"))

from pendulab.cli.main import main  # noqa: E402

if __name__ == "__main__":
    raise SystemExit(main(["build-fmus", *sys.argv[1:]]))
