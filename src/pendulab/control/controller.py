"""The student's controller ``G(s) = G1(s)·G2(s)·…·Gn(s)`` as zeros, poles and gains (SPEC §4).

``G1`` is the *kernel*, ``G2 … Gn`` are *compensators*, ``n <= 6``. Each factor is
``gain · prod(s - z) / prod(s - p)``. The entry rules, each enforced with a one-line
:class:`~pendulab.errors.ControllerError` naming the offending value and the fix:

1. no pole and no zero exactly at ``s = 0`` (no pure integrator or differentiator);
2. the product is proper (no more zeros than poles in total);
3. at most 6 factors; complex values in conjugate pairs inside a factor; every number finite;
   gains real and non-zero.

Text forms (command-line flags, the interactive prompt): numbers are separated by commas, complex
numbers are written ``-3+4j`` (or ``-3+4i``), and ``""`` or ``none`` means no roots; a compensator is
``"ZEROS;POLES[;GAIN]"``.

Examples
--------
>>> from pendulab.control.controller import Controller, Factor, parse_compensator
>>> c = Controller([Factor([-5], [7], 40000), parse_compensator("-17;-80"), parse_compensator("none;-80")])
>>> print(c)
40000 (s + 5)(s + 17) / ((s - 7)(s + 80)^2)
>>> c.to_dict()["compensators"][0]
{'zeros': [-17.0], 'poles': [-80.0], 'gain': 1.0}
>>> Controller.pid(kp=2.0, ki=0.0, kd=0.0).zpk()
(array([], dtype=float64), array([], dtype=float64), 2.0)
>>> Controller.from_zpk([0], [-1], 1.0)
Traceback (most recent call last):
...
pendulab.errors.ControllerError: kernel zero 0 lies exactly at s = 0 (a pure differentiator); move it off the origin and filter it, e.g. zeros -0.1 and poles -62.8 for (s+0.1)/(s+62.8) in place of s/(s+62.8)
"""

from __future__ import annotations

import math
import numbers
import re
from collections import Counter
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from pendulab.errors import ControllerError

#: At most this many factors: a kernel and five compensators.
MAX_FACTORS = 6
#: Two complex roots are a conjugate pair when they differ by less than this, relative to their size.
PAIR_TOLERANCE = 1e-9

Number = float | complex

_FACTOR_KEYS = ("zeros", "poles", "gain")
_CONTROLLER_KEYS = ("kernel", "compensators")
_NONE_WORDS = ("", "none", "-", "[]")


# ---------------------------------------------------------------------------------------------- numbers
def _one_line(text: str) -> str:
    """Error messages are one line: user text can carry newlines."""
    return " ".join(str(text).split())


def _show(value: Any, limit: int = 40) -> str:
    """A short, one-line rendering of a user's value for an error message."""
    text = value if isinstance(value, str) else repr(value)
    text = repr(text) if isinstance(value, str) else text
    text = _one_line(text)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def format_number(value: Number) -> str:
    """Shortest text that reads back exactly: ``-3``, ``0.1``, ``-3+4j``."""

    def real(x: float) -> str:
        text = repr(float(x))
        return text[:-2] if text.endswith(".0") else text

    value = complex(value)
    if value.imag == 0:
        return real(value.real)
    sign = "-" if math.copysign(1.0, value.imag) < 0 else "+"
    return f"{real(value.real)}{sign}{real(abs(value.imag))}j"


def _parse_token(token: str, what: str) -> Number:
    original = token
    text = token.strip()
    if text.startswith("(") and text.endswith(")"):
        text = text[1:-1].strip()
    # Allow "-3 + 4j" (spaces around the sign of the imaginary part) but not "1 2" (a missing comma).
    text = re.sub(r"(?<=[0-9.])\s*([+-])\s*(?=[0-9.]|inf|nan)", r"\1", text, flags=re.IGNORECASE)
    if re.search(r"\s", text):
        raise ControllerError(f"{what}: {_show(original.strip())} is not one number; separate numbers with commas, e.g. -1, -2.5, -3+4j")
    lowered = text.lower()
    if lowered.endswith("i") and not lowered.endswith("inf"):
        text = text[:-1] + "j"  # MATLAB style -3+4i
    try:
        value = complex(text)
    except (ValueError, OverflowError):
        hint = "separate numbers with commas" if re.search(r"\s", original.strip()) else "complex as re+imj"
        raise ControllerError(f"{what}: {_show(original.strip())} is not a number; write e.g. -2.5 or -3+4j ({hint})") from None
    return _finite(value, what, original.strip())


#: Largest magnitude of any number (far beyond any controller; keeps ``|z|`` and products finite).
MAX_MAGNITUDE = 1e100


