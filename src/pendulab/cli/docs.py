"""``pendulab docs``: where the documentation site is, and how to build or open it."""

from __future__ import annotations

import argparse
import subprocess
import sys
import webbrowser
from pathlib import Path

from pendulab.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "docs", help="say where the documentation site is (--build builds it, --open opens it)",
        description="The documentation site (user guides for students, TAs and FMI engineers; the API reference) "
                    "is built from docs/ in a checkout with Sphinx: 'pip install -e .[docs]' then 'pendulab docs --build'.",
    )
    parser.add_argument("--build", action="store_true", help="build the site first (sphinx-build -W; needs the docs extra)")
    parser.add_argument("--open", action="store_true", help="open the site in the browser")
    parser.set_defaults(func=run)


def site_paths() -> tuple[Path | None, Path | None]:
    """``(docs/ source folder, built index.html)`` of a checkout, or ``(None, None)`` for an installed package."""
    from pendulab.fmu.build import checkout_dir

    repo = checkout_dir()
    if repo is None or not (repo / "docs" / "conf.py").is_file():
        return None, None
    return repo / "docs", repo / "docs" / "_build" / "html" / "index.html"


def run(args: argparse.Namespace) -> int:
    source, index = site_paths()
    if source is None or index is None:
        raise UserError("the documentation is built from a checkout of pendulab (its docs/ folder): "
                        "clone it, 'pip install -e .[docs]', then 'pendulab docs --build'")
    if args.build:
        try:
            import sphinx  # noqa: F401
        except ImportError:
            raise UserError("building the documentation needs Sphinx: pip install -e \".[docs]\"") from None
        command = [sys.executable, "-m", "sphinx", "-W", "-q", "-b", "html", str(source), str(index.parent)]
        if subprocess.run(command).returncode != 0:
            raise UserError(f"the documentation build failed (see above); the command was: {' '.join(command)}")
    if not index.is_file():
        raise UserError(f"the documentation is not built yet: 'pendulab docs --build' writes {index}")
    print(index)
    if args.open:
        webbrowser.open(index.as_uri())
    return 0
