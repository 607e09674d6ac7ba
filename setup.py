"""Build hooks: a pendulab wheel carries every compiled part prebuilt, so nothing compiles on a lab PC.

Everything else is in pyproject.toml. Building a wheel (``python -m build``, or ``build_wheels.py`` for
both platforms) compiles, into the wheel's ``pendulab/prebuilt/``:

* the four FMUs, each with linux64 and win64 binaries and its ``sources/`` (needs a C compiler and
  the mingw-w64 cross compiler);
* the co-simulation master's step-plan runner for the wheel's platform (``cc`` for Linux,
  ``x86_64-w64-mingw32-gcc`` for ``--plat-name win_amd64``).

The wheel's tag is ``py3-none-<platform>``: no Python extension, binaries for one platform. A Linux
wheel is tagged manylinux for the newest glibc symbol version its binaries use. An editable install
(a checkout) builds nothing here: it builds ``fmus/`` on first use, as ``build_fmus.py`` does.
"""

from __future__ import annotations

import re
import shutil
import sys
import zipfile
from pathlib import Path

from setuptools import Distribution, setup
from setuptools.command.build_py import build_py

try:
    from setuptools.command.bdist_wheel import bdist_wheel
except ImportError:  # setuptools < 70
    from wheel.bdist_wheel import bdist_wheel

ROOT = Path(__file__).resolve().parent
WINDOWS_PLATFORMS = ("win_amd64",)
#: manylinux2014: the oldest glibc a wheel is tagged for.
MIN_GLIBC = (2, 17)


def _wheel_platform(command) -> str:
    """The platform the wheel is built for: bdist_wheel's ``--plat-name``, else this machine's."""
    plat = command.distribution.get_command_obj("bdist_wheel").plat_name
    if plat:
        return plat.replace("-", "_").replace(".", "_")
    return "win_amd64" if sys.platform == "win32" else "linux_x86_64"


class build_with_binaries(build_py):
    """build_py, then the FMUs and the plan runner compiled into ``pendulab/prebuilt/``."""

    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):
            return
        sys.path.insert(0, str(ROOT / "src"))
        from pendulab.cosim.master import PLAN_RUNNER_FLAGS, PLAN_RUNNER_SOURCE
        from pendulab.fmu.build import build_all, checkout_dir
        from pendulab.native import WIN64_COMPILER, compile_shared, compiler_needed, find_compiler, library_name

        windows = _wheel_platform(self) in WINDOWS_PLATFORMS
        prebuilt = Path(self.build_lib) / "pendulab" / "prebuilt"
        shutil.rmtree(prebuilt, ignore_errors=True)  # a build folder reused for another platform
        (prebuilt / "fmus").mkdir(parents=True)
        assert checkout_dir() is not None, "setup.py builds from the source tree"
        build_all(prebuilt / "fmus", progress=lambda line: print(f"pendulab: {line}"))
        compiler = WIN64_COMPILER if windows else find_compiler()
        if compiler is None:
            raise compiler_needed("building a pendulab wheel")
        name = library_name(PLAN_RUNNER_SOURCE.read_bytes(), PLAN_RUNNER_SOURCE.stem, PLAN_RUNNER_FLAGS,
                            system="Windows" if windows else "Linux")
        compile_shared(compiler, [PLAN_RUNNER_SOURCE], prebuilt / name, flags=PLAN_RUNNER_FLAGS, windows=windows)
        for fmu in (prebuilt / "fmus").glob("*.fmu"):
            members = zipfile.ZipFile(fmu).namelist()
            if not any(m.endswith(".dll") for m in members):
                raise SystemExit(f"{fmu.name} has no win64 binary: install the mingw-w64 cross compiler ({WIN64_COMPILER})")
        print(f"pendulab: prebuilt {sorted(p.name for p in prebuilt.rglob('*') if p.is_file())}")


def _glibc_needed(folder: Path) -> tuple[int, int]:
    """The newest ``GLIBC_x.y`` symbol version any Linux binary under ``folder`` (or inside its FMUs) uses."""
    blobs = [p.read_bytes() for p in folder.rglob("*.so")]
    for fmu in folder.rglob("*.fmu"):
        with zipfile.ZipFile(fmu) as zf:
            blobs += [zf.read(n) for n in zf.namelist() if n.endswith(".so")]
    versions = [tuple(map(int, m)) for blob in blobs for m in re.findall(rb"GLIBC_(\d+)\.(\d+)", blob)]
    return max([MIN_GLIBC, *versions])


class BinaryDistribution(Distribution):
    """Says it holds binaries, so the wheel is a platform wheel installed into platlib."""

    def has_ext_modules(self) -> bool:
        return True


class platform_wheel(bdist_wheel):
    """A ``py3-none-<platform>`` wheel: pure Python plus one platform's binaries (no Python extension)."""

    def get_tag(self) -> tuple[str, str, str]:
        plat = _wheel_platform(self)
        if plat.startswith("linux_"):
            major, minor = _glibc_needed(Path(self.bdist_dir))
            plat = f"manylinux_{major}_{minor}_{plat.removeprefix('linux_')}"
        return "py3", "none", plat


setup(distclass=BinaryDistribution, cmdclass={"build_py": build_with_binaries, "bdist_wheel": platform_wheel})
