"""Build pendulab's native FMUs: shared wrapper + one model folder -> ``fmus/<Name>.fmu``.

The FMI 2.0 FMUs (Plant, Controller, Supervisor) use ``c/fmi2_wrapper.c``; the FMI 3.0 ones
(:data:`~pendulab.fmu.models.FMI3_MODELS`, e.g. Plant3) the same model folder with ``c/fmi3_wrapper.c``.
Both wrappers only translate their API: the FMI logic is ``c/fmu_common.c``'s, compiled into every FMU.

Examples
--------
>>> from pendulab.fmu.build import ensure_fmu
>>> path = ensure_fmu("Plant")          # builds fmus/Plant.fmu on first use   # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import os
import platform
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path
from typing import Callable, Iterable

import fmpy

from pendulab.errors import FmuBuildError
from pendulab.fmu.description import ModelSpec, documentation_html, model_description_xml, variables_header
from pendulab.fmu.models import ALL_FMUS, FMI3_MODELS, MODELS
from pendulab.native import PREBUILT_DIR, WIN64_COMPILER, cache_dir, compile_shared, compiler_needed, find_compiler, library_suffix

PACKAGE_DIR = Path(__file__).resolve().parents[1]
WRAPPER_DIR = Path(__file__).resolve().parent / "c"
MODELS_DIR = Path(__file__).resolve().parent / "models"
FMI_HEADERS = Path(fmpy.__file__).resolve().parent / "c-code"
_STAMP = "pendulab-build "
#: The wrapper of each FMI version, and its binaries' platform folders (native Linux, win64).
WRAPPERS = {2: "fmi2_wrapper.c", 3: "fmi3_wrapper.c"}
#: The FMI logic both wrappers share, and the headers every FMU's sources/ carries (variables.h is generated).
COMMON_SOURCE = "fmu_common.c"
COMMON_HEADERS = ("fmu_model.h", "fmu_common.h")
PLATFORM_DIRS = {2: {"Linux": "linux64", "Darwin": "darwin64", "Windows": "win64"},
                 3: {"Linux": "x86_64-linux", "Darwin": "x86_64-darwin", "Windows": "x86_64-windows"}}


#: The FMUs the wheel carries, prebuilt (linux64 and win64 binaries, with their sources).
PREBUILT_FMUS = PREBUILT_DIR / "fmus"


def checkout_dir() -> Path | None:
    """The repository root when pendulab runs from a checkout (an editable install), else None."""
    repo = PACKAGE_DIR.parents[1]
    return repo if (repo / "build_fmus.py").is_file() else None


def default_fmu_dir() -> Path:
    """Where FMUs are built: ``$PENDULAB_FMU_DIR`` (``--fmus DIR``), else ``fmus/`` at the root of a
    checkout, else a per-user cache folder."""
    override = os.environ.get("PENDULAB_FMU_DIR")
    if override:
        return Path(override)
    repo = checkout_dir()
    if repo is not None:
        return repo / "fmus"
    return cache_dir("fmus")


def source_hash() -> str:
    """Hash of everything an FMU is built from; a change rebuilds the FMUs on next use."""
    digest = hashlib.sha256()
    for folder in ("fmu", "model"):
        for path in sorted((PACKAGE_DIR / folder).rglob("*")):
            if path.suffix in (".py", ".c", ".h") and "__pycache__" not in path.parts:
                digest.update(path.relative_to(PACKAGE_DIR).as_posix().encode())
                digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def model_spec(name: str) -> ModelSpec:
    """The spec of FMU ``name``; an FMI 3.0 FMU is its model's spec under its own identifier."""
    if name in FMI3_MODELS:
        spec = model_spec(FMI3_MODELS[name])
        return dataclasses.replace(spec, identifier=name, fmi_version=3, description=f"{spec.description} (FMI 3.0)")
    if name not in MODELS:
        raise FmuBuildError(f"unknown FMU {name!r}; known ones are {', '.join(ALL_FMUS)}")
    return importlib.import_module(MODELS[name]).spec()


def model_dir(name: str) -> Path:
    """The model folder an FMU is built from (an FMI 3.0 FMU shares its FMI 2.0 model's)."""
    return MODELS_DIR / FMI3_MODELS.get(name, name).lower()


