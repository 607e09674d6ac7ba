"""One description of a run: :class:`RunSpec`, typed, immutable, validated, serializable.

A run is the plant (and its preset and calibration), the controller, the poke, the timing
(stop time, control period, discretization, transport delay), the encoders' quantization and the
supervisor's settings. The command line, the GUI, ``lab``, the firmware twin and scripts all build a
``RunSpec`` and hand it to :func:`pendulab.simulate`; the run's files carry its serialization.

Every section is a frozen dataclass whose fields have defaults, so a new field (with a default) is
read from older files unchanged and :meth:`RunSpec.from_dict` refuses unknown keys by name. The
rules (and the messages the command line prints) live once, in :meth:`RunSpec.validate`.

Examples
--------
>>> from pendulab.spec import RunSpec, Poke, Timing
>>> from pendulab.control import demo_controller
>>> spec = RunSpec(demo_controller(), poke=Poke(magnitude=220.0), timing=Timing(stop_time=3.0))
>>> spec.validate() is spec
True
>>> spec.timing.stop_time, spec.poke.start
(3.0, 1.0)
>>> RunSpec.from_json(spec.to_json()) == spec
True
>>> spec.replace(timing=Timing(stop_time=0.5)).validate()
Traceback (most recent call last):
    ...
pendulab.errors.UserError: the poke starts at t=1 s, not before the stop time 0.5 s; start the poke earlier or lengthen --stop-time
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import sys
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Mapping

from pendulab.errors import UserError

#: Plants a run can name (``plant.kind``).
PLANT_KINDS = ("pendulum", "seesaw")
#: Discretizations of the controller (``timing.method``).
METHODS = ("tustin", "zoh")
#: The poke of a run that names none: 50 rad/s^2 for 5 ms from t = 1 s (SPEC §2).
POKE_DEFAULT = (50.0, 0.005, 1.0)
#: Longest run in steps (the log is kept in memory): 2000 s at 1 kHz.
MAX_STEPS = 2_000_000
#: The control period's largest value (s).
MAX_STEP = 0.1


class FrozenDict(dict):
    """A read-only dict (picklable, unlike a mappingproxy: a spec goes to worker processes)."""

    def _refuse(self, *args: Any, **kwargs: Any) -> None:
        raise TypeError("a RunSpec is immutable: build a new one (dataclasses.replace) instead")

    __setitem__ = __delitem__ = clear = pop = popitem = setdefault = update = _refuse  # type: ignore[assignment]
    __ior__ = _refuse  # type: ignore[assignment]

    def __reduce__(self) -> tuple[Any, ...]:
        return (FrozenDict, (dict(self),))

    def __hash__(self) -> int:  # type: ignore[override]
        return hash(tuple(sorted(self.items())))


def _frozen_mapping(value: Any, where: str) -> Mapping[str, Any]:
    if value is None:
        value = {}
    if not isinstance(value, Mapping):
        raise UserError(f"{where} must be a table of names and values, got {type(value).__name__}")
    return FrozenDict(value)


def _choice(*choices: str, default: str) -> Any:
    return field(default=default, metadata={"choices": choices})


def _mapping_field() -> Any:
    # Mappings are held read-only and left out of the hash (a spec stays hashable).
    return field(default_factory=FrozenDict, hash=False, metadata={"mapping": True})


# ------------------------------------------------------------------------------------------ sections
@dataclass(frozen=True)
class Plant:
    """The plant: which one, its preset, calibration and parameter overrides.

    Parameters
    ----------
    kind : {"pendulum"}
        The plant model (the cart-pendulum; other plants add their name to :data:`PLANT_KINDS`).
    pendulum : {"long", "short", "none"}
        Pendulum preset (24 in, 12 in, or none).
    cart : {"ip02", "ip02-weight", "ip01"}
        Cart preset.
    calibration : str, optional
        Calibration file (JSON or the old lab's ``.mat``); ``None``: the lab's measured table.
    overrides : mapping of str to float
        Plant parameters by name (:class:`~pendulab.model.parameters.PlantParameters`), applied after
        the preset and the calibration.
    start : {"upright", "hanging"}
        The pendulum at t = 0: upright at rest (default), or hanging at rest (for ``supervisor.swing_up``).

    Examples
    --------
    >>> plant = Plant(pendulum="short", overrides={"Beq": 5.0})
    >>> params = plant.parameters()
    >>> params.Lp, params.Beq
    (0.3365, 5.0)
    """

    kind: str = _choice(*PLANT_KINDS, default="pendulum")
    pendulum: str = "long"
    cart: str = "ip02"
    calibration: str | None = None
    overrides: Mapping[str, float] = _mapping_field()
    start: str = _choice("upright", "hanging", default="upright")

    def validate(self) -> None:
        """Check the preset's names, the calibration file and the overrides (UserError)."""
        self.parameters()

    def parameters(self) -> Any:
        """The plant's :class:`~pendulab.model.parameters.PlantParameters` (the seesaw's
        :class:`~pendulab.model.seesaw.SeesawParameters`): the preset, then the calibration file, then
        the overrides (the poke and the quantization are the run's)."""
        from pendulab.model.parameters import PlantParameters

        if self.kind == "seesaw":
            from pendulab.model.seesaw import SeesawParameters

            if self.cart != "ip02":
                raise UserError(f"the seesaw carries the IP02 cart without its weight; --cart {self.cart} is not a seesaw configuration")
            seesaw = SeesawParameters()
            if self.calibration:
                from pendulab.calibration.files import load_calibration

                seesaw = seesaw.with_values(**load_calibration(self.calibration).values)
            return seesaw.with_values(**self.overrides) if self.overrides else seesaw

        if "_parameters" in self.__dict__:
            return self.__dict__["_parameters"]
        params = PlantParameters.preset(pendulum=self.pendulum, cart=self.cart)
        if self.calibration:
            from pendulab.calibration.files import load_calibration

            params = load_calibration(self.calibration).apply(params)
        if self.overrides:
            params = params.with_values(**self.overrides)
        if not self.calibration:
            # Kept: validate() and the run both ask for them, and a frozen section's parameters cannot change
            # (a calibration file is read each time: it may have been rewritten).
            self.__dict__["_parameters"] = params
        return params


@dataclass(frozen=True)
class ControllerSpec:
    """The controller: the student's ``G(s)`` or a controller block FMU.

    Parameters
    ----------
    transfer_function : Controller, optional
        Kernel and compensators (:class:`pendulab.control.Controller`), discretized at the control
        period.
    fmu : str, optional
        A controller block FMU (e.g. built with :func:`pendulab.blocks.build_block`) instead.
    state_feedback : StateFeedbackDesign, optional
        An LQR state feedback (:func:`pendulab.control.state_feedback.design_state_feedback`, or a
        ``pendulab lqr --out`` file), run in the Controller FMU with its derivative filters and integral.
    parameters : mapping
        Start values of the block FMU's parameters.
    label : str, optional
        How the run's files name the controller (default: ``G(s)`` written out, or the block's name).

    Examples
    --------
    >>> from pendulab.control import Controller
    >>> ControllerSpec(transfer_function=Controller.pid(40, 5, 4)).fmu is None
    True
    >>> ControllerSpec(fmu="fmus/LQRController.fmu", parameters={"K_x": -10.0}).parameters["K_x"]
    -10.0
    """

    transfer_function: Any = None
    fmu: str | None = None
    state_feedback: Any = None
    parameters: Mapping[str, float] = _mapping_field()
    label: str | None = None

    def validate(self) -> None:
        """Nothing to check alone: :meth:`RunSpec.validate` checks the preset, calibration and controller."""


@dataclass(frozen=True)
class Poke:
    """A rectangular pulse added to the pendulum's angular acceleration (SPEC §2).

    Parameters
    ----------
    magnitude : float
        rad/s^2 (default 50; 220 gives a response of the size seen on the rig).
    duration : float
        s (default 0.005).
    start : float
        s (default 1.0); before the run's stop time.

    Examples
    --------
    >>> Poke(220.0)
    Poke(magnitude=220.0, duration=0.005, start=1.0)
    """

    magnitude: float = POKE_DEFAULT[0]
    duration: float = POKE_DEFAULT[1]
    start: float = POKE_DEFAULT[2]

    @classmethod
    def parse(cls, text: str) -> "Poke":
        """From the command line's ``MAG,DUR,START`` (e.g. ``"220,0.005,1"``), checked.

        Examples
        --------
        >>> Poke.parse("220, 0.005, 1")
        Poke(magnitude=220.0, duration=0.005, start=1.0)
        """
        try:
            values = tuple(float(p.strip()) for p in text.split(","))
        except ValueError:
            raise UserError(f"--poke {text!r} must be three numbers MAG,DUR,START, e.g. --poke 50,0.005,1") from None
        if len(values) != 3:
            raise UserError(f"--poke {text!r} must be three numbers MAG,DUR,START, e.g. --poke 50,0.005,1")
        poke = cls(*values)
        poke.validate()
        return poke

    def validate(self) -> None:
        """Check this section's own rules (UserError with the command line's message)."""
        values = (self.magnitude, self.duration, self.start)
        if not all(math.isfinite(v) for v in values) or self.duration < 0 or self.start < 0:
            raise UserError(f"--poke {','.join(f'{v:g}' for v in values)}: the magnitude must be finite and the duration and start >= 0")

    def check_disturbs(self, magnitude: str = "--poke magnitude", duration: str = "--poke duration", what: str = "poke") -> None:
        """Refuse a poke that disturbs nothing (size or length 0): any controller "stays up" then (UserError).

        ``simulate`` and the GUI call it (``magnitude`` and ``duration`` name their fields in the message,
        ``what`` is "poke" or the seesaw's "tap"); a spec with such a poke still runs in Python, and its
        verdict is ``not tested``.

        Examples
        --------
        >>> Poke(0.0).check_disturbs()
        Traceback (most recent call last):
        ...
        pendulab.errors.UserError: --poke magnitude is 0: a poke of size 0 disturbs nothing, so any controller would stay up and the run would test nothing; give a magnitude such as 50 rad/s^2 (the default) or 220 (the lab's)
        """
        size, length = _TYPICAL_DISTURBANCE[what]
        if self.magnitude == 0:
            raise UserError(f"{magnitude} is 0: a {what} of size 0 disturbs nothing, so any controller would stay up and the run "
                            f"would test nothing; give a magnitude such as {size}")
        if self.duration == 0:
            raise UserError(f"{duration} is 0 s: a {what} of length 0 disturbs nothing, so the run would test nothing; "
                            f"give a duration such as {length}")


#: Typical sizes and lengths of the pendulum's poke and the seesaw's tap (for the messages that refuse a 0).
_TYPICAL_DISTURBANCE = {
    "poke": ("50 rad/s^2 (the default) or 220 (the lab's)", "0.005 s (the default)"),
    "tap": ("3.3 rad/s^2 (the default: about 5 degrees of tilt)", "0.1 s (the default)"),
}


@dataclass(frozen=True)
class Timing:
    """When the run ends, its control period, the discretization and the transport delay.

    Parameters
    ----------
    stop_time : float
        Simulated time in s (default 5).
    step : float
        Control period in s, the co-simulation's macro step (default 0.001; at most 0.1).
    method : {"tustin", "zoh"}
        Discretization of the controller (default Tustin).
    delay : int
        Transport delay before the plant in control periods, as on the rig (default 0).

    Examples
    --------
    >>> Timing(stop_time=10.0, delay=2).validate()
    >>> Timing(step=0.5).validate()
    Traceback (most recent call last):
        ...
    pendulab.errors.UserError: --step 0.5 must be within (0, 0.1] s; the lab runs at 0.001
    """

    stop_time: float = 5.0
    step: float = 1e-3
    method: str = _choice(*METHODS, default="tustin")
    delay: int = 0

    def validate(self) -> None:
        """Check this section's own rules (UserError with the command line's message)."""
        if not (isinstance(self.stop_time, (int, float)) and self.stop_time > 0 and math.isfinite(self.stop_time)):
            raise UserError(f"--stop-time {self.stop_time} must be a positive number of seconds")
        if not (0 < self.step <= MAX_STEP):
            raise UserError(f"--step {self.step} must be within (0, {MAX_STEP:g}] s; the lab runs at 0.001")
        if self.stop_time / self.step > MAX_STEPS:
            # The log is held in memory (9 signals per step): refuse before allocating it.
            raise UserError(
                f"--stop-time {self.stop_time:g} s at --step {self.step:g} s is {self.stop_time / self.step:.3g} steps; "
                f"a run has at most {MAX_STEPS:,}: shorten the run or lengthen the step"
            )
        from pendulab.hil.protocol import MAX_DELAY

        if isinstance(self.delay, bool) or not isinstance(self.delay, int) or not 0 <= self.delay <= MAX_DELAY:
            raise UserError(f"--delay {self.delay} must be a whole number of control periods from 0 to {MAX_DELAY} (give the N that 'pendulab lab' measured on the rig: its timing.json, delay_periods)")


@dataclass(frozen=True)
class Quantization:
    """The encoders: quantized (default) or ideal.

    Parameters
    ----------
    enabled : bool
        ``False``: ideal encoders (both steps 0).
    q_alpha, q_x : float, optional
        Encoder steps (rad, m) instead of the preset's (e.g. ``2*pi/4096`` for the real IP02).

    Examples
    --------
    >>> import math
    >>> RunSpec(quantization=Quantization(q_alpha=2 * math.pi / 4096)).parameters().q_alpha
    0.0015339807878856412
    """

    enabled: bool = True
    q_alpha: float | None = None
    q_x: float | None = None

    def validate(self) -> None:
        """Check this section's own rules (UserError with the command line's message)."""
        for name in ("q_alpha", "q_x"):
            step = getattr(self, name)
            if step is not None and not (math.isfinite(step) and step >= 0):
                raise UserError(f"quantization.{name} {step} must be a step >= 0 (0: ideal encoder)")


@dataclass(frozen=True)
class Supervisor:
    """The safety supervisor's settings; ``None`` keeps the Supervisor FMU's default.

    Parameters
    ----------
    alpha_max : float, optional
        Angle limit in rad (10 to 15 degrees; default 15 degrees).
    x_max : float, optional
        Track limit in m (default 0.40).
    recentre : bool
        Re-centring (the old lab's "kickback"): a slow outer loop on the cart position acts through the
        controller's reference r before the cart nears the track limit (default off: r = 0, as in the
        old lab's runs).
    swing_up : bool
        Swing the pendulum up from hanging (energy law) and hand it to the controller inside the catch
        window (default off).
    rig_mode : bool, optional
        The angle input is the rig's encoder (0 hanging down); engage inside the capture window.
    auto_start : bool, optional
        Start at initialization (simulation, default) or wait for the start command (lab).

    Examples
    --------
    >>> RunSpec(supervisor=Supervisor(x_max=0.35, recentre=True)).supervisor_parameters()
    {'x_max': 0.35, 'recentre': True}
    """

    alpha_max: float | None = None
    x_max: float | None = None
    recentre: bool = False
    swing_up: bool = False
    rig_mode: bool | None = None
    auto_start: bool | None = None

    def validate(self) -> None:
        """Check this section's own rules (UserError with the command line's message)."""
        if self.alpha_max is not None:
            from pendulab.fmu.models.supervisor.config import ALPHA_MAX_RANGE_DEG, ALPHA_MAX_SLACK

            lo, hi = (math.radians(d) for d in ALPHA_MAX_RANGE_DEG)
            if not lo - ALPHA_MAX_SLACK <= self.alpha_max <= hi + ALPHA_MAX_SLACK:
                raise UserError(f"supervisor.alpha_max {self.alpha_max:g} rad must be {ALPHA_MAX_RANGE_DEG[0]:g} to {ALPHA_MAX_RANGE_DEG[1]:g} degrees")
        if self.x_max is not None and not (math.isfinite(self.x_max) and self.x_max > 0):
            raise UserError(f"supervisor.x_max {self.x_max} must be a positive distance in m")
        for name in ("recentre", "swing_up"):
            if not isinstance(getattr(self, name), bool):
                raise UserError(f"supervisor.{name} {getattr(self, name)!r} must be true or false")


#: The sections of a RunSpec, by field name.
SECTIONS: dict[str, type] = {
    "plant": Plant,
    "controller": ControllerSpec,
    "poke": Poke,
    "timing": Timing,
    "quantization": Quantization,
    "supervisor": Supervisor,
}


# ------------------------------------------------------------------------------------------ the spec
@dataclass(frozen=True)
class RunSpec:
    """Everything one simulated run needs; build it, :meth:`validate` it, :func:`pendulab.simulate` it.

    Parameters
    ----------
    controller : ControllerSpec, Controller or control.TransferFunction
        A controller is wrapped into a :class:`ControllerSpec`.
    plant, poke, timing, quantization, supervisor
        The sections (see their classes); each defaults to the lab's defaults.

    Examples
    --------
    >>> from pendulab.control import Controller
    >>> spec = RunSpec(Controller.pid(40, 5, 4), plant=Plant(pendulum="short"))
    >>> spec.to_dict()["plant"]
    {'kind': 'pendulum', 'pendulum': 'short', 'cart': 'ip02', 'calibration': None, 'overrides': {}, 'start': 'upright'}
    >>> spec.parameters().Lp
    0.3365
    """

    controller: ControllerSpec = field(default_factory=ControllerSpec)
    plant: Plant = field(default_factory=Plant)
    poke: Poke = field(default_factory=Poke)
    timing: Timing = field(default_factory=Timing)
    quantization: Quantization = field(default_factory=Quantization)
    supervisor: Supervisor = field(default_factory=Supervisor)

    def __post_init__(self) -> None:
        controller = self.controller
        if controller is None:
            controller = ControllerSpec()
        elif not isinstance(controller, ControllerSpec):
            controller = ControllerSpec(transfer_function=_as_controller(controller))
        elif controller.transfer_function is not None:
            controller = dataclasses.replace(controller, transfer_function=_as_controller(controller.transfer_function))
        if controller.state_feedback is not None and isinstance(controller.state_feedback, Mapping):
            from pendulab.control.state_feedback import design_from_table

            controller = dataclasses.replace(controller, state_feedback=design_from_table(controller.state_feedback, "controller.state_feedback"))
        object.__setattr__(self, "controller", controller)
        for name, cls in SECTIONS.items():
            value = getattr(self, name)
            if not isinstance(value, cls):
                raise UserError(f"RunSpec {name} must be a {cls.__name__}, got {type(value).__name__}")
            for f in fields(value):
                if f.metadata.get("mapping"):
                    object.__setattr__(value, f.name, _frozen_mapping(getattr(value, f.name), f"{name}.{f.name}"))

    # ------------------------------------------------------------------ checks
    def validate(self) -> "RunSpec":
        """Check every rule of a run; the first broken one raises :class:`~pendulab.errors.UserError`.

        The messages are the command line's (they name its options). Returns the spec itself.
        """
        for name in ("timing", "poke", "quantization", "supervisor", "controller", "plant"):  # files last
            section = getattr(self, name)
            _check_choices(section, name)
            section.validate()
        t = self.timing
        p = self.poke
        if p.start >= t.stop_time:
            # Checked before simulating: the metrics are measured from the poke on.
            raise UserError(
                f"the poke starts at t={p.start:g} s, not before the stop time {t.stop_time:g} s; start the poke earlier or lengthen --stop-time"
            )
        c = self.controller
        if sum(x is not None for x in (c.transfer_function, c.fmu, c.state_feedback)) != 1:
            raise UserError("a run needs one controller: a transfer function (kernel and compensators), a state feedback or a controller block FMU")
        if self.plant.kind == "seesaw" and c.state_feedback is None:
            raise UserError("the seesaw runs a state feedback: design one with 'pendulab lqr --plant seesaw --out FILE' "
                            "and give it with --controller FILE (or --demo)")
        if c.state_feedback is not None and c.state_feedback.plant != self.plant.kind:
            raise UserError(f"the controller is a state feedback for the {c.state_feedback.plant}, but the run's plant is the "
                            f"{self.plant.kind}; design one for the {self.plant.kind} with 'pendulab lqr --plant {self.plant.kind}'")
        if c.fmu is not None and not Path(c.fmu).is_file():
            raise UserError(f"controller FMU {c.fmu} does not exist; build it with pendulab.blocks.build_block")
        if self.plant.start == "hanging" and not self.supervisor.swing_up:
            raise UserError("the pendulum starts hanging but nothing swings it up: add --swing-up (or start it upright)")
        return self

    # ------------------------------------------------------------------ derived values
    def parameters(self) -> Any:
        """The plant's :class:`~pendulab.model.parameters.PlantParameters` for this run.

        :meth:`Plant.parameters` (preset, calibration file, overrides), then the poke and the quantization.
        """
        params = self.plant.parameters()
        if self.plant.kind == "seesaw":
            return self._seesaw_run_parameters(params)
        params = params.with_values(poke_magnitude=self.poke.magnitude, poke_duration=self.poke.duration, poke_start=self.poke.start)
        q = self.quantization
        if not q.enabled:
            params = params.with_values(q_alpha=0.0, q_x=0.0)
        else:
            steps = {k: v for k, v in (("q_alpha", q.q_alpha), ("q_x", q.q_x)) if v is not None}
            if steps:
                params = params.with_values(**steps)
        return params

    def _seesaw_run_parameters(self, params: Any) -> Any:
        """The seesaw's parameters for this run: the poke as the tap, the quantization (``q_alpha`` is the
        tilt encoder's step)."""
        params = params.with_values(tap_magnitude=self.poke.magnitude, tap_duration=self.poke.duration, tap_start=self.poke.start)
        q = self.quantization
        if not q.enabled:
            return params.with_values(q_theta=0.0, q_x=0.0)
        steps = {k: v for k, v in (("q_theta", q.q_alpha), ("q_x", q.q_x)) if v is not None}
        return params.with_values(**steps) if steps else params

    def supervisor_parameters(self) -> dict[str, Any]:
        """Start values for the Supervisor FMU: the settings that differ from their field's default (``None``:
        the FMU's own default; a mode only when it is on), by their FMU names.

        A field is the Supervisor FMU's parameter of the same name, unless its metadata says
        ``{"fmu": False}`` (a setting the master acts on instead).
        """
        s = self.supervisor
        return {f.name: getattr(s, f.name) for f in fields(s)
                if getattr(s, f.name) is not None and getattr(s, f.name) != f.default and f.metadata.get("fmu", True)}

    def initial_state(self) -> dict[str, float]:
        """The plant's start values for the pendulum's pose at t = 0 (``plant.start``)."""
        return {"alpha": math.pi} if self.plant.start == "hanging" else {}

    def describe_controller(self) -> str:
        """The controller as the run's files name it."""
        c = self.controller
        if c.label is not None:
            return c.label
        if c.fmu is not None:
            return f"Python block {Path(c.fmu).name}"
        if c.state_feedback is not None:
            return c.state_feedback.describe()
        describe = getattr(c.transfer_function, "describe", None)
        return describe() if callable(describe) else str(c.transfer_function)

    # ------------------------------------------------------------------ construction
    def replace(self, **sections: Any) -> "RunSpec":
        """A copy with whole sections replaced (``spec.replace(poke=Poke(220.0))``)."""
        return dataclasses.replace(self, **sections)

    @classmethod
    def for_parameters(cls, controller: Any, params: Any, **sections: Any) -> "RunSpec":
        """A spec whose plant is exactly ``params`` (a :class:`PlantParameters`), its poke included."""
        poke = Poke(params.poke_magnitude, params.poke_duration, params.poke_start)
        return cls(controller, plant=Plant(overrides=params.as_dict()), poke=poke, **sections)

    # ------------------------------------------------------------------ serialization
    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON types): one table per section; ``None`` where a setting is not given."""
        out: dict[str, Any] = {}
        for name in SECTIONS:
            section = getattr(self, name)
            table: dict[str, Any] = {}
            for f in fields(section):
                value = getattr(section, f.name)
                if f.metadata.get("mapping"):
                    value = dict(value)
                elif name == "controller" and f.name == "transfer_function":
                    value = value.to_dict() if value is not None else None
                elif name == "controller" and f.name == "state_feedback":
                    value = value.to_dict()["state_feedback"] if value is not None else None
                table[f.name] = value
            out[name] = table
        return out

    @classmethod
    def from_dict(cls, data: Any, *, source: str = "run description") -> "RunSpec":
        """From :meth:`to_dict`'s shape; missing keys take their defaults, unknown keys are an error."""
        if not isinstance(data, Mapping):
            raise UserError(f"{source} must be a table of sections ({', '.join(SECTIONS)}), got {type(data).__name__}")
        unknown = [k for k in data if k not in SECTIONS]
        if unknown:
            raise UserError(f"{source}: unknown section {unknown[0]!r}; the sections are {', '.join(SECTIONS)}")
        sections = {name: _section_from_dict(SECTIONS[name], data[name], f"{source}: {name}") for name in data}
        return cls(**sections)

    def to_json(self) -> str:
        """JSON text of :meth:`to_dict`."""
        return json.dumps(self.to_dict(), indent=2) + "\n"

    @classmethod
    def from_json(cls, text: str, *, source: str = "run description") -> "RunSpec":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise UserError(f"{source} is not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}; fix the syntax") from None
        return cls.from_dict(data, source=source)

    def to_toml(self) -> str:
        """TOML text of :meth:`to_dict` (settings not given are left out)."""
        return _toml(self.to_dict())

    @classmethod
    def from_toml(cls, text: str, *, source: str = "run description") -> "RunSpec":
        if sys.version_info >= (3, 11):
            import tomllib
        else:  # pragma: no cover
            import tomli as tomllib
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise UserError(f"{source} is not valid TOML: {' '.join(str(exc).split())}; fix the syntax") from None
        return cls.from_dict(data, source=source)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> "RunSpec":
        """Read a run description file (``.toml`` or ``.json``)."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise UserError(f"run description {path} cannot be read ({getattr(exc, 'strerror', None) or exc}); check the path") from None
        reader = cls.from_toml if path.suffix.lower() == ".toml" else cls.from_json
        return reader(text, source=f"run description {path}")


# ------------------------------------------------------------------------------------------ helpers
def _check_choices(section: Any, name: str) -> None:
    for f in fields(section):
        choices = f.metadata.get("choices")
        if choices and getattr(section, f.name) not in choices:
            raise UserError(f"{name}.{f.name} {getattr(section, f.name)!r}: choose {' or '.join(choices)}")


def _as_controller(value: Any) -> Any:
    from pendulab.control.controller import Controller

    if isinstance(value, Controller):
        return value
    if isinstance(value, Mapping):
        return Controller.from_dict(value)
    if hasattr(value, "num") and hasattr(value, "den"):  # control.TransferFunction
        return Controller.from_transfer_function(value)
    raise UserError(f"a controller is a pendulab Controller, a control.TransferFunction or a controller table, got {type(value).__name__}")


def _type_names(annotation: str) -> tuple[set[str], bool]:
    parts = {p.strip() for p in str(annotation).split("|")}
    optional = "None" in parts
    return parts - {"None"}, optional


def _coerce(value: Any, f: dataclasses.Field, where: str) -> Any:
    """A value read from a file, checked against the field's annotation."""
    if f.metadata.get("mapping"):
        return _frozen_mapping(value, where)
    kinds, optional = _type_names(f.type)
    if value is None:
        if optional or "Any" in kinds:
            return None
        raise UserError(f"{where} must be given (no null)")
    if "Any" in kinds:
        return value
    if "bool" in kinds:
        if isinstance(value, bool):
            return value
        raise UserError(f"{where} must be true or false, got {value!r}")
    if "int" in kinds:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
        raise UserError(f"{where} must be a whole number, got {value!r}")
    if "float" in kinds:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise UserError(f"{where} must be a number, got {value!r}")
    if "str" in kinds:
        if isinstance(value, str):
            return value
        raise UserError(f"{where} must be text, got {value!r}")
    return value