def _finite(value: complex, what: str, shown: Any) -> Number:
    if not (math.isfinite(value.real) and math.isfinite(value.imag)):
        raise ControllerError(f"{what}: {_show(shown)} is not finite; every number must be finite")
    if max(abs(value.real), abs(value.imag)) > MAX_MAGNITUDE:
        raise ControllerError(f"{what}: {_show(shown)} is too large; every number must be within ±1e100")
    return value if value.imag != 0 else float(value.real)


def to_number(value: Any, what: str = "value") -> Number:
    """One number from a Python number, a string (``"-3+4j"``) or a pair ``[re, im]``.

    Real values come back as ``float``, others as ``complex``; non-finite values are an error.
    """
    if isinstance(value, bool) or value is None:
        raise ControllerError(f"{what}: {_show(value)} is not a number; write e.g. -2.5 or -3+4j")
    if isinstance(value, str):
        return _parse_token(value, what)
    if isinstance(value, numbers.Number):
        try:
            number = complex(value)  # type: ignore[arg-type]
        except (TypeError, ValueError, OverflowError):
            raise ControllerError(f"{what}: {_show(value)} is not a usable number; give a finite real or complex value") from None
        return _finite(number, what, value)
    if isinstance(value, (list, tuple, np.ndarray)) and len(value) == 2:
        re_, im_ = value[0], value[1]
        if all(isinstance(v, numbers.Real) and not isinstance(v, bool) for v in (re_, im_)):
            try:
                number = complex(float(re_), float(im_))
            except OverflowError:
                raise ControllerError(f"{what}: {_show(value)} is too large; every number must be finite") from None
            return _finite(number, what, value)
    raise ControllerError(f"{what}: {_show(value)} is not a number; use a number, a string like \"-3+4j\" or a pair [re, im]")


def parse_numbers(text: str, what: str = "numbers") -> list[Number]:
    """Comma-separated numbers: ``"1, -2.5, -3+4j"``; ``""`` or ``"none"`` for none.

    Examples
    --------
    >>> parse_numbers("1, -2.5, -3+4j")
    [1.0, -2.5, (-3+4j)]
    >>> parse_numbers("none")
    []
    """
    if not isinstance(text, str):
        raise ControllerError(f"{what}: expected text like \"-1, -3+4j\", got {_show(text)}")
    stripped = text.strip()
    if stripped.startswith("[") and stripped.endswith("]"):
        stripped = stripped[1:-1].strip()
    if stripped.lower() in _NONE_WORDS:
        return []
    tokens = stripped.split(",")
    if any(not t.strip() for t in tokens):
        raise ControllerError(f"{what}: {_show(text.strip())} has an empty entry; separate numbers with single commas, e.g. -1, -2")
    return [_parse_token(t, what) for t in tokens]


def format_numbers(values: Iterable[Number]) -> str:
    """The inverse of :func:`parse_numbers`: ``"-6, -3+4j, -3-4j"`` (``"none"`` when empty)."""
    values = list(values)
    return ", ".join(format_number(v) for v in values) if values else "none"


def _number_list(values: Any, what: str) -> list[Number]:
    if isinstance(values, str):
        return parse_numbers(values, what)
    if values is None:
        return []
    if isinstance(values, np.ndarray):
        values = values.ravel().tolist()
    if isinstance(values, numbers.Number) and not isinstance(values, bool):
        return [to_number(values, what)]
    if not isinstance(values, (list, tuple)):
        raise ControllerError(f"{what}: expected a list of numbers, got {_show(values)}")
    return [to_number(v, what) for v in values]


def _gain(value: Any, what: str) -> float:
    gain = to_number(value, what)
    if isinstance(gain, complex):
        raise ControllerError(f"{what} {format_number(gain)} is complex; the gain must be a real number")
    if gain == 0:
        raise ControllerError(f"{what} is 0, which switches the controller off; give a non-zero gain")
    return float(gain)


