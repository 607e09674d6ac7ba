"""Controller files: TOML or JSON, the shape of :meth:`Controller.to_dict`.

A controller file holds a table ``kernel`` (``zeros``, ``poles``, ``gain``) and an optional list
``compensators`` (``zeros``, ``poles``, optional ``gain``). Complex numbers are ``[re, im]`` pairs or
strings ``"-3+4j"``. Anything else (unknown keys, malformed text, unreadable files) is a one-line
:class:`~pendulab.errors.ControllerError` that names the file.

Example ``controller.toml``::

    [kernel]
    zeros = [-5]
    poles = [7]
    gain = 40000

    [[compensators]]
    zeros = [-17]
    poles = [-80]

    [[compensators]]
    poles = [-80]

Examples
--------
>>> import tempfile, pathlib
>>> from pendulab.control.controller import demo_controller
>>> from pendulab.control.files import load_controller_file, save_controller_file
>>> path = pathlib.Path(tempfile.mkdtemp()) / "demo.toml"
>>> save_controller_file(demo_controller(), path)
>>> load_controller_file(path) == demo_controller()
True
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

from pendulab.control.controller import Controller, _one_line
from pendulab.errors import ControllerError
from pendulab.outputs import atomic_write

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

SUFFIXES = (".toml", ".json")


def _suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise ControllerError(f"controller file {path}: unknown type {suffix or '(no suffix)'!r}; name it *.toml or *.json")
    return suffix


def load_controller_file(path: str | os.PathLike[str]) -> Controller:
    """Read and check a controller file (``.toml`` or ``.json``)."""
    path = Path(path)
    suffix = _suffix(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ControllerError(f"controller file {path} does not exist; check the path") from None
    except IsADirectoryError:
        raise ControllerError(f"controller file {path} is a directory; give the path of a .toml or .json file") from None
    except UnicodeDecodeError:
        raise ControllerError(f"controller file {path} is not UTF-8 text; save it as a plain-text .toml or .json file") from None
    except OSError as exc:
        raise ControllerError(f"cannot read controller file {path}: {exc.strerror or exc}; check the path and its permissions") from None
    try:
        if suffix == ".toml":
            data: Any = tomllib.loads(text)
        else:
            data = json.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ControllerError(f"controller file {path} is not valid TOML: {_one_line(str(exc))}; fix the syntax") from None
    except json.JSONDecodeError as exc:
        raise ControllerError(f"controller file {path} is not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}; fix the syntax") from None
    except (ValueError, RecursionError) as exc:  # e.g. numbers too large for Python's int conversion
        raise ControllerError(f"controller file {path} cannot be read: {_one_line(str(exc))[:120]}; fix the file") from None
    try:
        return Controller.from_dict(data)
    except ControllerError as exc:
        raise ControllerError(f"controller file {path}: {exc}") from None


def _toml_value(value: Any) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return repr(float(value))


def controller_toml(controller: Controller) -> str:
    """The TOML text of a controller file."""

    def table(factor: dict[str, Any]) -> list[str]:
        return [f"{key} = {_toml_value(factor[key])}" for key in ("zeros", "poles", "gain")]

    data = controller.to_dict()
    lines = ["# pendulab controller: G(s) = kernel x compensators", f"# {controller}", "", "[kernel]", *table(data["kernel"])]
    for comp in data["compensators"]:
        lines += ["", "[[compensators]]", *table(comp)]
    return "\n".join(lines) + "\n"


def save_controller_file(controller: Controller, path: str | os.PathLike[str]) -> None:
    """Write a controller file (format by suffix), atomically: no half-written file is left behind."""
    path = Path(path)
    suffix = _suffix(path)
    text = controller_toml(controller) if suffix == ".toml" else json.dumps(controller.to_dict(), indent=2) + "\n"
    try:
        atomic_write(path, lambda handle: handle.write(text.encode("utf-8")))
    except OSError as exc:
        raise ControllerError(f"cannot write controller file {path}: {exc.strerror or exc}; check the folder") from None

__all__ = ["SUFFIXES", "controller_toml", "load_controller_file", "save_controller_file"]
