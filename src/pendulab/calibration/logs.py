"""Calibration logs: time, voltage, cart position (and optionally the angle).

A log is read from

- a CSV file with a header naming ``t``, ``V``, ``x`` (s, V, m) and optionally ``alpha`` (rad); other columns and ``#`` lines are ignored, or
- the ``run.csv`` / ``run.mat`` of ``pendulab simulate``: ``voltage`` is read as ``V``, ``alpha_measured`` (else ``alpha``) as the angle, or
- a folder of the old MATLAB lab's logs (one ``.mat`` per signal, see :func:`read_old_lab_folder`).

Sample ``k`` means: ``x[k]`` (and ``alpha[k]``) measured at ``t[k]``, and ``V[k]`` applied from ``t[k]`` until ``t[k+1]``.

Examples
--------
>>> import numpy as np
>>> log = RampLog(t=np.arange(5) * 1e-3, V=np.zeros(5), x=np.zeros(5))
>>> round(log.period, 6), log.duration
(0.001, 0.004)
"""

from __future__ import annotations

import contextlib
import csv
import io
import os
from dataclasses import dataclass, field, replace
from datetime import datetime
from pathlib import Path
from typing import Sequence

import numpy as np

from pendulab.analysis.results import atomic_write
from pendulab.errors import CalibrationError

#: Accepted column names, first match wins.
TIME_NAMES = ("t", "time")
VOLTAGE_NAMES = ("V", "voltage", "V_applied", "u")
POSITION_NAMES = ("x", "x_measured")
ANGLE_PREFERRED = ("alpha_measured", "alpha")  # a simulate log has both: the encoder reading is what a rig gives


@dataclass(frozen=True)
class RampLog:
    """One logged run: ``t``, ``V``, ``x`` (and ``alpha``) as equally long float arrays.

    Attributes
    ----------
    t, V, x : ndarray
        Seconds, volts, metres; ``t`` strictly increasing.
    alpha : ndarray or None
        Pendulum angle from upright (rad), when logged.
    source : str
        Where the log came from (file name or ``"virtual rig"``).
    interrupted : bool
        The run was stopped early (Ctrl-C, a signal, the rig); the log holds what was measured until then.
    events : tuple of (time, text)
        Notes of the procedure (iterations, breakaways, track limits).
    end_reason : str
        Why a ramp test ended early ("" when it did not).
    iterations_done, iterations_done_at : int or None, float or None
        Ramp test: how many iterations finished, and the time the last of them finished.
    """

    t: np.ndarray
    V: np.ndarray
    x: np.ndarray
    alpha: np.ndarray | None = None
    source: str = ""
    interrupted: bool = False
    events: tuple[tuple[float, str], ...] = field(default=())
    end_reason: str = ""
    iterations_done: int | None = None
    iterations_done_at: float | None = None

    def __post_init__(self) -> None:
        for name in ("t", "V", "x", "alpha"):
            if (value := getattr(self, name)) is not None:
                object.__setattr__(self, name, np.asarray(value, dtype=float).ravel())
        validate_log(self)

    def __len__(self) -> int:
        return len(self.t)

    @property
    def period(self) -> float:
        """Median sample period (s)."""
        return float(np.median(np.diff(self.t))) if len(self.t) > 1 else 0.0

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if len(self.t) else 0.0

    def slice(self, first: int, stop: int) -> "RampLog":
        """Samples ``first`` to ``stop - 1``."""
        part = slice(first, stop)
        return replace(self, t=self.t[part], V=self.V[part], x=self.x[part], alpha=None if self.alpha is None else self.alpha[part])

    def between(self, start: float, stop: float) -> "RampLog":
        """The samples with ``start <= t < stop``."""
        return self.slice(*np.searchsorted(self.t, [start, stop]))  # t increases (validate_log)