def _check_roots(values: Sequence[Number], kind: str, label: str) -> tuple[Number, ...]:
    """Rule 1 (nothing at s = 0) and conjugate pairs; exact conjugates are stored for each pair."""
    for v in values:
        if v == 0:
            if kind == "pole":
                raise ControllerError(
                    f"{label} pole 0 lies exactly at s = 0 (a pure integrator); move it just off the origin, e.g. pole -0.1 for 1/(s+0.1) in place of 1/s"
                )
            raise ControllerError(
                f"{label} zero 0 lies exactly at s = 0 (a pure differentiator); move it off the origin and filter it, "
                "e.g. zeros -0.1 and poles -62.8 for (s+0.1)/(s+62.8) in place of s/(s+62.8)"
            )
    out: list[Number] = list(values)
    unmatched = [i for i, v in enumerate(out) if isinstance(v, complex)]
    while unmatched:
        i = unmatched.pop(0)
        v = complex(out[i])
        scale = PAIR_TOLERANCE * max(1.0, abs(v))
        partner = next((j for j in unmatched if abs(complex(out[j]) - v.conjugate()) <= scale), None)
        if partner is None:
            raise ControllerError(
                f"{label} {kind} {format_number(v)} has no conjugate; complex values come in conjugate pairs: add {format_number(v.conjugate())}"
            )
        unmatched.remove(partner)
        out[partner] = v.conjugate()
    return tuple(out)


def _label_errors(label: str, build: Any) -> Any:
    try:
        return build()
    except ControllerError as exc:
        message = str(exc)
        raise ControllerError(message if message.startswith(label) else f"{label}: {message}") from None


# ---------------------------------------------------------------------------------------------- factors
@dataclass(frozen=True, init=False)
class Factor:
    """One factor ``gain · prod(s - z) / prod(s - p)`` of the controller.

    Parameters
    ----------
    zeros, poles : sequence of numbers
        Real or complex (complex ones in conjugate pairs); numbers, ``"-3+4j"`` strings or
        ``[re, im]`` pairs are accepted. None may lie at ``s = 0``.
    gain : float
        Real and non-zero (default 1).
    label : str
        How error messages name this factor (``"kernel"``, ``"compensator 2"``).

    Examples
    --------
    >>> Factor([-17], [-80])
    Factor(zeros=(-17.0,), poles=(-80.0,), gain=1.0)
    >>> Factor(["-3+4j", "-3-4j"], [-1, -2, -50], gain=2.0).zeros
    ((-3+4j), (-3-4j))
    """

    zeros: tuple[Number, ...]
    poles: tuple[Number, ...]
    gain: float = 1.0

    def __init__(self, zeros: Any = (), poles: Any = (), gain: Any = 1.0, *, label: str = "factor") -> None:
        z = _check_roots(_number_list(zeros, f"{label} zeros"), "zero", label)
        p = _check_roots(_number_list(poles, f"{label} poles"), "pole", label)
        object.__setattr__(self, "zeros", z)
        object.__setattr__(self, "poles", p)
        object.__setattr__(self, "gain", _gain(gain, f"{label} gain"))

    def numerator(self) -> np.ndarray:
        """Real polynomial coefficients of ``gain · prod(s - z)``, highest power first."""
        return self.gain * _real_poly(self.zeros)

    def denominator(self) -> np.ndarray:
        """Real monic polynomial ``prod(s - p)``, highest power first."""
        return _real_poly(self.poles)

    def transfer_function(self) -> "control.TransferFunction":  # noqa: F821
        import control  # python-control costs a second to import: only where it is used

        return control.tf(self.numerator(), self.denominator())

    def to_dict(self) -> dict[str, Any]:
        """``{"zeros": [...], "poles": [...], "gain": k}``; complex numbers as ``[re, im]``."""
        return {"zeros": [_json_number(z) for z in self.zeros], "poles": [_json_number(p) for p in self.poles], "gain": self.gain}

    def to_string(self) -> str:
        """The ``"ZEROS;POLES;GAIN"`` text form read by :func:`parse_compensator`."""
        return f"{format_numbers(self.zeros)};{format_numbers(self.poles)};{format_number(self.gain)}"

    def describe(self) -> str:
        """``40000 (s + 5) / (s - 7)``."""
        return format_zpk(self.zeros, self.poles, self.gain)


def _real_poly(roots: Sequence[Number]) -> np.ndarray:
    """Polynomial with these roots; conjugate pairs are multiplied out as real quadratics."""
    poly = np.array([1.0])
    for r in roots:
        r = complex(r)
        if r.imag > 0:
            poly = np.convolve(poly, [1.0, -2.0 * r.real, r.real**2 + r.imag**2])
        elif r.imag == 0:
            poly = np.convolve(poly, [1.0, -r.real])
    return poly


def _json_number(value: Number) -> float | list[float]:
    value = complex(value)
    return float(value.real) if value.imag == 0 else [float(value.real), float(value.imag)]


