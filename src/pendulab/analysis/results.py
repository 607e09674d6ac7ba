"""The files of a run (SPEC §7): ``run.mat``, ``run.csv``, ``metrics.json``, and a streamed CSV log.

``run.mat`` is a MATLAB 5 file (readable by every MATLAB version since 5 and by Octave): each column
a column vector of doubles, plus a ``meta`` struct with ``controller``, ``parameters``,
``calibration``, ``pendulum`` and ``version``. ``run.csv`` has a header line and the same columns with
15 significant digits (relative error below 1e-14; short decimals such as ``0.001`` or ``2`` read back
exactly), formatted as whole arrays so that a long run's CSV costs little; ``run.mat`` holds the exact
doubles. Every file is written to a temporary file in the same folder first and
moved into place with :func:`os.replace`, so a crash never leaves a half-written file behind.

Examples
--------
>>> import tempfile, numpy as np
>>> n = 5
>>> cols = {name: np.zeros(n) for name in COLUMNS} | {"t": np.linspace(0, 0.004, n)}
>>> out = tempfile.mkdtemp()
>>> paths = write_results(out, cols, {"pendulum": "long"}, {"stable": True})
>>> sorted(paths)
['csv', 'mat', 'metrics']
>>> columns, meta = read_run(out)
>>> float(columns["t"][-1]), meta["pendulum"]
(0.004, 'long')
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import os
import re
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping, Sequence

import numpy as np
import scipy.io

import pendulab
from pendulab.errors import UserError
from pendulab.outputs import atomic_write, create_temporary  # noqa: F401 - re-exported
from pendulab.outputs import write_temporary as _write_temporary

#: The columns of every run file, in this order (SPEC §7).
COLUMNS = ("t", "x", "xdot", "alpha", "alpha_measured", "tip", "voltage_command", "voltage", "supervisor_state")
#: The seesaw's run columns (its runs have the tilt ``theta`` where the pendulum's have ``alpha``; no tip).
SEESAW_COLUMNS = ("t", "x", "xdot", "theta", "theta_measured", "x_measured", "voltage_command", "voltage", "supervisor_state")


def is_seesaw_run(columns: Mapping[str, Any]) -> bool:
    """Whether run columns are the seesaw's (its tilt ``theta`` where the pendulum's runs have ``alpha``).

    Examples
    --------
    >>> is_seesaw_run(dict.fromkeys(SEESAW_COLUMNS)), is_seesaw_run(dict.fromkeys(COLUMNS))
    (True, False)
    """
    return "theta" in columns and "alpha" not in columns


def run_columns(columns: Mapping[str, Any]) -> tuple[str, ...]:
    """The columns every run of that plant has: :data:`SEESAW_COLUMNS` for a seesaw run, else :data:`COLUMNS`."""
    return SEESAW_COLUMNS if is_seesaw_run(columns) else COLUMNS


#: The fields the ``meta`` struct always has (empty when not given).
META_FIELDS = ("controller", "parameters", "calibration", "pendulum", "version")
FILE_NAMES = {"mat": "run.mat", "csv": "run.csv", "metrics": "metrics.json"}

# MATLAB 5 names: a letter, then letters, digits, underscores; at most 31 characters.
_MATLAB_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,30}$")


# ------------------------------------------------------------------------------------------ write
def write_results(
    out_dir: str | os.PathLike[str],
    columns: Mapping[str, Any],
    meta: Mapping[str, Any],
    metrics: Mapping[str, Any],
) -> dict[str, Path]:
    """Write ``run.mat``, ``run.csv`` and ``metrics.json`` into ``out_dir`` (created if missing).

    Parameters
    ----------
    out_dir : path
        Output folder.
    columns : mapping of name -> 1-D array
        At least every name in :data:`COLUMNS`, all of the same length; further columns (valid
        MATLAB names) are written after them.
    meta : mapping
        ``controller`` (string or mapping), ``parameters`` (mapping or :class:`PlantParameters`),
        ``calibration`` (mapping or string), ``pendulum`` (string), ``version`` (defaults to the
        package version), and any other entries. Nested mappings become MATLAB structs, ``None``
        an empty array.
    metrics : mapping
        Written to ``metrics.json`` (indent 2); non-finite numbers become ``null``.

    Returns
    -------
    dict
        ``{"mat": Path, "csv": Path, "metrics": Path}``.

    Raises
    ------
    ValueError
        Missing or malformed columns (a programming error, not a user's).
    UserError
        The output folder cannot be created or written.
    """
    names, data = column_table(columns)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise UserError(f"output folder {out} is a file; give a folder name for --out")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create output folder {out}: {exc.strerror or exc}; choose another --out") from None

    mat_meta = matlab_meta(meta)
    writers = {
        "mat": lambda f: scipy.io.savemat(
            f,
            {**{n: data[:, i : i + 1] for i, n in enumerate(names)}, "meta": mat_meta},  # column views, no copies
            format="5",
            oned_as="column",
        ),
        "metrics": lambda f: f.write((json.dumps(json_safe(metrics), indent=2, allow_nan=False) + "\n").encode()),
    }
    # Write every file to a temporary name first, then move them all into place: a failure half
    # way leaves the previous run's files (or none), never a mixture or a truncated file.
    temporaries: dict[str, Path] = {}
    try:
        # run.csv, the slow one (formatting a million numbers), is written by a thread while run.mat
        # and metrics.json are (numpy's array operations, file writes and fsync release the GIL).
        with ThreadPoolExecutor(max_workers=1) as pool:
            csv_file = pool.submit(_write_temporary, out, FILE_NAMES["csv"], lambda f: f.writelines(_csv_blocks(names, data)))
            try:
                for key, write in writers.items():
                    temporaries[key] = _write_temporary(out, FILE_NAMES[key], write)
            finally:
                temporaries["csv"] = csv_file.result()
        paths = {}
        for key, tmp in temporaries.items():
            paths[key] = out / FILE_NAMES[key]
            os.replace(tmp, paths[key])
        return paths
    except OSError as exc:
        raise UserError(f"cannot write results to {out}: {exc.strerror or exc}; check the folder's permissions and free space") from None
    finally:
        for tmp in temporaries.values():
            tmp.unlink(missing_ok=True)


def column_table(columns: Mapping[str, Any]) -> tuple[list[str], np.ndarray]:
    """A run's columns as one table: the names in file order and a 2-D array, one column per name.

    The order is the one every run file has: the required columns (:data:`COLUMNS`, or
    :data:`SEESAW_COLUMNS` for a seesaw run, told by its ``theta`` column) first, then any other
    column in the given order. :func:`write_results` writes this table; :func:`csv_bytes` formats it.

    Parameters
    ----------
    columns : Mapping[str, array_like]
        Column name -> 1-D array (or an n x 1 / 1 x n array); all of one length.

    Returns
    -------
    names : list of str
        The column names in file order.
    data : numpy.ndarray
        ``len(t) x len(names)`` floats.

    Raises
    ------
    ValueError
        A required column is missing, a name is not a MATLAB variable name, a column is not 1-D,
        or the lengths differ.

    Examples
    --------
    >>> import numpy as np
    >>> cols = {"extra": np.ones(3)} | {name: np.zeros(3) for name in COLUMNS}
    >>> names, data = column_table(cols)
    >>> names[0], names[-1], data.shape
    ('t', 'extra', (3, 10))
    """
    required = run_columns(columns)
    missing = [name for name in required if name not in columns]
    if missing:
        raise ValueError(f"run columns lack {', '.join(missing)}; every run has {', '.join(required)}")
    names = list(required) + [name for name in columns if name not in required]
    arrays = []
    for name in names:
        if not _MATLAB_NAME.match(name):
            raise ValueError(f"column name {name!r} is not a MATLAB variable name (letter, then letters/digits/_; max 31)")
        array = np.asarray(columns[name], dtype=float)
        if array.ndim == 2 and 1 in array.shape:
            array = array.reshape(-1)
        if array.ndim != 1:
            raise ValueError(f"column {name!r} has shape {array.shape}; give a 1-D array")
        arrays.append(array)
    lengths = {a.size for a in arrays}
    if len(lengths) > 1:
        detail = ", ".join(f"{n}={a.size}" for n, a in zip(names, arrays))
        raise ValueError(f"run columns differ in length ({detail})")
    return names, np.column_stack(arrays) if arrays[0].size else np.zeros((0, len(names)))


#: Significant digits in run.csv: the decimal mantissa stays below 2**53, so numpy's int64 holds it
#: exactly and every step of the formatting is a whole-array operation (run.mat keeps the exact values).
CSV_DIGITS = 15

# Each number's text is built in a fixed field of 24 bytes, held as three little-endian 64-bit words
# so that every step of the formatting is one operation on whole arrays of words:
#   byte 0 sign, 1 first digit, 2 decimal point, 3-16 the other 14 digits (word 0: bytes 0-7,
#   word 1: 8-15, word 2: 16-23), 17-21 the exponent ("e-123"), 23 the separator.
# Bytes a number does not use are 0 and are dropped when a block of rows is joined.
_WORD = np.dtype("<u8")
_FIELD_WORDS = 3
_FIELD_TEXT = 23  # bytes 0-22: the longest text a field holds


def _digit_table(count: int, places: Sequence[int | None]) -> np.ndarray:
    """For every ``count``-digit group (zero-padded), a word with its k-th digit in ASCII at byte
    ``places[k]`` of the word (``None``: digit left out)."""
    groups = np.arange(10**count)
    table = np.zeros(10**count, dtype=_WORD)
    for k, place in enumerate(places):
        if place is not None:
            digit = (groups // 10 ** (count - 1 - k)) % 10
            table |= (digit + ord("0")).astype(_WORD) << _WORD.type(8 * place)
    return table


def _trailing_zeros(count: int) -> np.ndarray:
    """For every ``count``-digit group, its trailing zero digits (``count`` for the group 0)."""
    groups = np.arange(10**count)
    return sum((groups % 10**k == 0).astype(np.uint8) for k in range(1, count + 1))


# The mantissa d0 d1 ... d14 is split into groups a = d0-d3, b = d4-d7, c = d8-d10, d = d11-d14, and
# each group's digits go to their bytes in the field by table look-up (one table per word it reaches).
# Word 0 also carries a sign and a decimal point in every entry; the layout's mask keeps those needed.
_A_WORD0 = _digit_table(4, (1, 3, 4, 5)) | _WORD.type(ord("-") | ord(".") << 16)
_B_WORD0 = _digit_table(4, (6, 7, None, None))
_B_WORD1 = _digit_table(4, (None, None, 0, 1))
_C_WORD1 = _digit_table(3, (2, 3, 4))
_D_WORD1 = _digit_table(4, (5, 6, 7, None))
_D_WORD2 = _digit_table(4, (None, None, None, 0))
_TRAILING4 = _trailing_zeros(4)
_TRAILING3 = _trailing_zeros(3)
#: Powers of ten as ``np.power`` gives them (index: exponent + 300): the factors the mantissas have
#: always been computed with (on some processors a few differ from the correctly rounded double).
_POWERS_OF_TEN = np.power(10.0, np.arange(-300.0, 301.0))


def _keep_masks() -> tuple[np.ndarray, ...]:
    """Per layout ``shown + 16 * point + 32 * negative`` (``shown``: digits written, 1 to 15), the
    mask of the bytes written in each of the three words: sign, digits, decimal point."""
    layouts = np.arange(64)
    keep = np.zeros((64, 8 * _FIELD_WORDS), dtype=np.uint8)
    keep[:, 0] = np.where(layouts >= 32, 0xFF, 0)
    keep[:, 1] = 0xFF
    keep[:, 2] = np.where(layouts % 32 >= 16, 0xFF, 0)
    for k in range(1, CSV_DIGITS):
        keep[:, 2 + k] = np.where(layouts % 16 > k, 0xFF, 0)
    words = keep.view(_WORD)
    return words[:, 0].copy(), words[:, 1].copy(), words[:, 2].copy()


_KEEP_WORD0, _KEEP_WORD1, _KEEP_WORD2 = _keep_masks()


def _exponent_table() -> np.ndarray:
    """Word 2's exponent bytes (``e-3`` at bytes 1-3) for exponents -300 to 300 (index: exponent +
    301); index 0 is no exponent."""
    text = np.zeros((602, 8), dtype=np.uint8)
    for e in range(-300, 301):
        chars = np.frombuffer(f"e{e}".encode(), dtype=np.uint8)
        text[e + 301, 1 : 1 + chars.size] = chars
    return text.view(_WORD)[:, 0].copy()


_EXPONENT_WORD2 = _exponent_table()


def _format_numbers(values: np.ndarray) -> np.ndarray:
    """``values`` as text, vectorized: an ``(n, 3)`` array of words, one 24-byte field per number.

    Each number is written with at most :data:`CSV_DIGITS` significant digits (correctly rounded
    from the double up to one unit in the last digit), trailing zeros dropped: integers below 1e15
    as integers (``2``, ``-120``), numbers in [1, 10) without an exponent (``1.5``), others as
    ``d.ddde-5``. NaN, infinities and exponents beyond +-280 fall back to Python's ``repr``. The
    separator byte (23) is left 0.
    """
    magnitude = np.abs(values)
    zero = magnitude == 0
    normal = np.isfinite(values) & (zero | ((magnitude > 1e-280) & (magnitude < 1e280)))
    safe = np.where(normal & ~zero, magnitude, 1.0)
    e = np.floor(np.log10(safe)).astype(np.int64)
    mant = np.rint(safe * _POWERS_OF_TEN[CSV_DIGITS - 1 + 300 - e]).astype(np.int64)
    bad = (mant >= 10**CSV_DIGITS) | (mant < 10 ** (CSV_DIGITS - 1))
    if bad.any():  # log10 is one off next to a power of ten
        eb = np.floor(np.log10(safe[bad]) + 1e-12).astype(np.int64)
        mb = np.rint(safe[bad] * _POWERS_OF_TEN[CSV_DIGITS - 1 + 300 - eb]).astype(np.int64)
        over = mb >= 10**CSV_DIGITS
        e[bad], mant[bad] = eb + over, np.where(over, mb // 10, mb)
    mant[zero] = 0
    e[zero] = 0
    # The digit groups (integer division by a constant is fast in numpy; divmod is not).
    high = mant // 10**7
    low = mant - high * 10**7
    a = high // 10**4
    b = high - a * 10**4
    c = low // 10**4
    d = low - c * 10**4
    trailing = _TRAILING4[d] + (d == 0) * (_TRAILING3[c] + (c == 0) * (_TRAILING4[b] + (b == 0) * _TRAILING4[a]))
    nd = (CSV_DIGITS - np.minimum(trailing, CSV_DIGITS - 1)).astype(np.int8)  # significant digits, at least one
    e8 = np.clip(e, -100, 100).astype(np.int8)
    integer = (e8 >= 1) & (e8 < CSV_DIGITS) & (nd <= e8 + 1)
    shown = np.where(integer, e8 + 1, nd)
    plain = integer | (e8 == 0)
    point = ~integer & (nd > 1)
    layout = (shown.view(np.uint8) | (point.view(np.uint8) << 4) | ((values < 0).view(np.uint8) << 5)).astype(np.intp)
    words = np.empty((values.size, _FIELD_WORDS), dtype=_WORD)
    words[:, 0] = (_A_WORD0[a] | _B_WORD0[b]) & _KEEP_WORD0[layout]
    words[:, 1] = (_B_WORD1[b] | _C_WORD1[c] | _D_WORD1[d]) & _KEEP_WORD1[layout]
    words[:, 2] = (_D_WORD2[d] & _KEEP_WORD2[layout]) | _EXPONENT_WORD2[np.where(plain, 0, e + 301)]
    for i in np.flatnonzero(~normal):
        value = float(values[i])
        text = repr(value)
        if len(text) > _FIELD_TEXT:  # 17 digits and a three-digit exponent: keep 15
            text = f"{value:.{CSV_DIGITS}g}"
        field = words[i].view(np.uint8)
        field[:] = 0
        field[: len(text)] = np.frombuffer(text.encode(), dtype=np.uint8)
    return words


#: Rows formatted per block: the block's intermediate arrays stay in the processor's cache, which
#: makes the writer about twice as fast as one pass over a long run.
_CSV_BLOCK_ROWS = 4096


def _csv_blocks(names: Sequence[str], data: np.ndarray) -> Iterator[bytes]:
    """The CSV text of a table, block by block: the header, then one line per row."""
    yield (",".join(names) + "\n").encode()
    for i in range(0, data.shape[0], _CSV_BLOCK_ROWS):
        yield _csv_rows(data[i : i + _CSV_BLOCK_ROWS])


def csv_bytes(names: Sequence[str], data: np.ndarray) -> bytes:
    """The CSV text of a table (header, then one line per row), formatted as whole arrays.

    The text ``run.csv`` holds (:func:`write_results` writes it block by block, the same bytes):
    15 significant digits, trailing zeros dropped (``2``, ``1e-3``).

    Parameters
    ----------
    names : Sequence[str]
        The header's column names.
    data : numpy.ndarray
        ``rows x len(names)`` floats.

    Returns
    -------
    bytes
        ASCII text, each line ending in ``\\n``.

    Examples
    --------
    >>> import numpy as np
    >>> csv_bytes(["t", "x"], np.array([[0.0, 2.0], [0.001, -1.5]]))
    b't,x\\n0,2\\n1e-3,-1.5\\n'
    """
    return b"".join(_csv_blocks(names, data))


def _csv_rows(data: np.ndarray) -> bytes:
    n, m = data.shape
    words = _format_numbers(np.ascontiguousarray(data).ravel()).reshape(n, m, _FIELD_WORDS)
    separators = np.full(m, ord(","), dtype=_WORD)
    separators[-1] = ord("\n")
    words[:, :, 2] |= separators << _WORD.type(56)
    return words.tobytes().translate(None, b"\0")


def matlab_meta(meta: Mapping[str, Any]) -> dict[str, Any]:
    """A run's ``meta`` as :func:`scipy.io.savemat` writes it into ``run.mat``'s ``meta`` struct.

    Every field of :data:`META_FIELDS` is present (empty when not given; ``version`` is this
    pendulab's unless given); nested mappings become structs, ``None`` an empty matrix, number lists
    row vectors, other lists cell arrays, and names are made MATLAB field names.

    Parameters
    ----------
    meta : Mapping[str, Any]
        The run's description (:func:`pendulab.simulation.run_meta`), JSON-like data or dataclasses.

    Returns
    -------
    dict
        Field name -> value, ready for ``scipy.io.savemat(path, {"meta": ...})``.

    Examples
    --------
    >>> m = matlab_meta({"pendulum": "long", "step": 0.001, "poke": [220, 0.005, 1]})
    >>> m["pendulum"], m["poke"].shape, m["calibration"].shape
    ('long', (1, 3), (0, 0))
    """
    merged: dict[str, Any] = {name: None for name in META_FIELDS}
    merged["version"] = pendulab.__version__
    merged.update(meta)
    return _to_matlab(merged)


def _to_matlab(value: Any) -> Any:
    """Python data to what :func:`scipy.io.savemat` writes as the natural MATLAB type."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = dataclasses.asdict(value)
    if isinstance(value, Mapping):
        return {_matlab_field(str(k)): _to_matlab(v) for k, v in value.items()}
    if value is None:
        return np.zeros((0, 0))
    if isinstance(value, (str, os.PathLike)):
        return os.fspath(value)
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, float, complex, np.number)):
        return value
    if isinstance(value, np.ndarray) and value.dtype != object:
        return value if value.ndim != 1 else value.reshape(1, -1)  # vectors in meta are rows
    if isinstance(value, (list, tuple, np.ndarray)):
        items = list(value)
        if items and all(isinstance(v, (int, float, complex, np.number)) and not isinstance(v, bool) for v in items):
            return np.asarray(items).reshape(1, -1)
        cell = np.empty((1, len(items)), dtype=object)  # anything else: a cell array
        for i, v in enumerate(items):
            cell[0, i] = _to_matlab(v)
        return cell
    return str(value)


