"""Compiled C, once per machine: the one place that finds a C compiler, compiles and caches.

pendulab compiles three kinds of C: the FMUs (:mod:`pendulab.fmu.build`), the co-simulation master's
step-plan runner (``cosim/c/plan_runner.c``) and the fit's CasADi-generated functions
(:mod:`pendulab.calibration`). A lab PC has no C compiler, so:

* the FMUs and the plan runner come **prebuilt** inside the installed wheel (``pendulab/prebuilt/``);
  :func:`shared_library` finds a prebuilt library by the hash of its source before it looks for a compiler;
* the fit's functions depend on the log (its shape, the parameters held fixed), so they cannot be
  prebuilt: without a compiler the fit evaluates them in CasADi's virtual machine (slower; it says so);
* a feature that truly needs a compiler raises :class:`CompilerNeeded`, whose one line says which
  compiler and how to get it (:func:`compiler_needed`).

Compiled libraries are cached under :func:`cache_dir` by a hash of their source and flags, written
atomically (a second process building the same library at once is harmless).

Examples
--------
>>> from pathlib import Path
>>> from pendulab.native import shared_library
>>> # skipped: the path and whether it was built depend on the machine
>>> lib = shared_library(Path("plan_runner.c"))        # prebuilt, cached, or compiled now   # doctest: +SKIP
>>> lib.path, lib.built                                  # doctest: +SKIP
(PosixPath('/home/me/.cache/pendulab/native/plan_runner-3f2a9c1d0b7e.so'), False)
"""

from __future__ import annotations

import hashlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import NamedTuple, Sequence

from pendulab.errors import FmuBuildError, UserError

#: Where the wheel build puts the prebuilt FMUs (``fmus/``) and helper libraries.
PREBUILT_DIR = Path(__file__).resolve().parent / "prebuilt"
#: The cross compiler for win64 binaries on Linux (Debian: gcc-mingw-w64-x86-64).
WIN64_COMPILER = "x86_64-w64-mingw32-gcc"
#: Compiler names tried in this order after ``$CC``.
COMPILER_NAMES = ("cc", "gcc", "clang")
SUFFIXES = {"Linux": ".so", "Darwin": ".dylib", "Windows": ".dll"}
#: What the fit tells its user when it cannot compile (the factor: bench/wheel.py, CPU time of a whole fit
#: of a 1-iteration ramp-test log, compiled functions cached against CasADi's virtual machine).
VM_FALLBACK_NOTE = "no C compiler: CasADi's virtual machine evaluates the fit, about 55x the CPU time"


class CompilerNeeded(UserError, FmuBuildError):
    """A feature needs a C compiler and none was found; the message says how to get one (exit status 2)."""


class CompileFailed(FmuBuildError):
    """The compiler ran and failed; the message holds its command line and its errors."""


class Library(NamedTuple):
    """A compiled shared library: where it is, and whether this call compiled it."""

    path: Path
    built: bool


def find_compiler() -> str | None:
    """The C compiler to use: ``$CC`` if set, else the first of :data:`COMPILER_NAMES` on the PATH, else None."""
    cc = os.environ.get("CC", "").strip()
    if cc:
        return cc
    for name in COMPILER_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None


def install_hint(system: str | None = None) -> str:
    """How to get a C compiler on this platform (or ``system``), as a short clause."""
    system = system or platform.system()
    if system == "Windows":
        return "install MinGW-w64 gcc (e.g. 'winget install BrechtSanders.WinLibs.POSIX.UCRT') and put its bin folder on PATH, or set CC"
    if system == "Darwin":
        return "install the Xcode command line tools ('xcode-select --install') or set CC"
    return "install gcc ('apt-get install gcc' on Debian/Ubuntu, 'dnf install gcc' on Fedora) or set CC"


def compiler_needed(feature: str, system: str | None = None) -> CompilerNeeded:
    """The one-line error for ``feature``, which cannot work without a C compiler.

    Examples
    --------
    >>> print(compiler_needed("building the FMUs from source", "Linux"))
    building the FMUs from source needs a C compiler, and none was found: install gcc ('apt-get install gcc' on Debian/Ubuntu, 'dnf install gcc' on Fedora) or set CC
    """
    return CompilerNeeded(f"{feature} needs a C compiler, and none was found: {install_hint(system)}")


def library_suffix(system: str | None = None) -> str:
    """``.so``, ``.dylib`` or ``.dll``: a shared library's file ending on this platform (or ``system``)."""
    return SUFFIXES[system or platform.system()]