# ---------------------------------------------------------------------------------------------- controller
@dataclass(frozen=True, init=False)
class Controller:
    """``G(s) = G1(s)·…·Gn(s)``: a kernel ``factors[0]`` and up to five compensators.

    Parameters
    ----------
    factors : iterable of Factor
        The kernel (its gain is the controller's gain), then the compensators; at most six.

    Examples
    --------
    >>> c = Controller([Factor([-5], [7], 40000), Factor([-17], [-80]), Factor([], [-80])])
    >>> c.order, len(c.compensators)
    (3, 2)
    >>> Controller.from_dict(c.to_dict()) == c
    True
    """

    factors: tuple[Factor, ...]

    def __init__(self, factors: Iterable[Factor]) -> None:
        if isinstance(factors, Factor):
            factors = [factors]
        try:
            factors = tuple(factors)
        except TypeError:
            raise ControllerError(f"a controller is a list of factors, got {_show(factors)}") from None
        if not factors:
            raise ControllerError("the controller has no kernel; give at least the kernel's zeros, poles and gain")
        for i, f in enumerate(factors):
            if not isinstance(f, Factor):
                raise ControllerError(f"factor {i + 1} is {_show(f)}, not a Factor; build it with Factor(zeros, poles, gain)")
        if len(factors) > MAX_FACTORS:
            raise ControllerError(
                f"{len(factors)} factors given; at most {MAX_FACTORS} are allowed (a kernel and {MAX_FACTORS - 1} compensators): "
                "merge compensators into one factor"
            )
        n_zeros = sum(len(f.zeros) for f in factors)
        n_poles = sum(len(f.poles) for f in factors)
        if n_zeros > n_poles:
            raise ControllerError(
                f"G(s) is improper: {n_zeros} zeros but only {n_poles} pole(s) in total; add {n_zeros - n_poles} pole(s) "
                "(e.g. a compensator with poles -62.8) or remove zeros"
            )
        object.__setattr__(self, "factors", factors)

    # ---------------------------------------------------------------- views
    @property
    def kernel(self) -> Factor:
        return self.factors[0]

    @property
    def compensators(self) -> tuple[Factor, ...]:
        return self.factors[1:]

    @property
    def order(self) -> int:
        """Number of poles (the order of any minimal realization without cancellations)."""
        return sum(len(f.poles) for f in self.factors)

    def zpk(self) -> tuple[np.ndarray, np.ndarray, float]:
        """All zeros, all poles (real arrays when all are real) and the overall gain.

        ``G(s) = gain · prod(s - zeros) / prod(s - poles)``.
        """
        zeros = np.array([z for f in self.factors for z in f.zeros])
        poles = np.array([p for f in self.factors for p in f.poles])
        gain = float(np.prod([f.gain for f in self.factors]))
        return _real_if_real(zeros), _real_if_real(poles), gain

    def transfer_function(self) -> "control.TransferFunction":  # noqa: F821
        """The product as one ``control.TransferFunction`` (continuous time)."""
        import control

        num, den = np.array([1.0]), np.array([1.0])
        for f in self.factors:
            num, den = np.convolve(num, f.numerator()), np.convolve(den, f.denominator())
        return control.tf(num, den)

    def to_dict(self) -> dict[str, Any]:
        """The controller-file shape: ``{"kernel": {...}, "compensators": [{...}, ...]}``."""
        return {"kernel": self.kernel.to_dict(), "compensators": [f.to_dict() for f in self.compensators]}

    def to_strings(self) -> dict[str, Any]:
        """Text form for flags, the inverse of :func:`parse_controller`: ``parse_controller(**c.to_strings())``."""
        k = self.kernel
        return {
            "zeros": format_numbers(k.zeros),
            "poles": format_numbers(k.poles),
            "gain": format_number(k.gain),
            "compensators": [f.to_string() for f in self.compensators],
        }

    def describe(self) -> str:
        """Readable text of ``G(s)``: each factor, then the product.

        Examples
        --------
        >>> print(Controller([Factor([-5], [7], 40000), Factor([-17], [-80])]).describe())
        G(s) = G1(s)·G2(s)
          G1(s) = 40000 (s + 5) / (s - 7)    (kernel)
          G2(s) = (s + 17) / (s + 80)    (compensator 1)
          G(s)  = 40000 (s + 5)(s + 17) / ((s - 7)(s + 80))
        """
        names = [f"G{i + 1}(s)" for i in range(len(self.factors))]
        lines = [f"G(s) = {'·'.join(names)}"]
        for i, (name, f) in enumerate(zip(names, self.factors)):
            role = "kernel" if i == 0 else f"compensator {i}"
            lines.append(f"  {name} = {f.describe()}    ({role})")
        lines.append(f"  G(s)  = {self}")
        return "\n".join(lines)

    def __str__(self) -> str:
        zeros, poles, gain = self.zpk()
        return format_zpk(list(zeros), list(poles), gain)

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_dict(cls, data: Any) -> "Controller":
        """From the controller-file shape (see :meth:`to_dict`); unknown keys are an error.

        Numbers may be numbers, strings (``"-3+4j"``) or ``[re, im]`` pairs; a list of roots may also
        be one comma-separated string. The kernel needs a gain; a compensator's gain defaults to 1.
        """
        if not isinstance(data, Mapping):
            raise ControllerError(f"a controller is a table with 'kernel' and optional 'compensators', got {_show(data)}")
        unknown = [k for k in data if k not in _CONTROLLER_KEYS]
        if unknown:
            raise ControllerError(f"unknown key {_show(unknown[0])} in the controller; allowed keys are kernel, compensators")
        if "kernel" not in data:
            raise ControllerError("the controller has no 'kernel'; add kernel = {zeros = [...], poles = [...], gain = ...}")
        factors = [_factor_from_mapping(data["kernel"], "kernel", gain_required=True)]
        compensators = data.get("compensators")
        if compensators is None:
            compensators = []
        if isinstance(compensators, Mapping) or not isinstance(compensators, (list, tuple)):
            raise ControllerError(f"'compensators' must be a list of tables with zeros, poles and gain, got {_show(compensators)}")
        if len(compensators) > MAX_FACTORS - 1:
            raise ControllerError(
                f"{len(compensators)} compensators given; at most {MAX_FACTORS - 1} are allowed besides the kernel: merge compensators into one"
            )
        for i, item in enumerate(compensators):
            factors.append(_factor_from_mapping(item, f"compensator {i + 1}", gain_required=False))
        return cls(factors)

    @classmethod
    def from_zpk(cls, zeros: Any, poles: Any, gain: Any) -> "Controller":
        """A controller with a kernel only."""
        return cls([Factor(zeros, poles, gain, label="kernel")])

    @classmethod
    def from_transfer_function(cls, tf: Any) -> "Controller":
        """A kernel-only controller from a continuous-time SISO ``control.TransferFunction``.

        A ``control.StateSpace`` is accepted too. Roots are computed from the polynomials.
        """
        import control

        if isinstance(tf, control.StateSpace):
            tf = control.tf(tf)
        if not isinstance(tf, control.TransferFunction):
            raise ControllerError(f"expected a control.TransferFunction, got {type(tf).__name__}")
        if tf.ninputs != 1 or tf.noutputs != 1:
            raise ControllerError(f"the transfer function has {tf.ninputs} inputs and {tf.noutputs} outputs; the controller is SISO (tip error -> voltage)")
        if tf.dt not in (0, None):
            raise ControllerError(f"the transfer function is discrete-time (dt={tf.dt}); give G(s) in continuous time, pendulab discretizes it")
        num = _trim(np.asarray(tf.num[0][0], dtype=complex))
        den = _trim(np.asarray(tf.den[0][0], dtype=complex))
        for poly, name in ((num, "numerator"), (den, "denominator")):
            if not np.all(np.isfinite(poly)):
                raise ControllerError(f"the transfer function's {name} has non-finite coefficients; every number must be finite")
            if np.any(poly.imag != 0):
                raise ControllerError(f"the transfer function's {name} has complex coefficients; give real polynomials")
        num, den = num.real, den.real
        if not np.any(num):
            raise ControllerError("the transfer function's numerator is 0, which switches the controller off; give a non-zero gain")
        if not np.any(den):
            raise ControllerError("the transfer function's denominator is 0; give a valid G(s)")
        zeros = _roots(num, "the transfer function's numerator")
        poles = _roots(den, "the transfer function's denominator")
        with np.errstate(all="ignore"):  # an overflow gives inf, which Factor refuses
            gain = num[0] / den[0]
        return cls.from_zpk(zeros, poles, gain)

    @classmethod
    def pid(cls, kp: float, ki: float, kd: float, wf: float = 62.8, Ti: float = 0.628) -> "Controller":
        """``Kp + Ki/(s + 1/Ti) + Kd·wf·s/(s + wf)`` as a one-factor kernel.

        The integral part has its pole at ``-1/Ti`` (not at 0) and the derivative is filtered at ``wf``.
        Terms with a zero gain drop out with their poles.

        Examples
        --------
        >>> c = Controller.pid(kp=10.0, ki=5.0, kd=0.0)
        >>> c.kernel.poles, round(c.kernel.zeros[0], 4)
        ((-1.5923566878980893,), -2.0924)
        """
        kp_, ki_, kd_ = (_pid_real(v, name) for v, name in ((kp, "Kp"), (ki, "Ki"), (kd, "Kd")))
        wf_, Ti_ = _pid_real(wf, "wf"), _pid_real(Ti, "Ti")
        what = f"PID (Kp={kp_:g}, Ki={ki_:g}, Kd={kd_:g}, wf={wf_:g}, Ti={Ti_:g})"
        if wf_ <= 0 or Ti_ <= 0:
            raise ControllerError(f"{what}: wf and Ti must be > 0 (defaults wf=62.8 rad/s, Ti=0.628 s)")
        if kp_ == 0 and ki_ == 0 and kd_ == 0:
            raise ControllerError(f"{what}: all gains are 0, which switches the controller off; give a non-zero Kp, Ki or Kd")
        a = 1.0 / Ti_
        if not math.isfinite(a):
            raise ControllerError(f"{what}: Ti is too small (1/Ti overflows); give Ti in seconds, default 0.628")
        # Only the poles of the terms that are present: the common denominator of the others.
        poles = ([-a] if ki_ != 0 else []) + ([-wf_] if kd_ != 0 else [])
        den_i = np.poly([-a]) if ki_ != 0 else np.array([1.0])
        den_d = np.poly([-wf_]) if kd_ != 0 else np.array([1.0])
        with np.errstate(all="ignore"):  # extreme values overflow; checked just below
            num = np.polyadd(kp_ * np.convolve(den_i, den_d), ki_ * den_d)
            num = np.polyadd(num, kd_ * wf_ * np.convolve([1.0, 0.0], den_i))
        num = _trim(num)
        if not np.all(np.isfinite(num)):
            raise ControllerError(f"{what}: the gains are too large to combine into one transfer function; give smaller values")
        if not np.any(num):
            raise ControllerError(f"{what}: the terms cancel to 0; change the gains")
        if num[-1] == 0:
            raise ControllerError(f"{what}: Kp/Ti + Ki = 0 puts a zero exactly at s = 0 (a pure filtered differentiator); change Kp or Ki")
        zeros = _roots(num, what)
        return _label_errors("PID", lambda: cls.from_zpk(zeros, poles, num[0]))


