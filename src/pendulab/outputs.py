"""The one rule for everything pendulab writes (runs, calibrations, logs, plots, comparisons).

Every command that writes (``simulate``, ``lab``, ``calibrate``, ``fit``, ``compare``, the GUI, sweeps)
follows the same three rules, all implemented here:

1. **Checked before any work.** Each output path is checked when the command starts, before a rig
   moves or a simulation runs: a folder that cannot be created or written, a file name that is a
   folder, a folder name that is a file, all give one line (:class:`~pendulab.errors.UserError`, exit
   status 2). The check really creates (and removes) a hidden file where the outputs will go, so a
   read-only disk or a missing permission is found even for the administrator.
2. **An earlier result is never overwritten.** A run folder that already holds a run's files, or an
   output file that already exists, is refused unless the user says ``--overwrite``; then the earlier
   run's files (only those: a user's own notes stay) are removed before the new work starts, and the
   command says so. Without ``--out``, a new numbered folder is chosen (:func:`new_run_folder`).
3. **Atomic files with the user's umask.** Files are written to a hidden temporary file beside the
   final name and moved into place (:func:`atomic_write`): a crash never leaves a truncated file under
   the final name. The temporary file is created with mode 0666 less the umask (not the 0600 of
   :func:`tempfile.mkstemp`), so a calibration is readable like a run folder on a shared lab PC.

Examples
--------
>>> import tempfile, pathlib
>>> base = pathlib.Path(tempfile.mkdtemp())
>>> folder = check_run_folder(base / "run1")          # checked, not yet created
>>> folder.prepare().is_dir()
True
>>> _ = atomic_write(folder.path / "run.csv", lambda f: f.write(b"t\\n0\\n"))
>>> check_run_folder(base / "run1")                    # doctest: +IGNORE_EXCEPTION_DETAIL
Traceback (most recent call last):
pendulab.errors.UserError: --out .../run1 holds an earlier run (run.csv); give a new folder, or add --overwrite to replace it
>>> check_run_folder(base / "run1", overwrite=True).prepare(announce=lambda text: None).exists()
True
"""

from __future__ import annotations

import os
import secrets
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

from pendulab.errors import UserError

#: Files a run folder holds (``simulate``, ``lab``, ``lab --compare``, ``compare``).
RUN_FILES = frozenset({
    "run.mat", "run.csv", "metrics.json", "rig_log.csv", "timing.json", "comparison.txt", "comparison.png",
    "rig.gif", "loop.ssp", "results.parquet", "journal.jsonl", "sweep.toml",
})
#: Plots, animations and tables of a run (any name: the plot set grows; a sweep's parts).
RUN_SUFFIXES = (".png", ".gif", ".parquet")
#: Sub-folders that are part of a run (``lab --compare`` simulates into ``simulation/``; a sweep writes
#: ``parts/`` and ``plots/``; ``simulate --robust`` its rigs' sweep into ``robust/`` and the worst rig's run into ``worst/``).
RUN_SUBFOLDERS = ("simulation", "parts", "plots", "robust", "worst")


# ------------------------------------------------------------------------------------------ checks
def _say(text: str) -> None:
    print(text, flush=True)


def _probe(folder: Path, option: str, target: Path) -> None:
    """Create and remove a hidden file in the existing ``folder``: the only check that sees a read-only
    disk, an ACL or a missing permission the same way for every user (root passes ``os.access``)."""
    try:
        fd, tmp = create_temporary(folder, ".pendulab-write-check")
    except OSError as exc:
        raise UserError(
            f"{option} {target}: cannot write in {folder} ({exc.strerror or exc}); choose a folder you can write to"
        ) from None
    os.close(fd)
    tmp.unlink(missing_ok=True)