def encoder_step(x: np.ndarray) -> float:
    """The encoder step of logged positions (or angles): the smallest change that recurs, 0 if unquantized.

    The one rule for the ramp-test extraction and the fit (its rests and noise floor). Quantized data changes by whole multiples of one step; the step
    is the median of the smallest changes, so that a stray tiny difference (a rounding in a CSV) does not pass for it.

    Examples
    --------
    >>> x = 2e-5 * np.round(np.cumsum(np.random.default_rng(1).normal(0, 1e-4, 500)) / 2e-5)
    >>> round(encoder_step(x) * 1e6, 3), encoder_step(np.linspace(0, 1, 50) ** 2)
    (20.0, 0.0)
    """
    dx = np.abs(np.diff(np.asarray(x, dtype=float)))
    dx = dx[dx > 1e-12]
    if dx.size < 10:
        return 0.0
    q = float(np.median(np.sort(dx)[: max(5, dx.size // 100)]))
    multiples = dx / q
    return q if np.mean(np.abs(multiples - np.round(multiples)) < 0.05) > 0.9 else 0.0


def validate_log(log: RampLog) -> None:
    """Raise :class:`CalibrationError` (one line) for unequal lengths, NaN or non-increasing time."""
    where = f"log {log.source}" if log.source else "log"
    n = len(log.t)
    columns = {name: value for name in ("t", "V", "x", "alpha") if (value := getattr(log, name)) is not None}
    for name, value in columns.items():
        if len(value) != n:
            raise CalibrationError(f"{where}: column {name} has {len(value)} values but t has {n}")
    if n < 2:
        raise CalibrationError(f"{where} has {n} sample(s); a calibration log needs a ramp of many samples")
    for name, value in columns.items():
        bad = np.flatnonzero(~np.isfinite(value))
        if bad.size:
            k = int(bad[0])
            raise CalibrationError(f"{where}: {name} is not finite (NaN or inf) in sample {k + 1} (t={log.t[k]:g} s); remove or repair that row")
    steps = np.diff(log.t)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        fix = ("a repeated time stamp: write t with more digits (or remove the repeated row)" if steps[k - 1] == 0
               else "time goes backwards: sort the log by time")
        raise CalibrationError(f"{where}: time is not increasing at sample {k + 1} (t={float(log.t[k])!r} s after {float(log.t[k - 1])!r} s); {fix}")


def _pick(names: Sequence[str], available: Sequence[str]) -> str | None:
    """The first of ``names`` in ``available``, else the first there in another case (None if none is)."""
    lowered = {a.lower(): a for a in available}
    found = [name for name in names if name in available]
    found += [lowered[name.lower()] for name in names if name.lower() in lowered and name != "V"]  # 'v' is not the voltage (it may be a speed)
    return found[0] if found else None


def read_log(path: str | os.PathLike[str]) -> RampLog:
    """Read a CSV log or a ``run.mat`` (see the module docstring), or a folder of the old lab's logs.

    Parameters
    ----------
    path : path
        ``.csv`` (columns ``t``, ``V``/``voltage``, ``x``, optional ``alpha``), a ``run.mat``, or a folder.

    Returns
    -------
    RampLog

    Examples
    --------
    >>> import tempfile, pathlib
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "log.csv"
    >>> _ = path.write_text("t,V,x\\n0,0,0\\n0.001,0.5,0\\n0.002,1.0,2.275e-05\\n")
    >>> log = read_log(path)
    >>> log.period, float(log.x[-1])
    (0.001, 2.275e-05)

    Raises
    ------
    CalibrationError
        Missing file or column, a value that is not a number, NaN, non-increasing time.
    """
    path = Path(path)
    if path.is_dir():
        columns = read_old_lab_folder(path)
        return RampLog(t=columns["t"], V=columns["voltage"], x=columns["x"], alpha=columns["alpha"], source=str(path))
    if not path.is_file():
        raise CalibrationError(f"log {path} does not exist")
    columns = _read_mat(path) if path.suffix.lower() == ".mat" else _read_csv(path)
    available = list(columns)
    accepted = {"t": TIME_NAMES, "V": VOLTAGE_NAMES, "x": POSITION_NAMES}
    picked = {label: _pick(("voltage", *names) if label == "V" else names, available) for label, names in accepted.items()}  # 'voltage' before V, u
    missing = [label for label, name in picked.items() if name is None]
    if missing:
        raise CalibrationError(
            f"log {path} has no column {', '.join(missing)} (found: {', '.join(available) or 'none'}); a log needs columns t, V, x "
            f"(s, V, m), each a vector: {'name the variable' if path.suffix.lower() == '.mat' else 'rename the column in the header'} ({'; '.join(f'{m} is read from ' + ', '.join(accepted[m][:-1]) + ' or ' + accepted[m][-1] for m in missing)})"
        )
    a_name = _pick(ANGLE_PREFERRED, available)
    return RampLog(**{label: columns[name] for label, name in picked.items()}, alpha=columns[a_name] if a_name else None, source=str(path))


def _read_csv(path: Path) -> dict[str, np.ndarray]:
    try:
        text = path.read_text(encoding="utf-8-sig")  # Excel's "CSV UTF-8" starts with a byte-order mark
    except UnicodeDecodeError as exc:
        raise CalibrationError(f"log {path} is not UTF-8 text ({exc.reason} at byte {exc.start}); save it as UTF-8 (or plain ASCII) CSV") from None
    except OSError as exc:
        raise CalibrationError(f"log {path} cannot be read: {exc.strerror or exc}") from None
    lines = [(i + 1, line) for i, line in enumerate(text.splitlines()) if line.strip() and not line.lstrip().startswith("#")
             and not (i == 0 and line.startswith("sep="))]  # Excel's line naming the separator, which the header shows too
    if not lines:
        raise CalibrationError(f"log {path} is empty; expected a CSV header naming t, V, x and rows of numbers")
    header_line = lines[0][1]
    delimiter = next((d for d in (",", ";", "\t") if d in header_line), None)

    def split(line: str) -> list[str]:
        return line.split() if delimiter is None else next(csv.reader([line], delimiter=delimiter))

    if len(lines) > 1 and not text.endswith(("\n", "\r")):
        # A last row without a line end was cut off mid-write (a crash, a full disk, a copy stopped early), possibly mid-number: a wrong value.
        raise CalibrationError(f"log {path}, line {lines[-1][0]}: the file ends in the middle of this row (no line end): it was cut off; "
                               f"delete that line (or add a line end if the row is complete) and run again")
    header = [h.strip() for h in split(header_line)]
    if any(_is_number(h) for h in header):
        raise CalibrationError(f"log {path} has no header line; the first line must name the columns, e.g. 't,V,x'")
    twice = sorted({h for h in header if h and header.count(h) > 1})
    if twice:
        raise CalibrationError(f"log {path}: column {twice[0]} appears twice in the header; rename or remove one")
    used = {*TIME_NAMES, *VOLTAGE_NAMES, *POSITION_NAMES, *ANGLE_PREFERRED}
    values: dict[str, list[float]] = {name: [] for name in header if name}
    first_clock: dict[str, datetime] = {}  # a time column of clock times: seconds from its first
    for line_no, line in lines[1:]:
        row = split(line)
        if len(row) != len(header):
            raise CalibrationError(f"log {path}, line {line_no}: {len(row)} fields but the header (line {lines[0][0]}: {header_line.strip()[:40]!r}) "
                                   f"has {len(header)}; remove any lines above the header, or repair the row")
        for name, cell in zip(header, row):
            if not name:
                continue
            cell = cell.strip()
            try:
                values[name].append(float(cell))
            except ValueError:
                if name.lower() in TIME_NAMES and (clock := _clock_time(cell)) is not None:
                    first = first_clock.setdefault(name, clock)
                    if (clock.tzinfo is None) != (first.tzinfo is None):  # datetime cannot subtract one from the other
                        raise CalibrationError(f"log {path}, line {line_no}: {name}={cell!r} has {'no' if clock.tzinfo is None else 'a'} time zone "
                                               "and the first row's time has the other; give every time with its zone or none") from None
                    values[name].append((clock - first).total_seconds())
                elif name in used or name.lower() in {u.lower() for u in used if u != "V"}:
                    hint = ("write numbers with a decimal point, not a comma" if "," in cell and _is_number(cell.replace(",", "."))
                            else "fill the cell or remove the row" if not cell else "repair or remove the row")
                    raise CalibrationError(f"log {path}, line {line_no}: {name}={cell!r} is not a number; {hint}") from None
                else:
                    values[name].append(float("nan"))  # a text column we do not use (e.g. a state name)
    return {name: np.asarray(v, dtype=float) for name, v in values.items()}


def _clock_time(cell: str) -> datetime | None:
    """A clock time as a logger writes it: '14:03:07.125', or with its date ('2026-11-28 14:03:07.125', ISO 8601)."""
    for text in (cell, f"2000-01-01T{cell}"):
        with contextlib.suppress(ValueError):
            return datetime.fromisoformat(text)
    return None


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_mat(path: Path) -> dict[str, np.ndarray]:
    """Column vectors of a ``run.mat`` (or any .mat of column vectors), by variable name."""
    return {name: array.astype(float).ravel() for name, array in read_mat_variables(path, what=f"log {path}").items()
            if array.dtype.kind in "fiub" and array.ndim <= 2 and array.size > 0 and (array.ndim < 2 or 1 in array.shape)}


def read_mat_variables(path: Path, what: str) -> dict[str, np.ndarray]:
    """Numeric and other arrays of a MATLAB ``.mat`` file, MAT v5 (SciPy) or v7.3 (HDF5, h5py).

    v7.3 stores arrays column-major; transposed back to MATLAB's shape. Structs and cell arrays come back as object arrays (v5) or are skipped (v7.3).

    Raises
    ------
    CalibrationError
        Unreadable or corrupt file (one line, naming ``what``).
    """
    import scipy.io

    try:
        contents = scipy.io.loadmat(str(path), squeeze_me=False)
    except Exception as exc:  # scipy raises several kinds for a corrupt file
        # MAT v7.3 is HDF5 (NotImplementedError), also where written without MATLAB's text header
        if isinstance(exc, NotImplementedError) or _is_hdf5(path):
            return _read_mat_hdf5(path, what)
        raise CalibrationError(f"{what} is not a readable MATLAB .mat file: {exc}") from None
    return {k: np.asarray(v) for k, v in contents.items() if not k.startswith("__")}


def _is_hdf5(path: Path) -> bool:
    try:
        import h5py

        return bool(h5py.is_hdf5(path))
    except (ImportError, OSError):
        return False


def _read_mat_hdf5(path: Path, what: str) -> dict[str, np.ndarray]:
    import h5py

    variables: dict[str, np.ndarray] = {}
    try:
        with h5py.File(path, "r") as handle:
            for name, item in handle.items():
                if name.startswith("#") or not isinstance(item, h5py.Dataset):
                    continue  # '#refs#' and struct groups
                kind = item.attrs.get("MATLAB_class", b"double")
                kind = kind.decode() if isinstance(kind, bytes) else str(kind)
                if kind in ("char", "cell", "struct") or item.dtype.kind not in "fiub":
                    continue
                variables[name] = np.zeros((0,), dtype=float) if item.attrs.get("MATLAB_empty", 0) else np.asarray(item[()]).T  # column-major on disk
    except OSError as exc:
        raise CalibrationError(f"{what} is not a readable MATLAB .mat file: {exc}") from None
    return variables


# ------------------------------------------------------------------------------ old-lab log folders
#: Words in a file (or variable) name that say which signal an old-lab .mat file holds.
_OLD_LAB_SIGNALS = {
    "alpha": ("angle", "alpha", "theta", "pend"),
    "x": ("position", "pos", "cart", "x"),
    "voltage": ("voltage", "volt", "vm", "u", "v"),
}


def _signal_of(name: str) -> str | None:
    """``alpha``, ``x`` or ``voltage`` for a file/variable name, by whole words first, then substrings."""
    stem = name.lower()
    words = "".join(c if c.isalnum() else " " for c in stem).split()
    for matches in (lambda k: k in words, lambda k: len(k) > 2 and k in stem):  # whole words first, then substrings
        for signal, keys in _OLD_LAB_SIGNALS.items():
            if any(map(matches, keys)):
                return signal
    return None


def _two_column(path: Path) -> np.ndarray:
    """The ``[t, value]`` array of one old-lab .mat file, as ``(n, 2)`` sorted by strictly increasing t."""
    variables = read_mat_variables(path, what=f"old-lab log file {path}")
    arrays = [np.asarray(v, dtype=float) for v in variables.values() if v.dtype.kind in "fiub" and v.ndim == 2 and 2 in v.shape and v.size > 4]
    if len(arrays) != 1:
        found = ", ".join(f"{k} {tuple(v.shape)}" for k, v in variables.items()) or "no variables"
        raise CalibrationError(f"old-lab log file {path} must hold one two-column [t, value] array (found: {found})")
    data = arrays[0] if arrays[0].shape[1] == 2 else arrays[0].T
    data = data[np.all(np.isfinite(data), axis=1)]
    data = data[np.argsort(data[:, 0], kind="stable")]
    data = data[np.concatenate(([True], np.diff(data[:, 0]) > 0))]  # repeated time stamps: keep the first
    if len(data) < 2:
        raise CalibrationError(f"old-lab log file {path} holds fewer than 2 finite samples")
    return data


def read_old_lab_folder(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """Read a folder of the old MATLAB lab's logs: one ``.mat`` per signal, each ``[t, value]``.

    The old lab saved each signal in its own file (MAT v5 or v7.3), a two-column array at a variable time step, told by its file name
    (``angle``/``alpha``/``theta``/``pend``, ``position``/``pos``/``cart``/``x``, ``voltage``/``volt``/``vm``/``u``/``v``) else its variable's name.

    The columns are put on one uniform time base: the time span all three cover, at the median sample period of the finest signal. Position and angle
    are interpolated linearly; the voltage is held (zero-order hold, as a DAC holds it), so ``voltage[k]`` is what was applied from ``t[k]`` on.

    Units and conventions (what can be told from the data, and only that):

    * angle: radians; if its largest magnitude exceeds ``2*pi + 0.5`` it is taken as degrees. If its median magnitude is above ``pi/2`` the log was
      zeroed with the pendulum hanging (the old lab's encoder zero), and ``alpha`` is wrapped to the upright convention ``alpha - pi`` in
      ``(-pi, pi]``; the sign is kept as logged (it cannot be told from the data).
    * position: metres; if its largest magnitude exceeds 1.5 m (longer than the track) it is taken as millimetres.
    * voltage: volts, as logged.

    Parameters
    ----------
    path : path-like
        The folder.

    Returns
    -------
    dict of str to ndarray
        ``t`` (s, starting where the signals start), ``alpha`` (rad, upright convention), ``x`` (m), ``voltage`` (V), equally long.

    Raises
    ------
    CalibrationError
        (a :class:`~pendulab.errors.UserError`) Not a folder, no .mat files, a signal missing or given twice, a file that is not one ``[t, value]``
        array, signals that do not overlap in time.
    """
    folder = Path(path)
    if not folder.is_dir():
        raise CalibrationError(f"old-lab log folder {folder} does not exist or is not a folder")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() == ".mat" and p.is_file())
    if not files:
        raise CalibrationError(f"old-lab log folder {folder} holds no .mat files; expected one .mat per signal (angle, position, voltage)")
    found: dict[str, Path] = {}
    for file in files:
        signal = _signal_of(file.stem) or next((s for s in map(_signal_of, read_mat_variables(file, what=f"old-lab log file {file}")) if s), None)
        if signal is None:
            continue  # another file in the folder
        if signal in found:
            raise CalibrationError(f"old-lab log folder {folder} has two {signal} files ({found[signal].name}, {file.name}); keep one per signal")
        found[signal] = file
    missing = [s for s in ("alpha", "x", "voltage") if s not in found]
    if missing:
        label = {"alpha": "angle", "x": "position", "voltage": "voltage"}
        raise CalibrationError(f"old-lab log folder {folder} has no {', '.join(label[m] for m in missing)} file "
                               f"(found: {', '.join(p.name for p in files)}); name the files angle.mat, position.mat, voltage.mat")
    data = {signal: _two_column(file) for signal, file in found.items()}
    t0 = max(d[0, 0] for d in data.values())
    t1 = min(d[-1, 0] for d in data.values())
    spans = {signal: float(d[-1, 0] - d[0, 0]) for signal, d in data.items()}
    longest = max(spans.values())
    short = min(spans, key=spans.__getitem__)
    if spans[short] < 0.5 * longest:
        # The signals are used where all of them were logged: one cut short would silently cut the others.
        raise CalibrationError(f"old-lab log folder {folder}: {found[short].name} covers {spans[short]:.3g} s but the other signals "
                               f"{longest:.3g} s; it looks cut short (copied or saved incompletely): replace it with the complete file")
    if not t1 > t0:
        raise CalibrationError(f"old-lab log folder {folder}: the signals do not overlap in time; they must come from one run")
    period = min(float(np.median(np.diff(d[:, 0]))) for d in data.values())
    n = int(np.floor((t1 - t0) / period + 1e-9)) + 1
    if n < 2:
        raise CalibrationError(f"old-lab log folder {folder}: the signals overlap for less than one sample period")
    t = t0 + period * np.arange(n)
    x, alpha = (np.interp(t, data[signal][:, 0], data[signal][:, 1]) for signal in ("x", "alpha"))
    tv, vv = data["voltage"][:, 0], data["voltage"][:, 1]
    # Held from each logged time on; a rounding error of the new time base must not pick the sample before.
    voltage = vv[np.clip(np.searchsorted(tv, t + 1e-6 * period, side="right") - 1, 0, len(vv) - 1)]
    if np.max(np.abs(x)) > 1.5:
        x = x * 1e-3
    if np.max(np.abs(alpha)) > 2 * np.pi + 0.5:
        alpha = np.radians(alpha)
    if np.median(np.abs(alpha)) > np.pi / 2:
        alpha = np.mod(alpha, 2 * np.pi) - np.pi  # hanging zero -> upright (alpha - pi), in [-pi, pi)
    return {"t": t, "alpha": alpha, "x": x, "voltage": voltage}


def write_log(log: RampLog, path: str | os.PathLike[str]) -> Path:
    """Write ``log`` as CSV (``t,V,x[,alpha]``), atomically."""
    path = Path(path)
    names = ["t", "V", "x"] + (["alpha"] if log.alpha is not None else [])
    header = [f"# pendulab calibration log; source: {log.source or 'unknown'}", *(f"# event t={at:.4f}: {text}" for at, text in log.events), ",".join(names)]
    buffer = io.StringIO()
    np.savetxt(buffer, np.column_stack([getattr(log, n) for n in names]), delimiter=",", fmt="%.10g", header="\n".join(header), comments="")
    path.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(path, lambda handle: handle.write(buffer.getvalue().encode("utf-8")))