def zpk(zeros: Any, poles: Any, gain: Any) -> Controller:
    """A controller from its zeros, poles and gain (one kernel factor), checked against the entry rules.

    Parameters
    ----------
    zeros, poles : sequence of number
        Roots (complex ones in conjugate pairs; none exactly at 0).
    gain : float
        Leading-coefficient gain, non-zero.

    Returns
    -------
    Controller

    Examples
    --------
    >>> print(zpk([-3, -6], [-30, -0.1], 80))
    80 (s + 3)(s + 6) / ((s + 30)(s + 0.1))
    """
    return Controller.from_zpk(zeros, poles, gain)


def pid(kp: float, ki: float, kd: float, wf: float = 62.8, Ti: float = 0.628) -> Controller:
    """The lab's PID ``Kp + Ki/(s + 1/Ti) + Kd·wf·s/(s + wf)`` (see :meth:`Controller.pid`).

    Parameters
    ----------
    kp, ki, kd : float
        Proportional, integral and derivative gains.
    wf : float
        Derivative filter frequency in rad/s (default 62.8).
    Ti : float
        Integral time constant in s (the integrator's pole is at ``-1/Ti``; default 0.628).

    Returns
    -------
    Controller

    Examples
    --------
    >>> pid(600, 200, 5).order
    2
    """
    return Controller.pid(kp, ki, kd, wf=wf, Ti=Ti)