def _matlab_field(name: str) -> str:
    field = re.sub(r"[^A-Za-z0-9_]", "_", name)
    if not field or not field[0].isalpha():
        field = "f_" + field
    return field[:31]


def json_safe(value: Any) -> Any:
    """Plain JSON data: numpy scalars and arrays as Python numbers and lists, non-finite numbers as ``None``.

    Parameters
    ----------
    value : any
        Mappings, sequences, numpy arrays and scalars, numbers, text.

    Examples
    --------
    >>> json_safe({"a": np.float64(1.5), "b": [np.inf, np.int64(2)], "c": np.bool_(True)})
    {'a': 1.5, 'b': [None, 2], 'c': True}
    """
    if isinstance(value, Mapping):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if value is None or isinstance(value, str):
        return value
    return str(value)


# ------------------------------------------------------------------------------------------- read
def read_run(path: str | os.PathLike[str]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read a run back from ``run.mat``, ``run.csv``, or a folder holding either (``run.mat`` first).

    Returns
    -------
    columns : dict of name -> 1-D float array
        Every column in the file (at least :data:`COLUMNS`, or a seesaw run's :data:`SEESAW_COLUMNS`).
    meta : dict
        The ``meta`` struct as nested dicts (``{}`` for a CSV file, which has no meta).

    Raises
    ------
    UserError
        The file is missing, unreadable, or lacks columns.
    """
    path = Path(path)
    if path.is_dir():
        candidates = [path / FILE_NAMES["mat"], path / FILE_NAMES["csv"]]
        found = next((p for p in candidates if p.is_file()), None)
        if found is None:
            raise UserError(f"no run.mat or run.csv in {path}; give the output folder of a run or the file itself")
        path = found
    elif not path.exists():
        raise UserError(f"run file {path} does not exist; give a run.mat or run.csv (or its folder)")
    suffix = path.suffix.lower()
    if suffix == ".mat":
        columns, meta = _read_mat(path)
    elif suffix == ".csv":
        columns, meta = _read_csv(path), {}
    else:
        raise UserError(f"{path} is neither a .mat nor a .csv file; give a run.mat or run.csv")
    required = run_columns(columns)
    missing = [name for name in required if name not in columns]
    if missing:
        what = "a seesaw run" if required is SEESAW_COLUMNS else "a pendulab run"
        raise UserError(f"{path} lacks column(s) {', '.join(missing)}; {what} has {', '.join(required)}")
    return columns, meta


def _read_mat(path: Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    try:
        content = scipy.io.loadmat(path, squeeze_me=False, struct_as_record=False)
    except Exception as exc:  # scipy raises several types for a damaged or foreign file
        raise UserError(f"cannot read {path} as a MATLAB file ({type(exc).__name__}: {exc}); give a run.mat written by pendulab") from None
    columns: dict[str, np.ndarray] = {}
    for name, value in content.items():
        if name.startswith("__") or name == "meta":
            continue
        if isinstance(value, np.ndarray) and value.dtype.kind in "fiub" and value.ndim == 2 and value.shape[1] == 1:
            columns[name] = value[:, 0].astype(float)
    meta_raw = content.get("meta")
    meta = _from_matlab(meta_raw) if meta_raw is not None else {}
    return columns, meta if isinstance(meta, dict) else {"meta": meta}


def _from_matlab(value: Any) -> Any:
    """Nested ``mat_struct`` / arrays as loaded by scipy, back to plain Python data."""
    if isinstance(value, scipy.io.matlab.mat_struct):
        return {name: _from_matlab(getattr(value, name)) for name in value._fieldnames}
    if isinstance(value, np.ndarray):
        if value.size == 0:
            return None
        if value.dtype.kind == "U":
            strings = [str(v) for v in value.ravel()]
            return strings[0] if len(strings) == 1 else strings
        if value.dtype == object:
            items = [_from_matlab(v) for v in value.ravel()]
            return items[0] if len(items) == 1 else items
        if value.size == 1:
            return value.ravel()[0].item()
        return value.ravel().tolist() if 1 in value.shape else value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _read_csv(path: Path) -> dict[str, np.ndarray]:
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read {path}: {exc}; give a run.csv written by pendulab") from None
    lines = text.split("\n")
    if not text.endswith("\n") and len(lines) > 2:
        lines = lines[:-1]  # a streamed log cut off mid-line by a crash: drop the partial row
    lines = [line for line in lines if line.strip()]
    if not lines:
        raise UserError(f"{path} is empty; give a run.csv written by pendulab")
    names = [name.strip() for name in lines[0].split(",")]
    try:
        data = np.loadtxt(io.StringIO("\n".join(lines[1:])), delimiter=",", ndmin=2) if len(lines) > 1 else np.zeros((0, len(names)))
    except ValueError as exc:
        raise UserError(f"{path} has a malformed row ({exc}); give a run.csv written by pendulab") from None
    if data.size and data.shape[1] != len(names):
        raise UserError(f"{path} has {data.shape[1]} values per row but {len(names)} names in its header")
    return {name: data[:, i].copy() for i, name in enumerate(names)}


# ------------------------------------------------------------------------------------ streamed log
class RunLog:
    """An incremental CSV writer for logs streamed while a run is going (HIL).

    Rows are kept in memory and written as whole lines every ``flush_every`` rows, so a crash
    loses at most the rows since the last flush, and the file never holds half a row except for
    a write interrupted by the crash itself (which :func:`read_run` drops).

    Parameters
    ----------
    path : path
        The CSV file (its folder is created; an existing file is replaced).
    columns : sequence of str
        Column names, in order (default :data:`COLUMNS`).
    flush_every : int
        Rows between writes to the operating system.
    fsync : bool
        Also ask the OS to put each flush on disk (survives a power cut, costs time).

    Examples
    --------
    >>> import tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "log.csv")
    >>> with RunLog(path, ("t", "V"), flush_every=2) as log:
    ...     log.append((0.0, 1.5))
    ...     log.append({"t": 0.001, "V": -2.0})
    >>> open(path).read()
    't,V\\n0.0,1.5\\n0.001,-2.0\\n'
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        columns: Sequence[str] = COLUMNS,
        *,
        flush_every: int = 100,
        fsync: bool = False,
    ) -> None:
        self.columns = tuple(columns)
        bad = [c for c in self.columns if not _MATLAB_NAME.match(c)]
        if not self.columns or bad:
            raise ValueError(f"log columns must be MATLAB-style names; bad: {bad or 'no columns'}")
        if flush_every < 1:
            raise ValueError(f"flush_every={flush_every} must be >= 1")
        self.path = Path(path)
        self.flush_every = int(flush_every)
        self.fsync = fsync
        self.rows = 0
        self._pending: list[str] = []
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file: io.TextIOWrapper | None = open(self.path, "w", encoding="ascii", newline="\n")
        except OSError as exc:
            raise UserError(f"cannot open log file {self.path}: {exc.strerror or exc}; choose another folder") from None
        self._file.write(",".join(self.columns) + "\n")
        self._file.flush()

    def append(self, row: Sequence[float] | Mapping[str, float]) -> None:
        """Add one row: values in column order, or a mapping by column name."""
        if self._file is None:
            raise ValueError(f"log {self.path} is closed")
        if isinstance(row, Mapping):
            try:
                values: Iterable[Any] = [row[c] for c in self.columns]
            except KeyError as exc:
                raise ValueError(f"log row lacks column {exc.args[0]!r}") from None
        else:
            values = list(row)
            if len(values) != len(self.columns):
                raise ValueError(f"log row has {len(values)} values for {len(self.columns)} columns")
        self._pending.append(",".join(repr(float(v)) for v in values))
        self.rows += 1
        if len(self._pending) >= self.flush_every:
            self.flush()

    def flush(self) -> None:
        """Write the pending rows to the file now."""
        if self._file is None:
            return
        if self._pending:
            self._file.write("\n".join(self._pending) + "\n")
            self._pending.clear()
        self._file.flush()
        if self.fsync:
            os.fsync(self._file.fileno())

    def close(self) -> Path:
        """Flush and close (idempotent); returns the file's path."""
        if self._file is not None:
            try:
                self.flush()
            finally:
                self._file.close()
                self._file = None
        return self.path

    @property
    def closed(self) -> bool:
        return self._file is None

    def __enter__(self) -> "RunLog":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:  # a forgotten log still keeps its rows
        try:
            self.close()
        except Exception:
            pass
