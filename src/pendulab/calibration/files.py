"""The calibration file: the friction vector, fitted parameters and metadata (SPEC §8).

A calibration file is human-editable JSON::

    {
      "format": "pendulab-calibration",
      "version": 1,
      "friction": {"F1": 1.5, "v1": 0.005, "F2": 3.0, "v2": 0.05, "B": 20.0},
      "Beq": 4.3, "force_gain": 1.0, "M_cart": 0.57,   # optional fitted parameters
      "metadata": {"date": "...", "rig": "...", "iterations": 5, "spread": {...}, "method": "..."}
    }

The friction vector is the one the model uses (:meth:`Calibration.apply` copies it into the plant parameters unchanged). ``pendulab calibrate`` writes
it already scaled for the pendulum's weight and keeps the vector measured with the pendulum removed in ``metadata.measured_friction``.

Loading also accepts the old lab's MATLAB ``.mat`` file (MAT v5 or v7.3) holding a friction vector: the variable named like ``friction``/``fric``
(case-insensitive), else the only numeric vector with 4 or 5 entries, whatever its name. Four numbers are read as the old lab's static-friction
function read them, ``[F1, v1, B, unused]`` with ``F2 = 4 F1`` and ``v2 = 0.1 m/s`` fixed (SPEC §8); five are pendulab's ``[F1, v1, F2, v2, B]``.

Examples
--------
>>> from pendulab.calibration.files import default_calibration
>>> cal = default_calibration()
>>> cal.friction
(1.5, 0.005, 3.0, 0.05, 20.0)
>>> from pendulab.model.parameters import PlantParameters
>>> cal.apply(PlantParameters.preset("long")).F2
3.0
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from pendulab.errors import CalibrationError, ParameterError
from pendulab.model.parameters import FRICTION_NAMES, PlantParameters

FORMAT = "pendulab-calibration"
VERSION = 1
#: Optional fitted parameters a calibration file may hold beside the friction vector.
FITTED_NAMES = ("Beq", "force_gain", "M_cart")
_TOP_LEVEL = {"format", "version", "friction", "metadata", *FITTED_NAMES}
UNITS = {"F1": "N", "v1": "m/s", "F2": "N", "v2": "m/s", "B": "kg/s", "Beq": "N.s/m", "force_gain": "", "M_cart": "kg"}

#: The packaged default file (a copy of ``calibration/default.json`` at the repository root).
DEFAULT_CALIBRATION_PATH = Path(__file__).resolve().parent / "default.json"


@dataclass(frozen=True)
class Calibration:
    """A friction vector plus optional fitted parameters and free-form metadata.

    Attributes
    ----------
    friction : tuple of 5 floats
        ``(F1, v1, F2, v2, B)`` in N, m/s, N, m/s, kg/s.
    Beq, force_gain, M_cart : float or None
        Fitted parameters; ``None`` keeps the plant's value.
    metadata : dict
        Date, rig, iterations, spread, method, ... (JSON-serializable).
    """

    friction: tuple[float, float, float, float, float]
    Beq: float | None = None
    force_gain: float | None = None
    M_cart: float | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        friction = tuple(float(v) for v in self.friction)
        if len(friction) != 5:
            raise CalibrationError(f"the friction vector needs 5 numbers [F1, v1, F2, v2, B], got {len(friction)}")
        object.__setattr__(self, "friction", friction)
        _validate(dict(zip(FRICTION_NAMES, friction)), {n: getattr(self, n) for n in FITTED_NAMES}, "calibration")

    # ------------------------------------------------------------------ use
    @property
    def values(self) -> dict[str, float]:
        """Every parameter this calibration sets, by plant-parameter name."""
        return {**dict(zip(FRICTION_NAMES, self.friction)), **{n: getattr(self, n) for n in FITTED_NAMES if getattr(self, n) is not None}}

    def apply(self, params: PlantParameters) -> PlantParameters:
        """``params`` with the friction vector and the fitted parameters of this calibration.

        Examples
        --------
        >>> cal = Calibration((2.0, 0.004, 3.5, 0.06, 25.0), Beq=5.0, force_gain=0.9)
        >>> p = cal.apply(PlantParameters.preset("long"))
        >>> (p.F1, p.Beq, p.force_gain)
        (2.0, 5.0, 0.9)
        """
        return params.with_values(**self.values)

    def to_dict(self) -> dict[str, Any]:
        """The JSON document (see the module docstring)."""
        fitted = {n: v for n, v in self.values.items() if n in FITTED_NAMES}
        return {"format": FORMAT, "version": VERSION, "friction": dict(zip(FRICTION_NAMES, self.friction)), **fitted, "metadata": dict(self.metadata)}

    @classmethod
    def from_dict(cls, data: Any, source: str = "calibration") -> "Calibration":
        """Validate a decoded JSON document; every problem is one :class:`CalibrationError` line."""
        if not isinstance(data, Mapping):
            raise CalibrationError(f"{source}: expected a JSON object with a 'friction' entry, got {type(data).__name__}")
        unknown = sorted(set(data) - _TOP_LEVEL)
        if unknown:
            raise CalibrationError(f"{source}: unknown entry {unknown[0]!r}; allowed are {', '.join(sorted(_TOP_LEVEL))}")
        if "format" in data and data["format"] != FORMAT:
            raise CalibrationError(f"{source}: 'format' is {data['format']!r}, expected {FORMAT!r}")
        if "friction" not in data:
            raise CalibrationError(f"{source}: missing 'friction' entry: give {{\"F1\", \"v1\", \"F2\", \"v2\", \"B\"}}")
        friction = data["friction"]
        if isinstance(friction, list):
            if len(friction) != 5:
                raise CalibrationError(f"{source}: friction list needs 5 numbers [F1, v1, F2, v2, B], got {len(friction)}")
            friction = dict(zip(FRICTION_NAMES, friction))  # then checked as an object
        if not isinstance(friction, Mapping):
            raise CalibrationError(f"{source}: 'friction' must be an object {{\"F1\": ..., \"B\": ...}}, got {type(friction).__name__}")
        missing = [n for n in FRICTION_NAMES if n not in friction]
        if missing:
            raise CalibrationError(f"{source}: friction is missing {', '.join(missing)}; give all of F1, v1, F2, v2, B")
        extra = sorted(set(friction) - set(FRICTION_NAMES))
        if extra:
            raise CalibrationError(f"{source}: unknown friction entry {extra[0]!r}; the names are F1, v1, F2, v2, B")
        checked = _validate(friction, {n: data.get(n) for n in FITTED_NAMES}, source)
        metadata = data.get("metadata", {})
        if not isinstance(metadata, Mapping):
            raise CalibrationError(f"{source}: 'metadata' must be a JSON object, got {type(metadata).__name__}")
        return cls(
            friction=tuple(checked[n] for n in FRICTION_NAMES),  # type: ignore[arg-type]
            **{n: checked.get(n) for n in FITTED_NAMES},
            metadata=dict(metadata),
        )


def _number(name: str, value: Any, source: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CalibrationError(f"{source}: {name}={value!r} is not a number; give a value in {UNITS[name] or 'units of 1'}")
    value = float(value)
    if not math.isfinite(value):
        raise CalibrationError(f"{source}: {name}={value} is not finite")
    if value < 0:
        raise CalibrationError(f"{source}: {name}={value:g} is negative; friction and fitted parameters are >= 0")
    return value


def _validate(friction: Mapping[str, Any], fitted: Mapping[str, Any], source: str) -> dict[str, float]:
    checked = {n: _number(n, friction[n], source) for n in FRICTION_NAMES}
    for low, high, what in (("v1", "v2", "the sticking speed"), ("F1", "F2", "the breakaway force")):
        if checked[low] > checked[high]:
            raise CalibrationError(f"{source}: {low}={checked[low]:g} {UNITS[low]} is above {high}={checked[high]:g} {UNITS[high]}; "
                                   f"{what} {low} must not exceed {high}")
    for name in FITTED_NAMES:
        if fitted.get(name) is not None:
            checked[name] = _number(name, fitted[name], source)
            if name in ("force_gain", "M_cart") and checked[name] == 0:
                raise CalibrationError(f"{source}: {name} must be > 0")
    try:  # within the plant's ranges (those of the FMU's variables)
        PlantParameters().with_values(**checked)
    except ParameterError as exc:
        raise CalibrationError(f"{source}: {exc}") from None
    return checked


# ---------------------------------------------------------------------- reading
def load_calibration(path: str | os.PathLike[str]) -> Calibration:
    """Read a calibration file: JSON (``.json`` or anything else) or the old lab's MATLAB ``.mat``.

    Parameters
    ----------
    path : path
        The file (``calibration/default.json`` holds the lab's table).

    Returns
    -------
    Calibration
        ``.apply(params)`` puts its values into a :class:`~pendulab.model.parameters.PlantParameters`.

    Examples
    --------
    >>> calibration = load_calibration(DEFAULT_CALIBRATION_PATH)
    >>> calibration.apply(PlantParameters.preset()).friction
    (1.5, 0.005, 3.0, 0.05, 20.0)

    Raises
    ------
    CalibrationError
        One line naming the file and what is wrong (unreadable, bad JSON, missing or bad values).
    """
    path = Path(path)
    if not path.is_file():
        raise CalibrationError(f"calibration file {path} does not exist (give a JSON file, e.g. calibration/default.json)")
    if path.suffix.lower() == ".mat":
        return _load_mat(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))  # Windows Notepad's UTF-8 starts with a byte-order mark
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"calibration file {path} cannot be read: {exc}") from None
    except json.JSONDecodeError as exc:
        raise CalibrationError(f"calibration file {path} is not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}") from None
    return Calibration.from_dict(data, source=f"calibration file {path}")


#: The old lab's static-friction function fixed these (SPEC §8): ``F2 = OLD_LAB_F2_FACTOR * F1``, ``v2``.
OLD_LAB_F2_FACTOR = 4.0
OLD_LAB_V2 = 0.1


def _load_mat(path: Path) -> Calibration:
    """The old lab's ``.mat`` calibration, read as that lab's code read it (see the module docstring)."""
    import numpy as np

    from pendulab.calibration.logs import read_mat_variables

    source = f"calibration file {path}"
    numeric = {k: v for k, v in read_mat_variables(path, what=source).items() if v.dtype.kind in "fiub"}
    if numeric and all(v.size == 0 for v in numeric.values()):
        raise CalibrationError(f"{source} is empty (variable {', '.join(sorted(numeric))} holds no numbers); "
                               "save the friction vector [F1 v1 B unused] in it, or use a JSON calibration file")
    vectors = {k: np.asarray(v, dtype=float).ravel() for k, v in numeric.items() if v.size in (4, 5)}
    candidates = [k for k in vectors if "fric" in k.lower()] or list(vectors)
    if not candidates:
        raise CalibrationError(f"{source} holds no friction vector: expected one variable with 4 numbers [F1 v1 B unused] "
                               "(the old lab's format) or 5 numbers [F1 v1 F2 v2 B]")
    if len(candidates) > 1:
        raise CalibrationError(f"{source} holds several 4/5-number vectors ({', '.join(sorted(candidates))}); keep only the friction vector in it")
    name = candidates[0]
    values = [float(v) for v in vectors[name]]
    metadata: dict[str, Any] = {"source": str(path), "mat_variable": name, "method": "old lab .mat file"}
    if len(values) == 4:
        metadata["note"] = ("4-number vector read as the old lab read it: [F1, v1, B, unused], "
                            f"F2 = {OLD_LAB_F2_FACTOR:g}*F1, v2 = {OLD_LAB_V2:g} m/s")
        metadata["old_lab_vector"] = values
        F1, v1, B, _ = values
        values = [F1, v1, OLD_LAB_F2_FACTOR * F1, OLD_LAB_V2, B]
    checked = _validate(dict(zip(FRICTION_NAMES, values)), {}, source)
    return Calibration(friction=tuple(checked[n] for n in FRICTION_NAMES), metadata=metadata)  # type: ignore[arg-type]


def default_calibration() -> Calibration:
    """The lab's measured friction table (SPEC §2), from the packaged ``default.json``."""
    return load_calibration(DEFAULT_CALIBRATION_PATH)


# ---------------------------------------------------------------------- writing
def save_calibration(calibration: Calibration, path: str | os.PathLike[str]) -> Path:
    """Write ``calibration`` as JSON, atomically with the user's umask (:func:`pendulab.outputs.atomic_write`).

    A reader never sees a half-written file, and an error leaves any previous file untouched.
    """
    path = Path(path)
    if path.is_dir():
        raise CalibrationError(f"--out {path} is a directory; give a file name such as {path / 'calibration.json'}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CalibrationError(f"cannot create the folder for {path}: {exc.strerror or exc}") from None
    text = json.dumps(calibration.to_dict(), indent=2, allow_nan=False) + "\n"
    from pendulab.outputs import atomic_write

    try:
        return atomic_write(path, lambda handle: handle.write(text.encode("utf-8")))
    except OSError as exc:
        raise CalibrationError(f"cannot write {path}: {exc.strerror or exc}") from None