def _pid_real(value: Any, name: str) -> float:
    number = to_number(value, f"PID {name}")
    if isinstance(number, complex):
        raise ControllerError(f"PID {name} = {format_number(number)} is complex; give a real number")
    return float(number)


def _factor_from_mapping(data: Any, label: str, *, gain_required: bool) -> Factor:
    if not isinstance(data, Mapping):
        raise ControllerError(f"{label} must be a table with zeros, poles and gain, got {_show(data)}")
    unknown = [k for k in data if k not in _FACTOR_KEYS]
    if unknown:
        raise ControllerError(f"unknown key {_show(unknown[0])} in {label}; allowed keys are zeros, poles, gain")
    if gain_required and "gain" not in data:
        raise ControllerError(f"{label} has no gain; add gain = <non-zero number> (the kernel's gain is required)")
    return _label_errors(label, lambda: Factor(data.get("zeros", ()), data.get("poles", ()), data.get("gain", 1.0), label=label))


def _roots(poly: np.ndarray, what: str) -> list[Number]:
    """Roots of a real polynomial; coefficients too extreme for that are a ControllerError."""
    try:
        with np.errstate(all="ignore"):
            roots = np.roots(poly)
    except (np.linalg.LinAlgError, ValueError):
        roots = np.array([np.nan])
    if not np.all(np.isfinite(roots)):
        raise ControllerError(f"{what}: the coefficients are too extreme to find the roots; give zeros and poles instead")
    return _clean_roots(roots)


