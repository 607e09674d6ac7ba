"""The package's import graph: the command line and the GUI are leaves, and no package reaches into
another's private names (issue 18).

Read from the source with :mod:`ast` (every ``import`` and ``from ... import``, at any depth, lazy
imports inside functions included), so the test sees imports that a run would only reach late.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "pendulab"
#: The entry points: ``python -m pendulab`` runs the command line, whose ``gui`` command starts the GUI.
ENTRY_POINTS = {"pendulab.__main__": {"pendulab.cli"}, "pendulab.cli": {"pendulab.gui"}}


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> list[tuple[int, str, list[str]]]:
    """``(line, module, names)`` for every import in the file (relative imports resolved)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    here = module_name(path).split(".") if path.is_relative_to(PACKAGE) else [path.stem]
    if path.name != "__init__.py":
        here = here[:-1]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name, []) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(here[: len(here) - node.level + 1] + ([base] if base else []))
            found.append((node.lineno, base, [alias.name for alias in node.names]))
    return found


def package_of(module: str) -> str:
    """``pendulab.<package>`` (or the top-level module) a module belongs to."""
    return ".".join(module.split(".")[:2])


SOURCES = sorted(PACKAGE.rglob("*.py"))


def test_the_graph_is_read_from_every_module():
    names = {module_name(p) for p in SOURCES}
    assert {"pendulab.cli.main", "pendulab.gui.app", "pendulab.spec", "pendulab.simulation"} <= names
    # The reader resolves relative imports and sees imports inside functions.
    found = {m for p in SOURCES if module_name(p) == "pendulab.cli.simulate" for _, m, _ in imports(p)}
    assert "pendulab.simulation" in found  # imported inside run()


@pytest.mark.parametrize("leaf", ["pendulab.cli", "pendulab.gui"])
def test_nothing_imports_the_command_line_or_the_gui(leaf):
    offenders = []
    for path in SOURCES:
        me = module_name(path)
        if package_of(me) == leaf or leaf in ENTRY_POINTS.get(package_of(me), set()) or leaf in ENTRY_POINTS.get(me, set()):
            continue
        for line, module, names in imports(path):
            targets = [module] + [f"{module}.{n}" for n in names]
            if any(t == leaf or t.startswith(leaf + ".") for t in targets):
                offenders.append(f"{path.relative_to(ROOT)}:{line} imports {module}")
    for path in sorted((ROOT / "examples").glob("*.py")) + sorted((ROOT / "bench").glob("*.py")):
        for line, module, _ in imports(path):
            if module == leaf or module.startswith(leaf + "."):
                offenders.append(f"{path.relative_to(ROOT)}:{line} imports {module}")
    assert not offenders, "\n".join(offenders)


def test_no_package_imports_another_packages_private_names():
    offenders = []
    for path in SOURCES + sorted((ROOT / "examples").glob("*.py")):
        me = module_name(path) if path.is_relative_to(PACKAGE) else "examples"
        for line, module, names in imports(path):
            if not module.startswith("pendulab") or package_of(module) == package_of(me):
                continue
            private = [n for n in names if n.startswith("_") and not n.startswith("__")]
            private += [part for part in module.split(".")[2:] if part.startswith("_") and not part.startswith("__")]
            if private:
                offenders.append(f"{path.relative_to(ROOT)}:{line} imports {', '.join(private)} from {module}")
    assert not offenders, "\n".join(offenders)


#: A test or a benchmark may reach into a private name only with a comment saying why, on the import's
#: line(s) or the line above: ``# private: <why>`` (for example, a benchmark of the fit's internals).
PRIVATE_WHY = re.compile(r"#\s*private:\s*\S.{9,}")