def platform_dir(fmi_version: int = 2, system: str | None = None) -> str:
    """The ``binaries/`` folder of this platform (or ``system``'s, 64 bit) for an FMU of ``fmi_version``."""
    if sys.maxsize <= 2**32 and fmi_version == 2:
        return {"Linux": "linux32", "Windows": "win32"}[system or platform.system()]
    return PLATFORM_DIRS[fmi_version][system or platform.system()]


def _compile(compiler: str, sources: list[Path], include_dirs: list[Path], output: Path, windows: bool) -> None:
    flags = ["-O2", "-std=c99"]
    if not windows and any(s.name in WRAPPERS.values() for s in sources):
        # An FMU exports only the FMI API (marked by fmi2Functions.h / fmi3Functions.h). Hidden internals are also called
        # directly instead of through the PLT, and can be inlined: the plant's step is ~30 % faster.
        flags.append("-fvisibility=hidden")
    compile_shared(compiler, sources, output, include_dirs=include_dirs, flags=flags, windows=windows)


def build_fmu(name: str, out_dir: Path | None = None, *, cross_compile: bool = True) -> Path:
    """Build ``<out_dir>/<name>.fmu`` (native binary, win64 where possible, with ``sources/``).

    Parameters
    ----------
    name : {"Plant", "Controller", "Supervisor", "Plant3"}
        Plant3 is the plant as an FMI 3.0 FMU; the others are FMI 2.0.
    out_dir : Path, optional
        Default :func:`default_fmu_dir`.
    cross_compile : bool
        Also build a win64 binary where the mingw-w64 cross compiler is installed.
    """
    out_dir = Path(out_dir or default_fmu_dir())
    out_dir.mkdir(parents=True, exist_ok=True)
    compiler = find_compiler()
    if not compiler:
        raise compiler_needed(f"building {name}.fmu from source")
    spec = model_spec(name)
    wrapper = WRAPPERS[spec.fmi_version]
    with tempfile.TemporaryDirectory(prefix=f"pendulab-{name}-") as tmp:
        root = Path(tmp) / "fmu"
        sources_dir = root / "sources"
        sources_dir.mkdir(parents=True)
        for filename in (*COMMON_HEADERS, COMMON_SOURCE, wrapper):
            shutil.copy(WRAPPER_DIR / filename, sources_dir / filename)
        for path in model_dir(name).iterdir():
            if path.suffix in (".c", ".h"):
                shutil.copy(path, sources_dir / path.name)
        for filename in spec.sources:  # a model made of shared C (c/state_space.c) names it among its sources
            if not (sources_dir / filename).exists() and filename not in spec.generated:
                shutil.copy(WRAPPER_DIR / filename, sources_dir / filename)
        for filename, text in spec.generated.items():
            (sources_dir / filename).write_text(text)
        (sources_dir / "variables.h").write_text(variables_header(spec))
        c_files = [wrapper, COMMON_SOURCE, *spec.sources]
        (root / "modelDescription.xml").write_text(model_description_xml(spec, c_files))
        (root / "documentation").mkdir()
        (root / "documentation" / "index.html").write_text(documentation_html(spec), encoding="utf-8")
        (sources_dir / "buildDescription.xml").write_text(_build_description(spec.identifier, c_files))

        binaries = root / "binaries"
        suffix = library_suffix()
        native = binaries / platform_dir(spec.fmi_version) / f"{spec.identifier}{suffix}"
        native.parent.mkdir(parents=True)
        sources = [sources_dir / f for f in c_files]
        _compile(compiler, sources, [sources_dir, FMI_HEADERS], native, windows=platform.system() == "Windows")
        if cross_compile and platform.system() != "Windows" and shutil.which(WIN64_COMPILER):
            win = binaries / platform_dir(spec.fmi_version, "Windows") / f"{spec.identifier}.dll"
            win.parent.mkdir(parents=True)
            _compile(WIN64_COMPILER, sources, [sources_dir, FMI_HEADERS], win, windows=True)

        # Write next to the target and rename: a reader never sees a half-written FMU.
        fd, partial = tempfile.mkstemp(dir=out_dir, prefix=f".{name}-", suffix=".fmu.part")
        os.close(fd)
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as zf:
            for path in sorted(root.rglob("*")):
                if path.is_file():
                    zf.write(path, path.relative_to(root).as_posix())
            zf.comment = (_STAMP + source_hash()).encode()
        target = out_dir / f"{name}.fmu"
        os.chmod(partial, 0o644)  # mkstemp creates 0600; an FMU is shared like any build product
        os.replace(partial, target)
    return target