def _trim(poly: np.ndarray) -> np.ndarray:
    """Drop exactly-zero leading coefficients."""
    poly = np.atleast_1d(poly)
    nonzero = np.flatnonzero(poly != 0)
    return poly[nonzero[0]:] if nonzero.size else poly[-1:]


def _clean_roots(roots: np.ndarray) -> list[Number]:
    """Numerical roots with round-off imaginary parts dropped and conjugate pairs made exact."""
    out: list[Number] = []
    for r in np.asarray(roots, dtype=complex):
        if abs(r.imag) <= 1e-12 * max(1.0, abs(r)):
            out.append(float(r.real))
        else:
            out.append(complex(r))
    # np.roots returns pairs as exact conjugates; enforce it anyway (pair by nearest conjugate).
    pending = [i for i, v in enumerate(out) if isinstance(v, complex) and v.imag > 0]
    lower = [i for i, v in enumerate(out) if isinstance(v, complex) and v.imag < 0]
    for i in pending:
        if not lower:
            break
        j = min(lower, key=lambda k: abs(complex(out[k]) - complex(out[i]).conjugate()))
        if abs(complex(out[j]) - complex(out[i]).conjugate()) <= 1e-6 * max(1.0, abs(complex(out[i]))):
            out[j] = complex(out[i]).conjugate()
            lower.remove(j)
    return out


def _real_if_real(values: np.ndarray) -> np.ndarray:
    values = np.asarray(values, dtype=complex)
    return values.real.copy() if np.all(values.imag == 0) else values


# ---------------------------------------------------------------------------------------------- text
def _root_factor(root: complex) -> str:
    sign = "-" if root.real > 0 else "+"
    return f"(s {sign} {abs(root.real):.6g})"


def _pair_factor(root: complex) -> str:
    """``(s^2 + 2ζω s + ω²)`` for a conjugate pair."""
    b, c = -2.0 * root.real, abs(root) ** 2
    middle = f" {'+' if b >= 0 else '-'} {abs(b):.6g}s" if b != 0 else ""
    return f"(s^2{middle} + {c:.6g})"


def format_zpk(zeros: Sequence[Number], poles: Sequence[Number], gain: float) -> str:
    """``40000 (s + 5)(s + 17) / ((s - 7)(s + 80)^2)``; conjugate pairs as real quadratics.

    Examples
    --------
    >>> format_zpk([-1], [-3+4j, -3-4j, -80], 2.0)
    '2 (s + 1) / ((s^2 + 6s + 25)(s + 80))'
    """

    def product(roots: Sequence[Number]) -> tuple[str, int]:
        terms: list[str] = []
        for r in roots:
            r = complex(r)
            if r.imag > 0:
                terms.append(_pair_factor(r))
            elif r.imag == 0:
                terms.append(_root_factor(r))
        counts = Counter(terms)
        parts, seen = [], set()
        for t in terms:
            if t in seen:
                continue
            seen.add(t)
            parts.append(t + (f"^{counts[t]}" if counts[t] > 1 else ""))
        return "".join(parts), len(parts)

    num, _ = product(zeros)
    den, n_den = product(poles)
    gain_text = f"{gain:.6g}"
    if num:
        text = num if gain == 1 else ("-" + num if gain == -1 else f"{gain_text} {num}")
    else:
        text = gain_text
    if not den:
        return text
    return f"{text} / ({den})" if n_den > 1 else f"{text} / {den}"


def parse_compensator(text: str, label: str = "compensator") -> Factor:
    """``"ZEROS;POLES[;GAIN]"``, e.g. ``"-17;-80"``, ``"none;-80"`` or ``"-1;-10;2.5"``.

    Examples
    --------
    >>> parse_compensator("-3+4j, -3-4j; -10, -20, -30; 2")
    Factor(zeros=((-3+4j), (-3-4j)), poles=(-10.0, -20.0, -30.0), gain=2.0)
    """
    if not isinstance(text, str):
        raise ControllerError(f"{label}: expected text \"ZEROS;POLES[;GAIN]\", got {_show(text)}")
    parts = text.split(";")
    if len(parts) not in (2, 3):
        raise ControllerError(
            f"{label} {_show(text.strip())} has {len(parts)} part(s); write ZEROS;POLES[;GAIN] with ';' between them, e.g. \"-16;-80\" or \"none;-80;2\""
        )
    zeros = parse_numbers(parts[0], f"{label} zeros")
    poles = parse_numbers(parts[1], f"{label} poles")
    gain: Any = 1.0
    if len(parts) == 3 and parts[2].strip():
        gain = to_number(parts[2], f"{label} gain")
    return Factor(zeros, poles, gain, label=label)


