"""setuptools' build backend, plus what building a wheel compiles with.

setup.py compiles the FMUs into the wheel: it generates their C from the CasADi model and imports the
model folders' variable tables, which import pendulab's own modules (and so its run-time dependencies).
A wheel's build therefore needs the project's dependencies; an editable install or an sdist does not, and
stays as quick as setuptools alone.
"""

import re
from pathlib import Path

from setuptools import build_meta as _setuptools
from setuptools.build_meta import *  # noqa: F403 - the backend's hooks, the one below extended


def _dependencies() -> list[str]:
    """``[project] dependencies`` of pyproject.toml (read by pattern: tomllib is not in Python 3.10)."""
    text = (Path(__file__).resolve().parent / "pyproject.toml").read_text()
    block = re.search(r"^dependencies\s*=\s*\[(.*?)^\]", text, re.S | re.M)
    return re.findall(r'"([^"]+)"', block.group(1)) if block else []


def get_requires_for_build_wheel(config_settings=None):
    return _setuptools.get_requires_for_build_wheel(config_settings) + _dependencies()
