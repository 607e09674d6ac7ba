"""Calibration logs: time, voltage, cart position (and optionally the angle).

A log is read from

- a CSV file whose header names at least ``t``, ``V`` and ``x`` (seconds, volts, metres; ``alpha`` in
  radians optional; other columns are ignored; lines starting with ``#`` are comments), or
- the ``run.csv`` / ``run.mat`` that ``pendulab simulate`` writes (columns ``t``, ``x``, ``voltage``,
  ``alpha_measured``, ...): ``voltage`` is used as ``V``, ``alpha_measured`` (else ``alpha``) as the angle.

Sample ``k`` means: ``x[k]`` (and ``alpha[k]``) measured at ``t[k]``, and ``V[k]`` applied from
``t[k]`` until ``t[k+1]``.

Examples
--------
>>> import numpy as np
>>> log = RampLog(t=np.arange(5) * 1e-3, V=np.zeros(5), x=np.zeros(5))
>>> round(log.period, 6), log.duration
(0.001, 0.004)
"""

from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from pendulab.analysis.results import atomic_write
from pendulab.errors import CalibrationError

#: Accepted column names, first match wins.
TIME_NAMES = ("t", "time")
VOLTAGE_NAMES = ("V", "voltage", "V_applied", "u")
POSITION_NAMES = ("x", "x_measured")
ANGLE_NAMES = ("alpha", "alpha_measured")
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
        The run was stopped early (Ctrl-C); the log holds what was measured until then.
    events : tuple of (time, text)
        Notes of the procedure (iterations, breakaways, track limits).
    """

    t: np.ndarray
    V: np.ndarray
    x: np.ndarray
    alpha: np.ndarray | None = None
    source: str = ""
    interrupted: bool = False
    events: tuple[tuple[float, str], ...] = field(default=())

    def __post_init__(self) -> None:
        for name in ("t", "V", "x", "alpha"):
            value = getattr(self, name)
            if value is not None:
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

    def between(self, start: float, stop: float) -> "RampLog":
        """The samples with ``start <= t < stop``."""
        keep = (self.t >= start) & (self.t < stop)
        alpha = None if self.alpha is None else self.alpha[keep]
        return RampLog(self.t[keep], self.V[keep], self.x[keep], alpha, self.source, self.interrupted, self.events)


def validate_log(log: RampLog) -> None:
    """Raise :class:`CalibrationError` (one line) for unequal lengths, NaN or non-increasing time."""
    where = f"log {log.source}" if log.source else "log"
    n = len(log.t)
    for name in ("V", "x", "alpha"):
        value = getattr(log, name)
        if value is not None and len(value) != n:
            raise CalibrationError(f"{where}: column {name} has {len(value)} values but t has {n}")
    if n < 2:
        raise CalibrationError(f"{where} has {n} sample(s); a calibration log needs a ramp of many samples")
    for name in ("t", "V", "x", "alpha"):
        value = getattr(log, name)
        if value is None:
            continue
        bad = np.flatnonzero(~np.isfinite(value))
        if bad.size:
            k = int(bad[0])
            raise CalibrationError(f"{where}: {name} is not finite (NaN or inf) in sample {k + 1} (t={log.t[k]:g} s); remove or repair that row")
    steps = np.diff(log.t)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise CalibrationError(
            f"{where}: time is not increasing at sample {k + 1} (t={log.t[k]:g} s after {log.t[k - 1]:g} s); sort the log by time"
        )


def _pick(names: Sequence[str], available: Sequence[str]) -> str | None:
    for name in names:
        if name in available:
            return name
    lowered = {a.lower(): a for a in available}
    for name in names:
        if name.lower() in lowered and name != "V":  # 'v' is not the voltage (it may be a speed)
            return lowered[name.lower()]
    return None


def read_log(path: str | os.PathLike[str]) -> RampLog:
    """Read a CSV log or a ``run.mat`` (see the module docstring).

    Raises
    ------
    CalibrationError
        Missing file or column, a value that is not a number, NaN, non-increasing time.
    """
    path = Path(path)
    if not path.is_file():
        raise CalibrationError(f"log {path} does not exist")
    if path.suffix.lower() == ".mat":
        columns = _read_mat(path)
    else:
        columns = _read_csv(path)
    available = list(columns)
    t_name = _pick(TIME_NAMES, available)
    v_name = _pick(VOLTAGE_NAMES if "voltage" not in available else ("voltage",), available)
    x_name = _pick(POSITION_NAMES, available)
    missing = [label for label, name in (("t", t_name), ("V", v_name), ("x", x_name)) if name is None]
    if missing:
        raise CalibrationError(
            f"log {path} has no column {', '.join(missing)} (found: {', '.join(available) or 'none'}); "
            "a log needs columns t, V, x (s, V, m)"
        )
    a_name = _pick(ANGLE_PREFERRED, available)
    assert t_name and v_name and x_name
    return RampLog(
        t=columns[t_name],
        V=columns[v_name],
        x=columns[x_name],
        alpha=columns[a_name] if a_name else None,
        source=str(path),
    )


def _read_csv(path: Path) -> dict[str, np.ndarray]:
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"log {path} cannot be read as text: {exc}") from None
    lines = [(i + 1, line) for i, line in enumerate(text.splitlines()) if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise CalibrationError(f"log {path} is empty; expected a CSV header naming t, V, x and rows of numbers")
    header_line = lines[0][1]
    delimiter = next((d for d in (",", ";", "\t") if d in header_line), None)

    def split(line: str) -> list[str]:
        if delimiter is None:
            return line.split()
        return next(csv.reader([line], delimiter=delimiter))

    header = [h.strip() for h in split(header_line)]
    if any(_is_number(h) for h in header):
        raise CalibrationError(f"log {path} has no header line; the first line must name the columns, e.g. 't,V,x'")
    used = {*TIME_NAMES, *VOLTAGE_NAMES, *POSITION_NAMES, *ANGLE_NAMES}
    values: dict[str, list[float]] = {name: [] for name in header if name}
    for line_no, line in lines[1:]:
        row = split(line)
        if len(row) != len(header):
            raise CalibrationError(f"log {path}, line {line_no}: {len(row)} fields but the header has {len(header)}")
        for name, cell in zip(header, row):
            if not name:
                continue
            cell = cell.strip()
            try:
                values[name].append(float(cell))
            except ValueError:
                if name in used or name.lower() in {u.lower() for u in used if u != "V"}:
                    raise CalibrationError(f"log {path}, line {line_no}: {name}={cell!r} is not a number") from None
                values[name].append(float("nan"))  # a text column we do not use (e.g. a state name)
    return {name: np.asarray(v, dtype=float) for name, v in values.items()}


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_mat(path: Path) -> dict[str, np.ndarray]:
    import scipy.io

    try:
        contents = scipy.io.loadmat(str(path), squeeze_me=True)
    except NotImplementedError:
        raise CalibrationError(f"log {path} is a MATLAB v7.3 (HDF5) file; save it with save(..., '-v7') and retry") from None
    except Exception as exc:
        raise CalibrationError(f"log {path} is not a readable MATLAB .mat file: {exc}") from None
    columns: dict[str, np.ndarray] = {}
    for name, value in contents.items():
        if name.startswith("__"):
            continue
        try:
            array = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            continue  # structs (meta), strings
        if array.ndim <= 2 and array.size > 0 and (array.ndim < 2 or 1 in array.shape):
            columns[name] = array.ravel()
    return columns


def write_log(log: RampLog, path: str | os.PathLike[str]) -> Path:
    """Write ``log`` as CSV (``t,V,x[,alpha]``), atomically."""
    path = Path(path)
    names = ["t", "V", "x"] + (["alpha"] if log.alpha is not None else [])
    data = np.column_stack([getattr(log, n) for n in names])
    buffer = io.StringIO()
    buffer.write(f"# pendulab calibration log; source: {log.source or 'unknown'}\n")
    for time, text in log.events:
        buffer.write(f"# event t={time:.4f}: {text}\n")
    buffer.write(",".join(names) + "\n")
    np.savetxt(buffer, data, delimiter=",", fmt="%.10g")
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda handle: handle.write(buffer.getvalue().encode("utf-8")))
    return path


Log = RampLog