def parse_controller(zeros: str, poles: str, gain: Any, compensators: Sequence[str] = ()) -> Controller:
    """A controller from its text form (the command-line flags): kernel zeros, poles, gain, compensators.

    Examples
    --------
    >>> print(parse_controller("-5", "7", "40000", ["-17;-80", "none;-80"]))
    40000 (s + 5)(s + 17) / ((s - 7)(s + 80)^2)
    """
    if gain is None or (isinstance(gain, str) and not gain.strip()):
        raise ControllerError("the kernel has no gain; give the kernel's gain (a non-zero number)")
    if isinstance(compensators, str):
        compensators = [compensators]
    if len(compensators) > MAX_FACTORS - 1:
        raise ControllerError(f"{len(compensators)} compensators given; at most {MAX_FACTORS - 1} are allowed besides the kernel: merge compensators into one")
    kernel = Factor(parse_numbers(zeros, "kernel zeros"), parse_numbers(poles, "kernel poles"), to_number(gain, "kernel gain"), label="kernel")
    factors = [kernel] + [parse_compensator(c, f"compensator {i + 1}") for i, c in enumerate(compensators)]
    return Controller(factors)


# ---------------------------------------------------------------------------------------------- demo
#: The demo controller's factors (kernel, two compensators). See :func:`demo_controller`.
DEMO_FACTORS = (((-5.0,), (7.0,), 40000.0), ((-17.0,), (-80.0,), 1.0), ((), (-80.0,), 1.0))


def demo_controller(pendulum: str = "long") -> Controller:
    """A controller that balances both pendulums: ``40000 (s+5)(s+17) / ((s-7)(s+80)^2)``.

    Kernel ``40000 (s+5)/(s-7)``, compensators ``(s+17)/(s+80)`` and ``1/(s+80)``.

    Examples
    --------
    >>> print(demo_controller())
    40000 (s + 5)(s + 17) / ((s - 7)(s + 80)^2)

    The plant ``alpha/V`` has a zero at ``s = 0`` and one unstable pole (``+4.84`` long, ``+6.40``
    short), so only an *unstable* controller can stabilize the tip loop (parity interlacing): the
    kernel's pole at ``+7`` does this. The zero at ``-17`` sits near the cart's fast pole and
    ``(s+80)^2`` rolls off the encoder noise. Designed for both lengths at once on the sampled linear
    loop (1 ms, Tustin, one sample of computation delay, :mod:`pendulab.control.loop`):

    ========  =============================  =============  ================
    pendulum  slowest closed-loop pole       least damping  stable loop gain
    ========  =============================  =============  ================
    long      s = -2.39 (z = 0.99761)        0.58           0.56x .. 4.2x
    short     s = -2.97±4.88j (z = 0.99704)  0.52           0.70x .. 4.3x
    ========  =============================  =============  ================

    A 50 rad/s² 5 ms poke gives a swing of 1.1° (long) / 1.3° (short) with at most 2 V, settling in
    about 1.7 s (long) / 1.3 s (short) in the linear model; the cart drifts by 8 cm (long) / 2 cm
    (short), as no integral action is possible through the plant's zero at 0. The lab's 220 rad/s²
    poke gives about 5° with up to 8.7 V and moves the cart 0.35 m. With the lab's stick-slip
    friction the pendulum keeps a limit cycle of about ±0.7° (long) / ±1.3° (short).

    Parameters
    ----------
    pendulum : {"long", "short"}
        Accepted for symmetry with the rest of the API; the same controller serves both.
    """
    if pendulum not in ("long", "short"):
        raise ControllerError(f"unknown pendulum {_show(pendulum)} for the demo controller; choose long or short")
    labels = ["kernel"] + [f"compensator {i}" for i in range(1, len(DEMO_FACTORS))]
    return Controller([Factor(z, p, k, label=label) for (z, p, k), label in zip(DEMO_FACTORS, labels)])


def unstable_example(pendulum: str = "long") -> Controller:
    """The demo controller with the wrong sign of the gain: the pendulum falls at once.

    For tests of the safety cuts: the sampled loop has a real pole at ``z = 1.023`` (1 ms), so any
    deviation grows e-fold every 43 ms; after the default poke the angle passes 15° within 0.2 s.
    """
    demo = demo_controller(pendulum)
    kernel = demo.kernel
    return Controller([Factor(kernel.zeros, kernel.poles, -kernel.gain, label="kernel"), *demo.compensators])
