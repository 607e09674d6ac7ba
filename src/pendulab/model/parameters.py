"""Plant parameters as plain data, shared by the CasADi model, the FMU builder, the CLI and the fit.

The parameter names are those of the specification and of the plant FMU's variables. Each field
carries its unit and description as metadata, so the FMU's ``modelDescription.xml`` is written from
this one place.

Examples
--------
>>> from pendulab.model.parameters import PlantParameters
>>> p = PlantParameters.preset(pendulum="long", cart="ip02")
>>> round(p.lumped_cart_mass, 4)
0.7031
>>> p.with_values(Beq=5.0).Beq
5.0
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, fields
from typing import Any, Iterator, Mapping

from pendulab.errors import ParameterError

PENDULUMS = ("long", "short", "none")
CARTS = ("ip02", "ip02-weight", "ip01")


def _p(value: float, unit: str, description: str, minimum: float = 0.0, maximum: float = math.inf, *,
       positive: bool = False) -> Any:
    """A parameter field: default, unit, description and its range ``minimum <= value <= maximum``
    (``positive``: also ``value > 0``). The range is the plant FMU's ``min``/``max`` too, which the FMU
    checks when the value is set."""
    return field(default=value, metadata={"unit": unit, "description": description, "min": minimum, "max": maximum,
                                          "positive": positive})


def range_text(minimum: float, maximum: float, unit: str) -> str:
    """``"0.01 to 100 kg"``: a range as the error messages (Python and the FMUs' C) word it."""
    unit = "" if unit in ("", "1") else f" {unit}"
    return f"{minimum:g} to {maximum:g}{unit}"


@functools.cache
def _ranges(cls: type) -> tuple[tuple[str, str, float, float, bool], ...]:
    """``(name, unit, min, max, positive)`` of every ``_p`` field of the dataclass ``cls``, in order (read once:
    a sweep builds parameters for every run)."""
    return tuple((f.name, f.metadata["unit"], f.metadata["min"], f.metadata["max"], f.metadata["positive"]) for f in fields(cls))


@functools.cache
def _names(cls: type) -> tuple[str, ...]:
    return tuple(r[0] for r in _ranges(cls))


def check_ranges(values: Any, owner: str = "parameter") -> None:
    """Raise :class:`ParameterError` (one line: name, value, allowed range) for the first field of the
    dataclass ``values`` that is not a finite number within its ``_p`` range."""
    for name, unit, low, high, positive in _ranges(type(values)):
        value = getattr(values, name)
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise ParameterError(f"{owner} {name}={value!r} is not a number; give a real value in {unit}")
        if not math.isfinite(value):
            raise ParameterError(f"{owner} {name}={value} is not finite; give a finite value in {unit}")
        if not low <= value <= high:
            negative = " (negative)" if value < 0 <= low else ""
            raise ParameterError(f"{owner} {name}={value}{negative} is outside its range {range_text(low, high, unit)}")
        if positive and value <= 0:
            raise ParameterError(f"{owner} {name}={value} must be > 0 {unit}")


#: Conditions between parameters, in the one syntax that Python and C both read (comparisons, ``+ - * /``,
#: ``or``/``and``), with the reason shown when one fails. The plant FMU checks the same text on leaving
#: initialization (generated into its C by :func:`pendulab.fmu.description.constraints_c`).
CONSTRAINTS: tuple[tuple[str, str], ...] = (
    ("lp <= Lp", "the centre of gravity lies between the pivot and the tip: set lp <= Lp"),
    ("Mp == 0 or Ip + Mp * lp * lp > 0", "the pendulum has mass but no inertia: set lp > 0 or Ip > 0"),
)
#: The conditions compiled once.
_CONSTRAINT_CODE = tuple((compile(condition, "<constraint>", "eval"), condition, why) for condition, why in CONSTRAINTS)


@dataclass(frozen=True)
class PlantParameters:
    """Every parameter of the cart-pendulum plant (SPEC §2), in SI units.

    ``I_max = 0`` switches the amplifier current limit off; ``q_alpha = 0`` or ``q_x = 0`` switches
    that encoder's quantization off; ``F1 = F2 = 0`` switches stick-slip friction off.
    """

    # pendulum (defaults: long, 24 in)
    Mp: float = _p(0.230, "kg", "Pendulum mass", 0, 10)
    Lp: float = _p(0.6413, "m", "Pendulum length, pivot to tip", 0, 5)
    lp: float = _p(0.3302, "m", "Pivot to pendulum centre of gravity", 0, 5)
    Ip: float = _p(0.230 * 0.6413**2 / 12, "kg.m2", "Pendulum inertia about its centre of gravity", 0, 10)
    Bp: float = _p(0.0024, "N.m.s/rad", "Viscous damping at the pendulum pivot", 0, 10)
    # cart and motor (defaults: IP02, no load)
    M_cart: float = _p(0.57, "kg", "Cart mass without the motor's rotor inertia", 0.01, 100)
    Beq: float = _p(4.3, "N.s/m", "Equivalent viscous damping of the cart", 0, 1e4)
    Rm: float = _p(2.6, "Ohm", "Motor armature resistance", 0.01, 1000)
    Kt: float = _p(0.007683, "N.m/A", "Motor torque constant", 1e-5, 10)
    Km: float = _p(0.007678, "V.s/rad", "Motor back-EMF constant", 0, 10)
    Kg: float = _p(3.71, "1", "Planetary gearbox ratio", 0.01, 1000)
    eta_g: float = _p(1.0, "1", "Gearbox efficiency", 0.01, 1)
    eta_m: float = _p(1.0, "1", "Motor efficiency", 0.01, 1)
    Jm: float = _p(3.90e-7, "kg.m2", "Rotor moment of inertia", 0, 1)
    r_mp: float = _p(6.35e-3, "m", "Motor pinion radius", 1e-4, 1)
    force_gain: float = _p(1.0, "1", "Calibration factor on the motor force", 0.01, 100)
    g: float = _p(9.81, "m/s2", "Gravitational acceleration", 0, 100)
    # amplifier
    V_max: float = _p(10.0, "V", "Amplifier voltage saturation", 0.01, 1000)
    I_max: float = _p(0.0, "A", "Amplifier current limit (0 = no limit)", 0, 1000)
    # stick-slip friction vector [F1, v1, F2, v2, B]
    F1: float = _p(1.5, "N", "Stiction: the cart sticks below this motor force", 0, 1000)
    v1: float = _p(0.005, "m/s", "Stiction: the cart can stick below this speed", 0, 10)
    F2: float = _p(3.0, "N", "Slip: strong viscous drag below this motor force", 0, 1000)
    v2: float = _p(0.05, "m/s", "Slip: strong viscous drag below this speed", 0, 10)
    B: float = _p(20.0, "kg/s", "Slip: viscous drag coefficient", 0, 1e4)
    # encoders
    q_alpha: float = _p(0.001, "rad", "Angle encoder step (0 = no quantization)", 0, 1)
    q_x: float = _p(22.75e-6, "m", "Cart encoder step (0 = no quantization)", 0, 1)
    # poke: a rectangular pulse added to the angular acceleration
    # Any finite pulse (a huge one overflows the state, which the FMU's step reports as an error).
    poke_magnitude: float = _p(50.0, "rad/s2", "Poke magnitude", -1e15, 1e15)
    poke_duration: float = _p(0.005, "s", "Poke duration", 0, 1e3)
    poke_start: float = _p(1.0, "s", "Poke start time", 0, 1e6)
    # track: the cart stops dead at the end stops (appended last: earlier value references stay stable)
    track_half_length: float = _p(
        0.407, "m", "End stops: the cart stops dead at +/- this position (IP02: 0.814 m cart travel); 1e4: no stops within reach", 0.01, 1e6
    )

    def __post_init__(self) -> None:
        check_ranges(self)
        values = self.as_dict()
        for code, condition, why in _CONSTRAINT_CODE:
            if not eval(code, {"__builtins__": {}}, values):  # noqa: S307 - our own table's text
                raise ParameterError(f"parameters violate {condition}: {why}")

    # ------------------------------------------------------------------ construction
    @classmethod
    def preset(cls, pendulum: str = "long", cart: str = "ip02", **overrides: float) -> "PlantParameters":
        """Parameters of a lab configuration.

        Parameters
        ----------
        pendulum : {"long", "short", "none"}
            24 in or 12 in pendulum, or ``"none"`` for the cart alone (calibration ramps).
        cart : {"ip02", "ip02-weight", "ip01"}
            IP02 without load (default), IP02 with its extra weight, or the IP01.
        **overrides
            Any field by name.
        """
        if pendulum not in PENDULUMS:
            raise ParameterError(f"unknown pendulum {pendulum!r}; choose one of {', '.join(PENDULUMS)}")
        if cart not in CARTS:
            raise ParameterError(f"unknown cart {cart!r}; choose one of {', '.join(CARTS)}")
        values: dict[str, float] = {}
        if pendulum == "short":
            values.update(Mp=0.127, Lp=0.3365, lp=0.1778, Ip=0.127 * 0.3365**2 / 12)
        elif pendulum == "none":
            values.update(Mp=0.0, Lp=0.0, lp=0.0, Ip=0.0, Bp=0.0)
        if cart == "ip02-weight":
            values.update(M_cart=0.94, Beq=5.4)
        elif cart == "ip01":
            values.update(M_cart=0.52, Beq=0.9)
        values.update(overrides)
        return cls.from_mapping(values)

    @classmethod
    def from_mapping(cls, values: Mapping[str, float]) -> "PlantParameters":
        """Build from a mapping of field names; unknown names are an error."""
        unknown = sorted(set(values) - set(cls.names()))
        if unknown:
            raise ParameterError(f"unknown plant parameter {unknown[0]!r}; known ones are {', '.join(cls.names())}")
        return cls(**{k: float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v for k, v in values.items()})

    def with_values(self, **values: float) -> "PlantParameters":
        """A copy with some fields changed (validated like a new object)."""
        return type(self).from_mapping({**self.as_dict(), **values})

    # ------------------------------------------------------------------ views
    @classmethod
    def names(cls) -> tuple[str, ...]:
        """Field names in their fixed order (the order of the CasADi parameter vector)."""
        return _names(cls)

    @classmethod
    def describe(cls) -> Iterator[tuple[str, float, str, str]]:
        """``(name, default, unit, description)`` for every field."""
        for f in fields(cls):
            yield f.name, f.default, f.metadata["unit"], f.metadata["description"]

    def as_dict(self) -> dict[str, float]:
        # Every field is a float: no deep copy needed (dataclasses.asdict's costs 0.3 ms, and a sweep
        # builds parameters for every run).
        return {name: getattr(self, name) for name in self.names()}

    def as_vector(self) -> list[float]:
        return [getattr(self, n) for n in self.names()]

    @property
    def friction(self) -> tuple[float, float, float, float, float]:
        """The friction vector ``[F1, v1, F2, v2, B]``."""
        return (self.F1, self.v1, self.F2, self.v2, self.B)

    @property
    def lumped_cart_mass(self) -> float:
        """``Mc = M_cart + eta_g Kg^2 Jm / r_mp^2``: the cart with the rotor inertia lumped in."""
        return self.M_cart + self.eta_g * self.Kg**2 * self.Jm / self.r_mp**2

    def without_nonlinearities(self) -> "PlantParameters":
        """Friction, quantization, current limit and poke off (the linearization's assumptions)."""
        return self.with_values(F1=0.0, F2=0.0, q_alpha=0.0, q_x=0.0, I_max=0.0, poke_magnitude=0.0)


def _parameters_section() -> str:
    """The numpydoc Parameters section of :class:`PlantParameters`, from its fields' metadata (one source)."""
    lines = ["", "    Parameters", "    ----------"]
    for name, default, unit, description in PlantParameters.describe():
        lines += [f"    {name} : float", f"        {description} ({unit}; default {default:g})."]
    lines += ["", "    Examples", "    --------",
              "    >>> p = PlantParameters.preset(\"short\", cart=\"ip01\")",
              "    >>> p.Lp, p.M_cart, p.friction",
              "    (0.3365, 0.52, (1.5, 0.005, 3.0, 0.05, 20.0))", ""]
    return "\n".join(lines)


PlantParameters.__doc__ = (PlantParameters.__doc__ or "").rstrip() + "\n" + _parameters_section()

FRICTION_NAMES = ("F1", "v1", "F2", "v2", "B")
