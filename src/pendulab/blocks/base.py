"""The base class of custom blocks: a controller (or any block) written as a Python class.

A block declares its variables in three small tables of :class:`Var` (start value, unit,
description) and implements :meth:`Block.step`. :func:`pendulab.blocks.build.build_block` turns
the class into an FMI 2.0 Co-Simulation FMU with **pythonfmu**; pendulab's master runs it beside the
native FMUs.

Semantics (a sampled block, like the lab's real-time controller): at every communication point
``t`` the block samples its inputs once and :meth:`~Block.step` computes the outputs held over
``[t, t + h]`` and advances the block's own state. With ``feedthrough = True`` (the default) the
outputs are computed as soon as a master reads them at ``t``, so they respond to the inputs of the
same point with no delay, like the native Controller FMU; with ``feedthrough = False`` they are
computed in ``fmi2DoStep`` and appear at ``t + h`` (one step of delay, no algebraic loop).

Examples
--------
A gain, in its own file ``gain.py``:

>>> from pendulab.blocks import Block, Var
>>> class Gain(Block):
...     '''Multiply the input by k.'''
...     inputs = {"u": Var(0.0, "V", "Input signal")}
...     outputs = {"y": Var(0.0, "V", "k times u")}
...     parameters = {"k": Var(2.0, None, "Gain")}
...
...     def step(self, t, h):
...         self.y = self.k * self.u
>>> block = Gain(instance_name="gain")        # what the FMU does when it is instantiated
>>> block.exit_initialization_mode()         # ... and at the end of its initialization
>>> block.u = 1.5
>>> block.do_step(0.0, 1e-3)
True
>>> block.y
3.0

Build it with ``pendulab.blocks.build_block("gain.py", "fmus/")``.
"""

from __future__ import annotations

import json
import keyword
import math
from abc import abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from pythonfmu import Fmi2Slave
from pythonfmu.enums import Fmi2Causality, Fmi2Initial, Fmi2Status, Fmi2Variability
from pythonfmu.variables import Boolean, Integer, Real

from pendulab.errors import UserError

#: File in the FMU's ``resources/`` with start values that override a class's defaults
#: (written by :func:`pendulab.blocks.build.build_block`).
START_VALUES_FILE = "pendulab_start_values.json"

_TYPES = {bool: "Boolean", int: "Integer", float: "Real"}

#: Instance attributes of pythonfmu's Fmi2Slave that a variable must not overwrite.
_RESERVED = frozenset(
    {"vars", "instance_name", "resources", "visible", "log_queue", "guid", "author", "license", "version",
     "copyright", "modelName", "description", "default_experiment"}
)


@dataclass(frozen=True)
class Var:
    """One variable of a block: start value (its type sets the FMI type), unit, description.

    Parameters
    ----------
    start : float, int or bool
        Start value; ``float`` -> Real, ``int`` -> Integer, ``bool`` -> Boolean.
    unit : str, optional
        Unit of a Real (``"m"``, ``"rad/s"``, ``"V/m"``); written to the model description.
    description : str
        One line for the model description.
    tunable : bool
        Parameters only: the master may change it between steps (default: fixed after initialization).

    Examples
    --------
    >>> Var(0.6413, "m", "Pendulum length").type
    'Real'
    >>> Var(3, description="Filter order").type
    'Integer'
    """

    start: float | int | bool = 0.0
    unit: str | None = None
    description: str = ""
    tunable: bool = False

    @property
    def type(self) -> str:
        return _TYPES.get(type(self.start), "Real")

    def coerce(self, value: Any, name: str) -> float | int | bool:
        """``value`` converted to this variable's type, or a UserError naming ``name``."""
        try:
            if self.type == "Boolean":
                if isinstance(value, str):
                    if value.lower() not in ("true", "false", "1", "0"):
                        raise ValueError(value)
                    return value.lower() in ("true", "1")
                return bool(value)
            if self.type == "Integer":
                if isinstance(value, float) and not value.is_integer():
                    raise ValueError(value)
                return int(value)
            result = float(value)
        except (TypeError, ValueError):
            raise UserError(f"start value {value!r} of {name} is not a {self.type}; give a {self.type.lower()} number") from None
        if not math.isfinite(result):
            raise UserError(f"start value {value!r} of {name} is not finite; give a finite number")
        return result


