"""Sphinx configuration of pendulab's documentation site (``sphinx-build -W -b html docs docs/_build/html``).

Offline by design: no intersphinx, no remote images or fonts, so the site builds on a lab PC or in CI
without the network. The FMUs' variable tables are generated from the same variable tables the FMUs are
built from (pendulab.fmu.models), so they cannot drift from the FMUs.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

import pendulab  # noqa: E402

project = "pendulab"
author = "pendulab"
copyright = "pendulab contributors"
release = version = pendulab.__version__

extensions = [
    "myst_parser",
    "numpydoc",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.viewcode",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build"]
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3
suppress_warnings = ["myst.xref_missing"]  # links from the README-style pages to repository files outside docs/

autosummary_generate = True
autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_typehints = "none"  # numpydoc's Parameters sections carry the types
numpydoc_show_class_members = False
numpydoc_validation_checks: set[str] = set()
numpydoc_xref_param_type = False

html_theme = "furo"
html_title = f"pendulab {release}"
html_static_path: list[str] = []
html_show_sourcelink = False


def _fmu_tables(app) -> None:
    """docs/_generated/fmu_variables.md: every FMU's variables, from the tables the FMUs are built from."""
    from pendulab.fmu.build import model_spec
    from pendulab.fmu.models import ALL_FMUS

    lines = ["# The FMUs' variables", "",
             "Generated from `pendulab.fmu.models` (the tables each FMU's `modelDescription.xml` is written from).", ""]
    for name in ALL_FMUS:
        spec = model_spec(name)
        lines += [f"## {name}.fmu", "", f"{spec.description} (FMI {spec.fmi_version}.0).", "",
                  "| name | causality | type | start | min | max | unit | description |", "|---|---|---|---|---|---|---|---|"]

        def number(value: object) -> str:
            return "" if value is None else f"{value:g}" if isinstance(value, float) else str(value)

        for v in spec.variables:
            text = v.description.replace("|", "\\|")
            lines.append(f"| `{v.name}` | {v.causality} | {getattr(v.type, 'name', v.type)} | {number(v.start)} | "
                         f"{number(v.min)} | {number(v.max)} | {v.unit} | {text} |")
        lines.append("")
    out = Path(app.srcdir) / "_generated"
    out.mkdir(exist_ok=True)
    text = "\n".join(lines)
    target = out / "fmu_variables.md"
    if not target.exists() or target.read_text() != text:  # unchanged: no rebuild of the page
        target.write_text(text)


def setup(app):
    app.connect("builder-inited", _fmu_tables)