def _build_description(identifier: str, c_files: Iterable[str]) -> str:
    files = "\n".join(f'      <SourceFile name="{f}"/>' for f in c_files)
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<fmiBuildDescription fmiVersion="3.0">\n'
        f'  <BuildConfiguration modelIdentifier="{identifier}">\n'
        '    <SourceFileSet language="C99">\n'
        f"{files}\n"
        "    </SourceFileSet>\n"
        "  </BuildConfiguration>\n"
        "</fmiBuildDescription>\n"
    )


def is_current(path: Path) -> bool:
    """Whether ``path`` is an FMU built from the current sources (and, where mingw-w64 has been installed
    since, with its win64 binary)."""
    try:
        with zipfile.ZipFile(path) as zf:
            if zf.comment.decode(errors="replace") != _STAMP + source_hash():
                return False
            wants_win64 = platform.system() != "Windows" and shutil.which(WIN64_COMPILER) is not None
            win64 = {f"binaries/{platform_dir(v, 'Windows')}/" for v in PLATFORM_DIRS}
            return not wants_win64 or any(n.startswith(tuple(win64)) for n in zf.namelist())
    except (OSError, zipfile.BadZipFile):
        return False


def find_fmu(name: str, out_dir: Path | None = None) -> Path | None:
    """The ``<name>.fmu`` to use without building anything, or None (see :func:`ensure_fmu` for the order)."""
    explicit = out_dir or os.environ.get("PENDULAB_FMU_DIR")
    candidates = [Path(explicit) / f"{name}.fmu"] if explicit else []
    if checkout_dir() is None:
        candidates += [Path.cwd() / "fmus" / f"{name}.fmu", PREBUILT_FMUS / f"{name}.fmu"]
    candidates.append(default_fmu_dir() / f"{name}.fmu")
    for path in candidates:
        if path.is_file() and (is_current(path) or not _ours(path) or find_compiler() is None or path.parent == PREBUILT_FMUS):
            return path
    return None


def _ours(path: Path) -> bool:
    """Whether ``path`` was built by pendulab (a user's own FMU is used as it is, never rebuilt)."""
    try:
        with zipfile.ZipFile(path) as zf:
            return zf.comment.startswith(_STAMP.encode())
    except (OSError, zipfile.BadZipFile):
        return False


def ensure_fmu(name: str, out_dir: Path | None = None, *, progress: Callable[[str], None] | None = None) -> Path:
    """Path of ``<name>.fmu``; built first only where no usable one exists.

    The first found is used: ``out_dir`` (or ``$PENDULAB_FMU_DIR``, which ``--fmus DIR`` sets); in an
    installed package, the user's ``fmus/`` in the current folder, then the FMUs prebuilt inside the
    package; last :func:`default_fmu_dir`. An FMU pendulab built from older sources is rebuilt where a
    C compiler exists; a user's own FMU is never rebuilt. With nothing found, the FMU is built into
    :func:`default_fmu_dir` (a C compiler is needed: :class:`~pendulab.native.CompilerNeeded` says how).

    Examples
    --------
    >>> ensure_fmu("Plant").name
    'Plant.fmu'
    """
    found = find_fmu(name, out_dir)
    if found is not None:
        return found
    if progress:
        progress(f"building {name}.fmu (first use) ...")
    return build_fmu(name, Path(out_dir) if out_dir else None)


def build_all(out_dir: Path | None = None, names: Iterable[str] | None = None, *, progress: Callable[[str], None] = print) -> list[Path]:
    """Build every FMU (or the named ones) and return their paths."""
    paths = []
    if platform.system() != "Windows" and shutil.which(WIN64_COMPILER) is None:
        progress(f"no win64 binaries: the mingw-w64 cross compiler ({WIN64_COMPILER}) is not installed "
                 "(apt-get install gcc-mingw-w64-x86-64); building for this platform only")
    for name in names or ALL_FMUS:
        progress(f"building {name}.fmu")
        paths.append(build_fmu(name, out_dir))
    return paths
