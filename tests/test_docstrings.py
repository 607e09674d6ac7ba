"""Docstrings of the public API (modelled on python-control's ``docstrings_test.py``) and every
module's doctests, run here so that an example that stops working fails the suite.

- every name in ``pendulab.__all__`` has a numpydoc docstring with an Examples section, and a
  function (or a class's constructor) documents every parameter of its signature, by name;
- every module's doctests pass, and a skipped example says why on its own line or in a comment.
"""

from __future__ import annotations

import doctest
import importlib
import inspect
import re
from pathlib import Path

import pytest

import pendulab

PACKAGE = Path(pendulab.__file__).resolve().parent
#: Modules whose doctests are not run here, with the reason.
NOT_RUN = {"pendulab.__main__": "running it starts the command line"}
SECTION = re.compile(r"^\s*(Parameters|Returns|Yields|Raises|Attributes|Examples|See Also|Notes|Other Parameters)\n\s*-{3,}\s*$", re.M)


def sections(doc: str) -> dict[str, str]:
    """numpydoc sections of a docstring by title."""
    doc = inspect.cleandoc(doc)
    found = list(SECTION.finditer(doc))
    return {m.group(1): doc[m.end(): found[i + 1].start() if i + 1 < len(found) else len(doc)] for i, m in enumerate(found)}


def documented_parameters(text: str) -> set[str]:
    """Names at the start of ``name : type`` (or ``a, b : type``, ``*args``, ``**kwargs``) lines."""
    names: set[str] = set()
    for line in text.splitlines():
        if line and not line.startswith((" ", "\t")):
            head = line.split(" : ")[0]
            names.update(n.strip().lstrip("*") for n in head.split(","))
    return names


def public_objects():
    for name in pendulab.__all__:
        yield name, getattr(pendulab, name)


@pytest.mark.parametrize("name", pendulab.__all__)
def test_public_name_documents_every_parameter_with_an_example(name):
    obj = getattr(pendulab, name)
    doc = inspect.getdoc(obj)
    assert doc, f"pendulab.{name} has no docstring"
    if isinstance(obj, type) and issubclass(obj, BaseException):
        return  # an error type: its docstring says when it is raised
    parts = sections(obj.__doc__)
    assert "Examples" in parts and ">>>" in parts["Examples"], f"pendulab.{name}: no Examples section with an example"
    target = obj.__init__ if isinstance(obj, type) else obj
    try:
        signature = inspect.signature(target)
    except (TypeError, ValueError):
        return
    wanted = [p.name for p in signature.parameters.values() if p.name not in ("self", "cls")]
    if not wanted:
        return
    documented = documented_parameters(parts.get("Parameters", "")) | documented_parameters(parts.get("Attributes", ""))
    missing = [p for p in wanted if p not in documented]
    assert not missing, f"pendulab.{name}: parameters {missing} are not in its Parameters section"


def modules() -> list[str]:
    names = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        if name not in NOT_RUN:
            names.append(name)
    return names


MODULES = modules()


@pytest.mark.parametrize("name", MODULES)
def test_module_doctests_pass(name, loop_fmus):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, report=True)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples in {name} failed (see the output above)"


SKIP = re.compile(r"#\s*doctest:.*\+SKIP")


def test_every_skipped_example_says_why():
    unexplained = []
    for path in sorted(PACKAGE.rglob("*.py")):
        lines = path.read_text(encoding="utf-8").splitlines()
        for i, line in enumerate(lines):
            if not SKIP.search(line):
                continue
            before = line[: line.index("# doctest")]
            # A reason: a comment before the directive on the same line, or a '# skipped: ...' example
            # line above (within the same block of examples).
            said = "#" in before or any("# skipped:" in lines[j] for j in range(max(0, i - 4), i))
            if not said:
                unexplained.append(f"{path.relative_to(PACKAGE.parent)}:{i + 1}: {line.strip()}")
    assert not unexplained, "+SKIP without a reason:\n" + "\n".join(unexplained)


def test_doctests_are_counted():
    """The count the closing note reports: examples run and examples skipped (with their reasons)."""
    finder = doctest.DocTestFinder()
    run = skipped = 0
    for name in MODULES:
        for test in finder.find(importlib.import_module(name)):
            for example in test.examples:
                if example.options.get(doctest.SKIP):
                    skipped += 1
                else:
                    run += 1
    print(f"doctest examples: {run} run, {skipped} skipped")
    assert run > 100