def _check_creatable(folder: Path, option: str, target: Path) -> None:
    """``folder`` exists and takes files, or can be created (its nearest existing ancestor takes folders)."""
    ancestor = folder if str(folder) else Path(".")
    while not ancestor.exists():
        if ancestor.is_symlink():  # a dangling link: mkdir would fail on it
            raise UserError(f"{option} {target}: {ancestor} is a broken link; choose another place")
        parent = ancestor.parent
        if parent == ancestor:
            break
        ancestor = parent
    if not ancestor.is_dir():
        raise UserError(f"{option} {target}: {ancestor} is a file, not a folder; choose another place")
    _probe(ancestor, option, target)


def check_output_file(
    path: str | os.PathLike[str],
    option: str = "--out",
    *,
    suffixes: Sequence[str] = (),
    overwrite: bool = False,
) -> Path:
    """Check an output file before any work: a file name, a writable place, no earlier file (unless ``overwrite``).

    Parameters
    ----------
    path : path
        The file to be written.
    option : str
        The option that named it, for the message (``--out``, ``--log``, ``--plot``).
    suffixes : sequence of str
        Accepted suffixes (lower case, with the dot); empty accepts any.
    overwrite : bool
        Allow replacing an existing file (the user's ``--overwrite``); it is replaced atomically at the end.

    Returns
    -------
    Path

    Raises
    ------
    UserError
        One line naming what is wrong and how to fix it.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> check_output_file(pathlib.Path(tempfile.mkdtemp()) / "new" / "c.json", "--out", suffixes=(".json",)).name
    'c.json'
    """
    target = Path(path)
    if not str(path).strip():
        raise UserError(f"{option} is empty; give a file name")
    if target.is_dir():
        raise UserError(f"{option} {target} is a directory; give a file name such as {target / ('output' + (suffixes[0] if suffixes else ''))}")
    if suffixes and target.suffix.lower() not in suffixes:
        raise UserError(f"{option} {target} must be a {' or '.join(suffixes)} file")
    if (target.exists() or target.is_symlink()) and not overwrite:
        raise UserError(f"{option} {target} exists (an earlier result); give another name, or add --overwrite to replace it")
    _check_creatable(target.parent, option, target)
    return target


def check_folder(path: str | os.PathLike[str], option: str = "--out") -> Path:
    """Check a folder of build products or caches (replaced freely): not a file, writable or creatable."""
    folder = Path(path)
    if folder.exists() and not folder.is_dir():
        raise UserError(f"{option} {folder} is a file; give a folder name")
    _check_creatable(folder, option, folder)
    return folder


def earlier_run_files(folder: str | os.PathLike[str]) -> list[Path]:
    """The files (and run sub-folders) of an earlier run in ``folder``; a user's other files are not listed."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    found = []
    for entry in sorted(folder.iterdir()):
        if entry.is_dir():
            if entry.name in RUN_SUBFOLDERS and earlier_run_files(entry):
                found.append(entry)
        elif entry.name in RUN_FILES or entry.suffix.lower() in RUN_SUFFIXES:
            found.append(entry)
    return found


@dataclass
class RunFolder:
    """A checked run folder: :meth:`prepare` makes it ready when the work starts."""

    path: Path
    #: The earlier run's files that :meth:`prepare` removes (``--overwrite`` given).
    earlier: list[Path] = field(default_factory=list)

    def prepare(self, announce: Callable[[str], None] = _say) -> Path:
        """Remove the earlier run's files (saying which), create the folder; returns its path."""
        if self.earlier:
            for entry in self.earlier:
                if entry.is_dir():
                    for inner in earlier_run_files(entry):
                        _remove(inner)
                    try:
                        entry.rmdir()  # only if the user kept nothing else there
                    except OSError:
                        pass
                else:
                    _remove(entry)
            announce(f"--overwrite: removed the earlier run in {self.path} ({', '.join(e.name for e in self.earlier)})")
            self.earlier = []
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UserError(f"cannot create the folder {self.path}: {exc.strerror or exc}; choose another --out") from None
        return self.path


def _remove(path: Path) -> None:
    try:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink(missing_ok=True)
    except OSError as exc:
        raise UserError(f"--overwrite: cannot remove {path} ({exc.strerror or exc}); remove it yourself or choose a new folder") from None