def _section_from_dict(cls: type, data: Any, where: str) -> Any:
    if not isinstance(data, Mapping):
        raise UserError(f"{where} must be a table, got {type(data).__name__}")
    known = {f.name: f for f in fields(cls)}
    unknown = [k for k in data if k not in known]
    if unknown:
        raise UserError(f"{where}: unknown key {unknown[0]!r}; known keys are {', '.join(known)}")
    values = {name: _coerce(value, known[name], f"{where}.{name}") for name, value in data.items()}
    return cls(**values)


def _toml_scalar(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value) if math.isfinite(value) else ("nan" if math.isnan(value) else ("inf" if value > 0 else "-inf"))
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_scalar(v) for v in value) + "]"
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{json.dumps(str(k))} = {_toml_scalar(v)}" for k, v in value.items() if v is not None) + "}"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def _toml(data: Mapping[str, Any]) -> str:
    lines: list[str] = []
    for name, table in data.items():
        lines.append(f"[{name}]")
        for key, value in table.items():
            if value is not None:
                lines.append(f"{key} = {_toml_scalar(value)}")
        lines.append("")
    return "\n".join(lines)


__all__ = ["ControllerSpec", "Plant", "Poke", "Quantization", "RunSpec", "Supervisor", "Timing", "POKE_DEFAULT", "MAX_STEPS"]