class Block(Fmi2Slave):
    """Base class of a custom block: declare the variable tables, implement :meth:`step`.

    Class attributes
    ----------------
    inputs, outputs, parameters : dict of str -> Var
        The block's variables. Each becomes an attribute of the instance (``self.u``) holding its
        current value. Every block also has the parameter ``h`` (the sample period).
    feedthrough : bool
        ``True``: outputs respond at the same communication point (see the module docstring).
    author, version : str, optional
        Written to the model description; the class docstring's first line is its description.

    Parameters
    ----------
    **kwargs
        pythonfmu's instance arguments (``instance_name``, ...); the FMU passes them.

    Notes
    -----
    Keep a block's state in attributes you reassign (floats, tuples): when a master changes an
    input after the outputs were computed at the same point, the block restores its attributes
    (a shallow copy taken before :meth:`step`) and samples again.

    Examples
    --------
    >>> class Doubler(Block):
    ...     '''Twice the input.'''
    ...     inputs = {"u": Var(0.0, "V", "Input")}
    ...     outputs = {"y": Var(0.0, "V", "2 u")}
    ...
    ...     def step(self, t, h):
    ...         self.y = 2 * self.u
    >>> sorted(Doubler.parameters) + sorted(Doubler.BASE_PARAMETERS)
    ['h']

    The module docstring runs a block by hand; :func:`pendulab.blocks.build_block` makes it an FMU.
    """

    inputs: ClassVar[dict[str, Var]] = {}
    outputs: ClassVar[dict[str, Var]] = {}
    parameters: ClassVar[dict[str, Var]] = {}
    feedthrough: ClassVar[bool] = True
    h: float  # the sample period, a parameter of every block (see BASE_PARAMETERS)

    #: Parameters every block has.
    BASE_PARAMETERS: ClassVar[dict[str, Var]] = {
        "h": Var(1e-3, "s", "Sample period: the communication step the block expects (the master sets it)"),
    }

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "description" not in cls.__dict__ and cls.__doc__:
            cls.description = cls.__doc__.strip().splitlines()[0]
        seen: dict[str, str] = {}
        for kind, table in (("input", cls.inputs), ("output", cls.outputs), ("parameter", cls.parameters)):
            if not isinstance(table, Mapping):
                raise UserError(f"{cls.__name__}.{kind}s must be a dict of name -> Var")
            for name, var in table.items():
                where = f"{cls.__name__}: {kind} {name!r}"
                if not isinstance(var, Var):
                    raise UserError(f"{where} must be declared as Var(start, unit, description), not {var!r}")
                if not (isinstance(name, str) and name.isidentifier()) or keyword.iskeyword(name) or name.startswith("_"):
                    raise UserError(f"{where} is not a valid name; use a Python identifier not starting with '_'")
                if name in seen:
                    raise UserError(f"{where} is also declared as {seen[name]}; give each variable its own name")
                if name in cls.BASE_PARAMETERS and not (kind == "parameter" and var.type == "Real"):
                    raise UserError(f"{where} clashes with the block parameter {name!r}; rename it")
                if name not in cls.BASE_PARAMETERS and (hasattr(Block, name) or name in _RESERVED):
                    raise UserError(f"{where} clashes with the attribute Block.{name}; rename it")
                if var.type == "Integer" and var.unit:
                    raise UserError(f"{where} has the integer start {var.start!r} and a unit; write {float(var.start)!r} for a Real")
                if kind == "output" and var.tunable:
                    raise UserError(f"{where} cannot be tunable; only parameters are")
                seen[name] = kind

    @classmethod
    def variables(cls) -> dict[str, tuple[str, Var]]:
        """Every variable in value-reference order: name -> (causality, Var)."""
        result: dict[str, tuple[str, Var]] = {}
        for name, var in cls.inputs.items():
            result[name] = ("input", var)
        for name, var in cls.outputs.items():
            result[name] = ("output", var)
        for name, var in {**cls.BASE_PARAMETERS, **cls.parameters}.items():
            result[name] = ("parameter", var)
        return result

    @classmethod
    def units(cls) -> dict[str, str]:
        """Variable name -> unit, for the Real variables that declare one."""
        return {name: var.unit for name, (_, var) in cls.variables().items() if var.unit and var.type == "Real"}

    # ------------------------------------------------------------------ construction
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        table = self.variables()
        for name, (_, var) in table.items():
            setattr(self, name, var.start)
        for name, value in _start_overrides(self.resources).items():
            if name not in table or table[name][0] == "output":
                raise UserError(f"{START_VALUES_FILE} sets {name!r}, which is no parameter or input of {type(self).__name__}")
            setattr(self, name, table[name][1].coerce(value, name))
        kinds = {"Real": Real, "Integer": Integer, "Boolean": Boolean}
        for name, (causality, var) in table.items():
            continuous = var.type == "Real"
            if causality == "parameter":
                options = {
                    "causality": Fmi2Causality.parameter,
                    "variability": Fmi2Variability.tunable if var.tunable else Fmi2Variability.fixed,
                    "initial": Fmi2Initial.exact,
                }
            elif causality == "input":
                options = {
                    "causality": Fmi2Causality.input,
                    "variability": Fmi2Variability.continuous if continuous else Fmi2Variability.discrete,
                }
            else:
                options = {
                    "causality": Fmi2Causality.output,
                    "variability": Fmi2Variability.continuous if continuous else Fmi2Variability.discrete,
                    "initial": Fmi2Initial.calculated,
                }
            self.register_variable(kinds[var.type](name, description=var.description or None, **options))
        refs = {v.name: vr for vr, v in self.vars.items()}
        self._input_refs = frozenset(refs[n] for n, (c, _) in table.items() if c == "input")
        self._output_refs = frozenset(refs[n] for n, (c, _) in table.items() if c == "output")
        self._time = 0.0
        self._last_step = float(self.h)
        self._initialized = False
        self._sampled = False
        self._snapshot: dict[str, Any] | None = None
        self._failure: str | None = None

    # ------------------------------------------------------------------ what a block implements
    def initialize(self, t: float) -> None:
        """Called once when initialization ends, with the parameters set: check them, reset states.

        Raise :class:`~pendulab.errors.UserError` (or ValueError) with a one-line message for a bad
        parameter: the block then stops, its first ``fmi2DoStep`` fails, and the message goes to
        its log and to :func:`block_error`. An exception in :meth:`step` does the same.
        """

    @abstractmethod
    def step(self, t: float, h: float) -> None:
        """Sample the inputs at ``t``, set the outputs held over ``[t, t + h]``, advance the state."""

    def warn(self, message: str) -> None:
        """Log a warning through the FMU's logger."""
        self.log(message, Fmi2Status.warning)

    # ------------------------------------------------------------------ the FMI side
    # No exception may leave these methods: pythonfmu 0.7 releases its Python objects when one
    # does and releases them again when the instance is freed, which corrupts the interpreter.
    # A failure is recorded instead (block_error, the FMU log) and the next fmi2DoStep returns
    # fmi2Discard, which a master reports as a failed step.
    def setup_experiment(self, start_time: float, stop_time: float | None = None, tolerance: float | None = None) -> None:
        self._time = float(start_time)

    def exit_initialization_mode(self) -> None:
        _ERRORS.pop(self.instance_name, None)
        self._failure = None
        try:
            self._last_step = float(self.h)
            if not self._last_step > 0:
                raise UserError(f"sample period h = {self._last_step} s must be positive")
            self.initialize(self._time)
        except Exception as exc:  # noqa: BLE001 - see above
            self._fail(exc, "initialize")
            return
        self._initialized = True

    def do_step(self, current_time: float, step_size: float) -> bool:
        if not self._sampled:
            self._sample(current_time, step_size)
        self._time = current_time + step_size
        self._last_step = step_size
        self._sampled = False
        self._snapshot = None
        return self._failure is None

    def _sample(self, t: float, h: float) -> None:
        if self._failure is not None or not self._initialized:
            return
        if self.feedthrough:
            self._snapshot = None  # no chain of snapshots
            self._snapshot = dict(self.__dict__)
        try:
            self.step(t, h)
        except Exception as exc:  # noqa: BLE001 - see above
            self._fail(exc, f"step at t = {t:.6g} s")
            return
        self._sampled = self.feedthrough

    def _fail(self, exc: Exception, where: str) -> None:
        detail = str(exc) if isinstance(exc, UserError) else f"{type(exc).__name__}: {exc}"
        self._failure = message = f"{type(self).__name__} ({where}): {detail}"
        _ERRORS[self.instance_name] = message
        self.log(message, Fmi2Status.error)

    def _get(self, getter: Any, vrs: list[int], fallback: Any) -> list[Any]:
        try:
            if self.feedthrough and not self._sampled and not self._output_refs.isdisjoint(vrs):
                self._sample(self._time, self._last_step)
            return getter(vrs)
        except Exception as exc:  # noqa: BLE001 - see above
            self._fail(exc, "get")
            return [fallback] * len(vrs)

    def _set(self, setter: Any, vrs: list[int], values: list[Any]) -> None:
        try:
            # A value changed after the outputs were computed at this point: undo that sample.
            if self._sampled and self._snapshot is not None:
                snapshot = self._snapshot
                self.__dict__.clear()
                self.__dict__.update(snapshot)
            setter(vrs, values)
        except Exception as exc:  # noqa: BLE001 - see above
            self._fail(exc, "set")

    def get_real(self, vrs: list[int]) -> list[float]:
        return self._get(super().get_real, vrs, math.nan)

    def get_integer(self, vrs: list[int]) -> list[int]:
        return self._get(super().get_integer, vrs, 0)

    def get_boolean(self, vrs: list[int]) -> list[bool]:
        return self._get(super().get_boolean, vrs, False)

    def set_real(self, vrs: list[int], values: list[float]) -> None:
        self._set(super().set_real, vrs, values)

    def set_integer(self, vrs: list[int], values: list[int]) -> None:
        self._set(super().set_integer, vrs, values)

    def set_boolean(self, vrs: list[int], values: list[bool]) -> None:
        self._set(super().set_boolean, vrs, values)


#: The last error of each block instance (by instance name): a master's FMI call only sees a
#: failed status, and pythonfmu drops the log message unless logging was switched on.
_ERRORS: dict[str, str] = {}


def block_error(instance_name: str) -> str | None:
    """The message of the last exception a block instance raised in ``initialize`` or ``step``.

    Examples
    --------
    >>> block_error("no such instance") is None
    True
    """
    return _ERRORS.get(instance_name)


def _start_overrides(resources: str | None) -> dict[str, Any]:
    if not resources:
        return {}
    path = Path(resources) / START_VALUES_FILE
    if not path.is_file():
        return {}
    return dict(json.loads(path.read_text()))