def check_run_folder(path: str | os.PathLike[str], option: str = "--out", *, overwrite: bool = False) -> RunFolder:
    """Check a run folder before any work: a folder (not a file), writable, holding no earlier run.

    An existing folder with only other files (a user's notes) is accepted and they are kept. A folder
    holding an earlier run is refused unless ``overwrite``; then :meth:`RunFolder.prepare` removes that
    run's files when the work starts. Nothing is created or removed here.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> check_run_folder(pathlib.Path(tempfile.mkdtemp()) / "run").earlier
    []
    """
    folder = Path(path)
    if not str(path).strip():
        raise UserError(f"{option} is empty; give a folder name")
    if folder.exists() and not folder.is_dir():
        raise UserError(f"{option} {folder} is a file; give a folder name")
    earlier = earlier_run_files(folder)
    if earlier and not overwrite:
        names = ", ".join(e.name for e in earlier[:5]) + (", ..." if len(earlier) > 5 else "")
        raise UserError(f"{option} {folder} holds an earlier run ({names}); give a new folder, or add --overwrite to replace it")
    _check_creatable(folder, option, folder)
    return RunFolder(folder, earlier)


def new_run_folder(name: str, base: str | os.PathLike[str] = "runs") -> RunFolder:
    """A new folder ``base/<date>-<time>-name`` (``-2``, ``-3``, ... if taken), checked.

    Examples
    --------
    >>> import tempfile
    >>> new_run_folder("demo", tempfile.mkdtemp()).path.name.endswith("-demo")
    True
    """
    stamp = time.strftime("%Y%m%d-%H%M%S")
    first = Path(base) / f"{stamp}-{name}"
    folder, k = first, 1
    while folder.exists():
        k += 1
        folder = Path(f"{first}-{k}")
    return check_run_folder(folder)


def run_folder(path: str | os.PathLike[str] | None, name: str, *, overwrite: bool = False, option: str = "--out") -> RunFolder:
    """The run folder a command writes: ``path`` checked (:func:`check_run_folder`), or a new one under ``runs/``."""
    if path is None:
        return new_run_folder(name)
    return check_run_folder(path, option, overwrite=overwrite)


# ------------------------------------------------------------------------------------------ writing
def atomic_write(path: str | os.PathLike[str], write: Any) -> Path:
    """Call ``write(binary_file)`` on a temporary file beside ``path``, then move it to ``path``.

    Used for every file pendulab writes (plots and animations too), so that a crash or an error
    never leaves a truncated file under the final name. The file gets the user's umask.

    Examples
    --------
    >>> import tempfile, os, stat
    >>> path = atomic_write(os.path.join(tempfile.mkdtemp(), "a.txt"), lambda f: f.write(b"ok"))
    >>> path.read_bytes(), stat.S_IMODE(path.stat().st_mode) == 0o666 & ~_umask()
    (b'ok', True)
    """
    path = Path(path)
    tmp = write_temporary(path.parent, path.name, write)
    try:
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def create_temporary(folder: str | os.PathLike[str], name: str) -> tuple[int, Path]:
    """Create a new hidden temporary file for ``name`` in ``folder``; returns ``(fd, path)``.

    Unlike :func:`tempfile.mkstemp` the file gets the normal permissions (0666 less the umask),
    so the file that replaces the final name is readable like any other output.
    """
    stem, dot, suffix = name.rpartition(".")
    for _ in range(100):
        # Keep the real suffix last: some writers (Pillow) pick the format from it.
        tmp = Path(folder) / f".{stem or name}.{secrets.token_hex(4)}.tmp{dot}{suffix if dot else ''}"
        try:
            return os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"cannot create a temporary file for {name} in {folder}")


def write_temporary(folder: str | os.PathLike[str], name: str, write: Any) -> Path:
    """``write(binary_file)`` into a new temporary file for ``name`` in ``folder``, flushed to disk; its path."""
    fd, tmp = create_temporary(folder, name)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