def cache_dir(kind: str = "native") -> Path:
    """The per-user cache folder for ``kind`` (``$PENDULAB_CACHE``, else the platform's cache folder)."""
    root = os.environ.get("PENDULAB_CACHE")
    if not root:
        if sys.platform == "win32":
            root = os.path.join(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local", "pendulab", "Cache")
        else:
            root = os.path.join(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache", "pendulab")
    return Path(root) / kind


def library_name(source: bytes, stem: str, flags: Sequence[str] = (), salt: str = "", system: str | None = None) -> str:
    """File name of the library compiled from ``source`` with ``flags``: ``<stem>-<hash><suffix>``.

    The hash covers the source, the flags and ``salt`` (e.g. a code generator's version), so a changed
    source never loads an old library; the wheel build names its prebuilt libraries the same way.
    """
    digest = hashlib.sha256(source + "\0".join([*flags, salt]).encode()).hexdigest()[:12]
    return f"{stem}-{digest}{library_suffix(system)}"


def compile_shared(
    compiler: str,
    sources: Sequence[Path],
    output: Path,
    *,
    include_dirs: Sequence[Path] = (),
    flags: Sequence[str] = (),
    windows: bool | None = None,
    timeout: float = 600,
) -> None:
    """Compile C ``sources`` into the shared library ``output``; raises :class:`CompileFailed`.

    ``windows`` (default: this platform, or a mingw-w64 ``compiler``) links libgcc statically so that the
    DLL needs only what every Windows has; elsewhere the code is position independent.
    """
    if windows is None:
        windows = platform.system() == "Windows" or "mingw" in Path(compiler).name
    platform_flags = ["-static-libgcc"] if windows else ["-fPIC"]
    command = [compiler, "-shared", *platform_flags, "-fno-math-errno", *flags, *(f"-I{d}" for d in include_dirs),
               *map(str, sources), "-o", str(output), "-lm"]
    try:
        result = subprocess.run(command, capture_output=True, text=True, timeout=timeout)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise CompileFailed(f"compiling {output.name} failed: {' '.join(command)}: {exc}") from None
    if result.returncode != 0:
        first = next((line for line in result.stderr.splitlines() if "error" in line.lower()), "") or \
            (result.stderr.strip().splitlines() or [f"exit status {result.returncode}"])[0]
        raise CompileFailed(f"compiling {output.name} with {compiler} failed: {first.strip()}\n{' '.join(command)}\n{result.stderr}")


def shared_library(
    source: Path | str,
    stem: str | None = None,
    *,
    flags: Sequence[str] = ("-O2",),
    salt: str = "",
    kind: str = "native",
    prebuilt: bool = True,
    feature: str | None = None,
) -> Library | None:
    """The shared library compiled from C ``source`` (a file, or the C text itself): prebuilt, cached or compiled now.

    Parameters
    ----------
    source : Path or str
        A C file, or its text (generated code).
    stem : str, optional
        The library's name before its hash (default: the file's stem).
    flags : sequence of str
        Compiler flags (optimization, ``-fopenmp``, ...); part of the library's hash.
    salt : str
        More to hash (a code generator's version).
    kind : str
        The cache's sub-folder.
    prebuilt : bool
        Look in the package's :data:`PREBUILT_DIR` first (the wheel's libraries).
    feature : str, optional
        If given, a missing compiler raises :func:`compiler_needed` for this feature and a failed
        compile raises :class:`CompileFailed`; if not, both return None (the caller has a fallback).

    Returns
    -------
    Library or None
    """
    if isinstance(source, Path):
        text, stem = source.read_bytes(), stem or source.stem
    else:
        text = source.encode()
    if not stem:
        raise ValueError("a library compiled from C text needs a stem")
    name = library_name(text, stem, flags, salt)
    if prebuilt and (PREBUILT_DIR / name).is_file():
        return Library(PREBUILT_DIR / name, False)
    target = cache_dir(kind) / name
    if target.is_file():
        return Library(target, False)
    compiler = find_compiler()
    if compiler is None:
        if feature:
            raise compiler_needed(feature)
        return None
    with tempfile.TemporaryDirectory(prefix="pendulab-cc-") as tmp:
        c_file = Path(tmp, f"{stem}.c")
        c_file.write_bytes(text)
        built = Path(tmp, name)
        try:
            compile_shared(compiler, [c_file], built, flags=flags)
        except CompileFailed:
            if feature:
                raise
            return None
        os.chmod(built, 0o755)
        return Library(_keep(built, target), True)


def _keep(built: Path, target: Path) -> Path:
    """Move ``built`` to ``target`` atomically (a reader never sees half a library); without a writable
    cache, into a temporary folder that outlives this process."""
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, staged = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".part")
        os.close(fd)
        shutil.copyfile(built, staged)
        os.chmod(staged, 0o755)
        os.replace(staged, target)
        return target
    except OSError:
        keep = Path(tempfile.mkdtemp(prefix="pendulab-cc-")) / target.name
        shutil.copyfile(built, keep)
        return keep