def private_imports(path: Path) -> list[tuple[int, int, str, list[str]]]:
    """``(first line, last line, module, private names)`` of every import of private pendulab names in a file
    (a name with a leading underscore, or a module on a private path such as ``pendulab.calibration._replay``)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.ImportFrom) and not node.level and (node.module or "").split(".")[0] == "pendulab":
            modules = [(node.module, [alias.name for alias in node.names])]
        elif isinstance(node, ast.Import):
            modules = [(alias.name, []) for alias in node.names if alias.name.split(".")[0] == "pendulab"]
        else:
            continue
        for module, names in modules:
            private = [part for part in module.split(".")[1:] if part.startswith("_") and not part.startswith("__")]
            private += [n for n in names if n.startswith("_") and not n.startswith("__")]
            if private:
                found.append((node.lineno, node.end_lineno or node.lineno, module, private))
    return found


def test_the_private_import_reader_sees_every_form(tmp_path):
    source = tmp_path / "sample.py"
    source.write_text("import pendulab.calibration._replay\n"
                      "from pendulab.analysis.results import json_safe, _hidden\n"
                      "from pendulab.calibration import (\n    _polish,  # private: the polish is what this measures\n)\n"
                      "from pendulab.spec import RunSpec\n"
                      "def f():\n    from pendulab.cosim._plan import run\n")
    found = [(first, last, module, names) for first, last, module, names in private_imports(source)]
    assert found == [(1, 1, "pendulab.calibration._replay", ["_replay"]), (2, 2, "pendulab.analysis.results", ["_hidden"]),
                     (3, 5, "pendulab.calibration", ["_polish"]), (8, 8, "pendulab.cosim._plan", ["_plan"])]
    lines = source.read_text().splitlines()
    assert [bool(PRIVATE_WHY.search("\n".join(lines[max(first - 2, 0) : last]))) for first, last, _, _ in found] == [False, False, True, False]


@pytest.mark.parametrize("folder", ["bench", "tests"])
def test_bench_and_tests_import_private_names_only_saying_why(folder):
    """The bench and the tests use pendulab's public names; where one measures or checks a private piece
    (the fit's replay, a compile helper), a ``# private: why`` comment says so at the import."""
    offenders = []
    for path in sorted((ROOT / folder).glob("*.py")):
        lines = path.read_text(encoding="utf-8").splitlines()
        for first, last, module, names in private_imports(path):
            if not PRIVATE_WHY.search("\n".join(lines[max(first - 2, 0) : last])):
                offenders.append(f"{folder}/{path.name}:{first} imports {', '.join(names)} from {module} without a '# private: why' comment")
    assert not offenders, "\n".join(offenders)


def test_the_bench_does_not_import_the_tests():
    for path in sorted((ROOT / "bench").glob("*.py")):
        for line, module, _ in imports(path):
            assert module.split(".")[0] != "tests", f"{path.name}:{line} imports {module}"


@pytest.mark.parametrize("statement, allowed", [
    ("import pendulab", set()),
    ("import pendulab; pendulab.simulate; pendulab.RunSpec", {"numpy"}),
])
def test_the_top_level_imports_the_heavy_libraries_only_when_used(statement, allowed):
    """``import pendulab`` stays light: fmpy, CasADi, python-control, SciPy and matplotlib load when a run or a
    linearization needs them (a machine-independent stand-in for the import time the closing note measures)."""
    import subprocess
    import sys

    heavy = ("numpy", "fmpy", "casadi", "control", "scipy", "matplotlib")
    code = f"{statement}; import sys; print(' '.join(m for m in {heavy!r} if m in sys.modules))"
    loaded = set(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split())
    assert loaded <= allowed, f"{statement!r} imports {sorted(loaded - allowed)}"


@pytest.mark.parametrize("module", ["pendulab.cosim.master", "pendulab.hil.session", "pendulab.hil.emulator", "pendulab.calibration.rig"])
def test_what_steps_an_fmu_uses_no_other_modules_private_names(module):
    """The master, the lab session, the rig emulator and the virtual rig step FMUs through the one component
    layer (pendulab.cosim.component), with its public names only."""
    path = PACKAGE.joinpath(*module.split(".")[1:]).with_suffix(".py")
    private = [f"{line}: {name} from {source}" for line, source, names in imports(path) if source.startswith("pendulab")
               for name in names if name.startswith("_") and not name.startswith("__")]
    assert not private, private
    sources = {source for _, source, _ in imports(path)}
    assert "pendulab.cosim.component" in sources
