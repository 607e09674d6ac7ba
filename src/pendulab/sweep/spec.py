"""The sweep spec: a base run, grid axes over the controller, distributions over the plant.

A sweep runs every point of a grid of controllers on the same random samples of plausible rigs
(common random numbers: sample ``s`` is the same rig for every controller point). It is written as
TOML::

    [run]                       # the base run: every run starts from it
    pendulum = "long"           # long | short
    cart = "ip02"               # ip02 | ip02-weight | ip01
    stop_time = 5               # s
    poke = [220, 0.005, 1]      # magnitude rad/s^2, duration s, start s
    delay = 0                   # control periods before the plant (the rig: 1..3)
    # step = 0.001, method = "tustin", quantization = true, calibration = "cal.json"

    [controller.pid]            # Kp + Ki/(s + 1/Ti) + Kd wf s/(s + wf); a list is a grid axis
    kp = [600, 750, 1200]
    ki = [6, 20, 200]
    kd = [5, 10, 20]

    [uncertainty]               # per-run random draws, the same for every controller point
    samples = 50
    seed = 1
    F1 = { uniform = [1.0, 2.0] }
    Beq = { normal = [4.3, 0.4] }
    delay = { choice = [1, 2, 3] }

Instead of ``[controller.pid]`` a zeros/poles/gain controller is ``[controller]`` with ``demo = true``,
``file = "ctl.toml"`` or the tables of a controller file (``kernel``, ``compensators``); its grid axes
are in ``[grid]``, keyed by the number they vary: ``"kernel.gain"``, ``"kernel.zeros.0"``,
``"compensators.1.poles.0"`` (indices from 0; a complex root is varied with its conjugate).

Distributions: ``uniform = [low, high]``, ``normal = [mean, sd]``, ``loguniform = [low, high]``
(``0 < low``), ``choice = [v1, v2, ...]``, or a fixed value. A parameter is any plant parameter
(``pendulab.model.parameters.PlantParameters``) or ``delay``. ``spread = true`` draws the friction
vector (and ``Beq``) from the calibration's spread: normal about the calibrated value with the spread
the calibration file records (``metadata.spread`` of ``pendulab calibrate``, ``metadata.uncertainty``
of ``pendulab fit``). Each parameter has its own random stream (seeded by ``seed`` and its name), so
adding a parameter leaves the others' draws unchanged.

``[sweep]`` holds ``timeout`` (s per run, default 60), ``batch`` (runs per task; default: about
a second of work) and ``save_every`` (s, default 5: finished runs are written to disk at least this
often, so a kill loses at most that much work; 0: after every batch).

Every mistake is one :class:`SpecError` line naming the key.

Examples
--------
>>> spec = parse_sweep_spec('''
... [run]
... stop_time = 3
... [controller.pid]
... kp = [600, 750]
... ki = 20
... kd = 10
... [uncertainty]
... samples = 3
... F1 = { uniform = [1.0, 2.0] }
... ''')
>>> spec.n_points, spec.n_samples, spec.n_runs
(2, 3, 6)
>>> all(1.0 <= s["F1"] <= 2.0 for s in spec.draws())
True
>>> spec.run_spec(next(runs_of(spec))[3]).timing.stop_time
3.0
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import itertools
import json
import math
import sys
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

import numpy as np

from pendulab.errors import UserError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


class SpecError(UserError):
    """A sweep spec that cannot be run; the message names the key."""


#: Keys of ``[run]`` and their defaults.
RUN_DEFAULTS: dict[str, Any] = {
    "pendulum": "long",
    "cart": "ip02",
    "calibration": None,
    "stop_time": 5.0,
    "step": 1e-3,
    "method": "tustin",
    "delay": 0,
    "poke": [50.0, 0.005, 1.0],
    "quantization": True,
    "supervisor": {},
    "start": "upright",
}
PID_KEYS = ("kp", "ki", "kd", "wf", "Ti")
PID_DEFAULTS = {"kp": 0.0, "ki": 0.0, "kd": 0.0, "wf": 62.8, "Ti": 0.628}
DISTRIBUTIONS = ("uniform", "normal", "loguniform", "choice")
SWEEP_DEFAULTS = {"timeout": 60.0, "batch": 0, "save_every": 5.0}
#: The parameters the friction spread of a calibration covers.
SPREAD_NAMES = ("F1", "v1", "F2", "v2", "B", "Beq")


# ------------------------------------------------------------------------------------- distributions
@dataclass(frozen=True)
class Distribution:
    """One parameter's distribution: ``kind`` in :data:`DISTRIBUTIONS` or ``"fixed"``, and its numbers."""

    kind: str
    values: tuple[float, ...]

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        if self.kind == "uniform":
            return rng.uniform(self.values[0], self.values[1], n)
        if self.kind == "normal":
            return rng.normal(self.values[0], self.values[1], n)
        if self.kind == "loguniform":
            return np.exp(rng.uniform(math.log(self.values[0]), math.log(self.values[1]), n))
        if self.kind == "choice":
            return np.asarray(self.values)[rng.integers(0, len(self.values), n)]
        return np.full(n, self.values[0])

    def support(self) -> tuple[float, ...]:
        """The values a ``choice`` or ``fixed`` draw can take (empty for a continuous one)."""
        return self.values if self.kind in ("choice", "fixed") else ()


def _stream(seed: int, name: str) -> np.random.Generator:
    """The random stream of one parameter: seeded by the sweep's seed and the parameter's name."""
    return np.random.default_rng([seed, zlib.crc32(name.encode())])


# ------------------------------------------------------------------------------------- the spec
@dataclass(frozen=True)
class Axis:
    """A grid axis: the name of the number it varies and its values."""

    name: str
    values: tuple[float, ...]


@dataclass(frozen=True)
class SweepSpec:
    """A parsed, validated sweep (see the module docstring for the TOML form).

    Attributes
    ----------
    run : dict
        The base run's settings (:data:`RUN_DEFAULTS` keys).
    controller : dict
        ``{"pid": {...}}`` (numbers, the axes' first values in place) or a controller file's tables.
    axes : tuple of Axis
        Grid axes, in the order given; every combination is a point.
    uncertainty : dict of name -> Distribution
    samples, seed : int
        Draws per point (0: one nominal run per point) and the seed.
    """

    run: dict[str, Any]
    controller: dict[str, Any]
    axes: tuple[Axis, ...] = ()
    uncertainty: dict[str, Distribution] = field(default_factory=dict)
    samples: int = 0
    seed: int = 0
    timeout: float = 60.0
    batch: int = 0
    save_every: float = 5.0
    source: str = "sweep spec"

    # ---------------------------------------------------------------- sizes
    @property
    def n_points(self) -> int:
        return math.prod(len(a.values) for a in self.axes)

    @property
    def n_samples(self) -> int:
        return max(1, self.samples)

    @property
    def n_runs(self) -> int:
        return self.n_points * self.n_samples

    @property
    def input_names(self) -> tuple[str, ...]:
        """The inputs that vary, in column order: the grid axes, then the uncertain parameters."""
        return tuple(a.name for a in self.axes) + tuple(self.uncertainty)

    def digest(self) -> str:
        """A hash of everything that decides the runs (a resumed sweep must have the same)."""
        return self._digest

    @functools.cached_property
    def _digest(self) -> str:
        data = {k: v for k, v in dataclasses.asdict(self).items() if k not in ("source", "batch", "save_every")}
        return hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()[:16]

    # ---------------------------------------------------------------- points and samples
    def to_toml(self) -> str:
        """The spec as TOML text that parses back to the same sweep (same :meth:`digest`).

        Examples
        --------
        >>> spec = parse_sweep_spec('[controller.pid]\\nkp = [600, 750]\\nki = 6\\nkd = 5\\n[uncertainty]\\nsamples = 2\\nF1 = 1.5')
        >>> parse_sweep_spec(spec.to_toml()).digest() == spec.digest()
        True
        """
        run = {k: v for k, v in self.run.items() if not k.startswith("_") and v is not None and v != {}}
        lines = ["[run]", *(f"{k} = {_toml(v)}" for k, v in run.items()), ""]
        axes = {a.name: list(a.values) for a in self.axes}
        if "pid" in self.controller:
            pid = {k: axes.get(k, v) for k, v in self.controller["pid"].items()}
            lines += ["[controller.pid]", *(f"{k} = {_toml(v)}" for k, v in pid.items()), ""]
        else:
            lines += ["[controller]", f"kernel = {_toml(self.controller['kernel'])}",
                      f"compensators = {_toml(self.controller['compensators'])}", ""]
            if axes:
                lines += ["[grid]", *(f"{json.dumps(k)} = {_toml(v)}" for k, v in axes.items()), ""]
        if self.samples:
            lines += ["[uncertainty]", f"samples = {self.samples}", f"seed = {self.seed}"]
            for name, dist in self.uncertainty.items():
                value = dist.values[0] if dist.kind == "fixed" else {dist.kind: list(dist.values)}
                lines.append(f"{name} = {_toml(value)}")
            lines.append("")
        lines += ["[sweep]", f"timeout = {self.timeout!r}", f"batch = {self.batch}", f"save_every = {self.save_every!r}", ""]
        return "\n".join(lines)

    def points(self) -> list[dict[str, float]]:
        """Every grid point (``{axis name: value}``), the last axis varying fastest."""
        return [dict(zip((a.name for a in self.axes), combo)) for combo in itertools.product(*(a.values for a in self.axes))]

    def draws_table(self) -> dict[str, np.ndarray]:
        """The drawn values of every uncertain parameter (arrays of :attr:`n_samples`)."""
        return {name: dist.draw(_stream(self.seed, name), self.n_samples) for name, dist in self.uncertainty.items()}

    def draws(self) -> list[dict[str, float]]:
        """The plant samples (``{parameter: value}``), the same for every grid point."""
        table = self.draws_table()
        return [{name: _plain(values[s], name) for name, values in table.items()} for s in range(self.n_samples)]

    def run_spec(self, inputs: Mapping[str, Any] | None = None) -> Any:
        """The :class:`~pendulab.spec.RunSpec` of the run with these inputs (grid values and draws).

        Without inputs: the base run at the grid's first point. The calibration's values are part of
        the plant's overrides (a Dask worker on another machine has no calibration file).
        """
        from pendulab.model.parameters import PlantParameters
        from pendulab.spec import Plant, Poke, Quantization, RunSpec, Supervisor, Timing

        run = self.run
        inputs = dict(inputs or {})
        point = {a.name: inputs.get(a.name, a.values[0]) for a in self.axes}
        names = set(PlantParameters.names())
        poke = dict(zip(("magnitude", "duration", "start"), run["poke"]))
        poke.update({k[len("poke_"):]: float(v) for k, v in inputs.items() if k.startswith("poke_")})
        overrides = {**run.get("_calibration_values", {}), **{k: float(v) for k, v in inputs.items() if k in names and not k.startswith("poke_")}}
        return RunSpec(
            self.controller_at(point),
            plant=Plant(pendulum=run["pendulum"], cart=run["cart"], overrides=overrides, start=run["start"]),
            poke=Poke(**poke),
            timing=Timing(stop_time=run["stop_time"], step=run["step"], method=run["method"], delay=int(inputs.get("delay", run["delay"]))),
            quantization=Quantization(enabled=run["quantization"]),
            supervisor=Supervisor(**run["supervisor"]),
        )

    def controller_at(self, point: Mapping[str, float]) -> Any:
        """The :class:`~pendulab.control.controller.Controller` of one grid point (built once per point: a
        point's runs come one after another, and a Controller is immutable)."""
        from pendulab.control.controller import Controller

        key = tuple(point.items())
        cache = self.__dict__.setdefault("_controllers", {})
        if key in cache:
            return cache[key]
        if len(cache) > 64:
            cache.clear()
        if "pid" in self.controller:
            controller = Controller.pid(**{**self.controller["pid"], **point})
        else:
            data = json.loads(json.dumps(self.controller))
            for name, value in point.items():
                _set_number(data, name, value)
            controller = Controller.from_dict(data)
        cache[key] = controller
        return controller

    def __getstate__(self) -> dict[str, Any]:
        # What a worker receives: the spec, not the controllers this process built.
        return {k: v for k, v in self.__dict__.items() if k != "_controllers"}


def _toml(value: Any) -> str:
    """One TOML value (numbers, strings, booleans, lists, inline tables)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, Mapping):
        return "{ " + ", ".join(f"{json.dumps(str(k))} = {_toml(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def _plain(value: Any, name: str) -> float | int:
    return int(value) if name == "delay" else float(value)


def _set_number(data: dict[str, Any], path: str, value: float) -> None:
    """Set the number at ``kernel.zeros.0`` (and the conjugate of a complex root) in controller tables."""
    parts = path.split(".")
    target: Any = data
    for part in parts[:-1]:
        target = target[int(part)] if isinstance(target, list) else target[part]
    last = parts[-1]
    if isinstance(target, list):
        index = int(last)
        old = target[index]
        if isinstance(old, list):  # a complex root [re, im]: vary its real part, with its conjugate
            for k, other in enumerate(target):
                if isinstance(other, list) and other[0] == old[0] and other[1] == -old[1]:
                    target[k] = [value, other[1]]
            target[index] = [value, old[1]]
        else:
            target[index] = value
    else:
        target[last] = value


# ------------------------------------------------------------------------------------- parsing
def load_sweep_spec(path: str | Path) -> SweepSpec:
    """Read and validate a sweep spec file (TOML). Every problem is one :class:`SpecError` line."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SpecError(f"sweep spec {path} does not exist; check the path") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(f"sweep spec {path} cannot be read: {getattr(exc, 'strerror', None) or exc}") from None
    return parse_sweep_spec(text, source=str(path), base_dir=path.parent)


def parse_sweep_spec(text: str, *, source: str = "sweep spec", base_dir: Path | None = None) -> SweepSpec:
    """Parse and validate the TOML text of a sweep spec (see the module docstring)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{source} is not valid TOML: {' '.join(str(exc).split())}; fix the syntax") from None
    return sweep_spec_from_dict(data, source=source, base_dir=base_dir)


def sweep_spec_from_dict(data: Mapping[str, Any], *, source: str = "sweep spec", base_dir: Path | None = None) -> SweepSpec:
    """Validate a sweep spec given as decoded TOML (a dict of sections), e.g. one a program builds."""
    return _Parser(source, base_dir or Path(".")).spec(dict(data))


class _Parser:
    def __init__(self, source: str, base_dir: Path) -> None:
        self.source = source
        self.base_dir = base_dir

    def fail(self, key: str, message: str) -> SpecError:
        return SpecError(f"{self.source}: {key}: {message}")

    def table(self, data: Mapping[str, Any], key: str) -> dict[str, Any]:
        value = data.get(key, {})
        if not isinstance(value, dict):
            raise self.fail(key, f"must be a table [{key}], got {value!r}")
        return value

    def number(self, key: str, value: Any, *, integer: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.fail(key, f"{value!r} is not a finite number")
        if integer and value != int(value):
            raise self.fail(key, f"{value!r} is not a whole number")
        return int(value) if integer else float(value)

    # ---------------------------------------------------------------- sections
    def spec(self, data: dict[str, Any]) -> SweepSpec:
        unknown = sorted(set(data) - {"run", "controller", "grid", "uncertainty", "sweep"})
        if unknown:
            raise self.fail(unknown[0], "unknown section; the sections are [run], [controller], [grid], [uncertainty], [sweep]")
        run = self.run(self.table(data, "run"))
        controller, axes = self.controller(self.table(data, "controller"), self.table(data, "grid"))
        uncertainty, samples, seed = self.uncertainty(self.table(data, "uncertainty"), run)
        options = self.table(data, "sweep")
        for key in options:
            if key not in SWEEP_DEFAULTS:
                raise self.fail(f"sweep.{key}", f"unknown key; the keys are {', '.join(SWEEP_DEFAULTS)}")
        timeout = self.number("sweep.timeout", options.get("timeout", SWEEP_DEFAULTS["timeout"]))
        if timeout <= 0:
            raise self.fail("sweep.timeout", f"{timeout:g} s must be > 0")
        batch = self.number("sweep.batch", options.get("batch", 0), integer=True)
        if batch < 0:
            raise self.fail("sweep.batch", f"{batch} must be >= 0 (0: about a second of work per task)")
        save_every = self.number("sweep.save_every", options.get("save_every", SWEEP_DEFAULTS["save_every"]))
        if save_every < 0:
            raise self.fail("sweep.save_every", f"{save_every:g} s must be >= 0 (0: after every batch)")
        spec = SweepSpec(run, controller, tuple(axes), uncertainty, samples, seed, timeout, int(batch), save_every, self.source)
        self.check_controllers(spec)
        return spec

    def run(self, table: dict[str, Any]) -> dict[str, Any]:
        from pendulab.model.parameters import CARTS

        run = dict(RUN_DEFAULTS)
        for key, value in table.items():
            if key not in RUN_DEFAULTS:
                raise self.fail(f"run.{key}", f"unknown key; the keys are {', '.join(RUN_DEFAULTS)}")
            run[key] = value
        if run["pendulum"] not in ("long", "short"):
            raise self.fail("run.pendulum", f"{run['pendulum']!r}: choose long or short")
        if run["cart"] not in CARTS:
            raise self.fail("run.cart", f"{run['cart']!r}: choose one of {', '.join(CARTS)}")
        if run["method"] not in ("tustin", "zoh"):
            raise self.fail("run.method", f"{run['method']!r}: choose tustin or zoh")
        if not isinstance(run["quantization"], bool):
            raise self.fail("run.quantization", f"{run['quantization']!r}: give true or false")
        from pendulab.spec import Supervisor

        known = [f.name for f in dataclasses.fields(Supervisor)]
        if not isinstance(run["supervisor"], dict) or set(run["supervisor"]) - set(known):
            raise self.fail("run.supervisor", f"{run['supervisor']!r}: give a table of the supervisor's settings ({', '.join(known)})")
        if run["start"] not in ("upright", "hanging"):
            raise self.fail("run.start", f"{run['start']!r}: choose upright or hanging")
        run["stop_time"] = self.number("run.stop_time", run["stop_time"])
        run["step"] = self.number("run.step", run["step"])
        run["delay"] = self.number("run.delay", run["delay"], integer=True)
        poke = run["poke"]
        if not isinstance(poke, list) or len(poke) != 3:
            raise self.fail("run.poke", f"{poke!r} must be [magnitude, duration, start]")
        run["poke"] = [self.number("run.poke", v) for v in poke]
        if run["poke"][1] < 0 or run["poke"][2] < 0:
            raise self.fail("run.poke", "the duration and start must be >= 0")
        if run["calibration"] is not None:
            if not isinstance(run["calibration"], str):
                raise self.fail("run.calibration", f"{run['calibration']!r} must be the path of a calibration file")
            path = Path(run["calibration"])
            path = path if path.is_absolute() else self.base_dir / path
            from pendulab.calibration.files import load_calibration

            try:
                calibration = load_calibration(path)
            except UserError as exc:
                raise self.fail("run.calibration", str(exc)) from None
            run["calibration"] = str(path)
            run["_calibration_values"] = calibration.values
            run["_calibration_spread"] = calibration_spread(calibration.metadata)
        return run

    def axis(self, key: str, value: Any) -> Axis | None:
        """A list is a grid axis; a number is a fixed value (None)."""
        if not isinstance(value, list):
            return None
        if not value:
            raise self.fail(key, "an empty list: a grid axis needs at least one value")
        values = tuple(self.number(key, v) for v in value)
        if len(set(values)) != len(values):
            raise self.fail(key, f"{list(values)} repeats a value; give each value once")
        return Axis(key, values)

    def controller(self, table: dict[str, Any], grid: dict[str, Any]) -> tuple[dict[str, Any], list[Axis]]:
        axes: list[Axis] = []
        if "pid" in table:
            if set(table) != {"pid"}:
                raise self.fail("controller", "give either [controller.pid] or a zeros/poles/gain controller, not both")
            if grid:
                raise self.fail("grid", "the PID's axes are lists in [controller.pid]; [grid] is for a zeros/poles/gain controller")
            pid = self.table(table, "pid")
            fixed: dict[str, float] = {}
            for key, value in pid.items():
                if key not in PID_KEYS:
                    raise self.fail(f"controller.pid.{key}", f"unknown key; the PID's keys are {', '.join(PID_KEYS)}")
                axis = self.axis(f"controller.pid.{key}", value)
                if axis is None:
                    fixed[key] = self.number(f"controller.pid.{key}", value)
                else:
                    axes.append(Axis(key, axis.values))
                    fixed[key] = axis.values[0]
            return {"pid": {**PID_DEFAULTS, **fixed}}, axes
        from pendulab.control.controller import demo_controller
        from pendulab.control.files import load_controller_file

        sources = [k for k in ("demo", "file", "kernel") if k in table]
        if len(sources) != 1:
            raise self.fail("controller", "give one controller: [controller.pid], demo = true, file = \"ctl.toml\" or a kernel table")
        try:
            if "demo" in table:
                if table["demo"] is not True or len(table) != 1:
                    raise self.fail("controller.demo", "write demo = true, alone in [controller]")
                controller = demo_controller()
            elif "file" in table:
                if not isinstance(table["file"], str) or len(table) != 1:
                    raise self.fail("controller.file", "write file = \"ctl.toml\", alone in [controller]")
                path = Path(table["file"])
                controller = load_controller_file(path if path.is_absolute() else self.base_dir / path)
            else:
                from pendulab.control.controller import Controller

                controller = Controller.from_dict(table)
        except SpecError:
            raise
        except UserError as exc:
            raise self.fail("controller", str(exc)) from None
        data = controller.to_dict()
        for key, value in grid.items():
            try:
                _check_path(data, key)
            except (KeyError, IndexError, ValueError, TypeError):
                raise self.fail(f"grid.{key}", "names no number of the controller; use kernel.gain, kernel.zeros.0, compensators.0.poles.0, ...") from None
            axis = self.axis(f"grid.{key}", value)
            if axis is None:
                raise self.fail(f"grid.{key}", f"{value!r} must be a list of values")
            axes.append(Axis(key, axis.values))
        return data, axes

    def check_controllers(self, spec: SweepSpec) -> None:
        """Every grid point's controller passes the entry rules (SPEC §4), the base run RunSpec's rules."""
        for point in spec.points():
            try:
                spec.controller_at(point)
            except UserError as exc:
                where = ", ".join(f"{k}={v:g}" for k, v in point.items())
                key = "controller.pid" if "pid" in spec.controller else "controller"
                raise self.fail(key, f"at {where or 'the base point'}: {exc}") from None
        try:
            spec.run_spec().validate()
        except UserError as exc:
            text = str(exc)
            for option, key in (("--stop-time", "stop_time"), ("--step", "step"), ("--delay", "delay"), ("--poke", "poke")):
                text = text.replace(option, key)
            raise self.fail("run", text) from None

    def uncertainty(self, table: dict[str, Any], run: dict[str, Any]) -> tuple[dict[str, Distribution], int, int]:
        from pendulab.hil.protocol import MAX_DELAY
        from pendulab.model.parameters import PlantParameters

        names = set(PlantParameters.names()) | {"delay"}
        samples = self.number("uncertainty.samples", table.get("samples", 0 if not table else 1), integer=True)
        if samples < 0 or (samples == 0 and set(table) - {"samples", "seed"}):
            raise self.fail("uncertainty.samples", f"{samples} must be >= 1 where parameters are drawn")
        seed = self.number("uncertainty.seed", table.get("seed", 0), integer=True)
        if seed < 0:
            raise self.fail("uncertainty.seed", f"{seed} must be >= 0")
        out: dict[str, Distribution] = {}
        spread = table.get("spread", False)
        if not isinstance(spread, bool):
            raise self.fail("uncertainty.spread", f"{spread!r}: give true to draw the friction from the calibration's spread")
        if spread:
            sigma = run.get("_calibration_spread") or {}
            if not sigma:
                raise self.fail("uncertainty.spread", "the calibration records no spread (give run.calibration = a file from 'pendulab calibrate' or 'pendulab fit')")
            values = run["_calibration_values"]
            out.update({n: Distribution("normal", (float(values.get(n, _nominal(run, n))), float(s))) for n, s in sigma.items()})
        for name, value in table.items():
            if name in ("samples", "seed", "spread"):
                continue
            key = f"uncertainty.{name}"
            if name not in names:
                raise self.fail(key, f"unknown parameter; give a plant parameter ({', '.join(sorted(names - {'delay'}))}) or delay")
            out[name] = self.distribution(key, value)
            if name == "delay":
                bad = [v for v in out[name].support() if v != int(v) or not 0 <= v <= MAX_DELAY]
                if bad:
                    raise self.fail(key, f"{bad[0]:g} is not a delay: give whole control periods from 0 to {MAX_DELAY}")
        return out, int(samples), int(seed)

    def distribution(self, key: str, value: Any) -> Distribution:
        if not isinstance(value, dict):
            return Distribution("fixed", (self.number(key, value),))
        if len(value) != 1 or next(iter(value)) not in DISTRIBUTIONS:
            raise self.fail(key, f"{value!r}: give one of {{ uniform = [low, high] }}, {{ normal = [mean, sd] }}, {{ loguniform = [low, high] }}, {{ choice = [...] }}")
        kind, numbers = next(iter(value.items()))
        if not isinstance(numbers, list) or not numbers:
            raise self.fail(f"{key}.{kind}", f"{numbers!r} must be a list of numbers")
        values = tuple(self.number(f"{key}.{kind}", v) for v in numbers)
        if kind != "choice":
            if len(values) != 2:
                raise self.fail(f"{key}.{kind}", f"{list(values)} must be two numbers")
            a, b = values
            if kind in ("uniform", "loguniform") and a > b:
                raise self.fail(f"{key}.{kind}", f"low {a:g} > high {b:g}; give [low, high]")
            if kind == "loguniform" and a <= 0:
                raise self.fail(f"{key}.{kind}", f"low {a:g} must be > 0 for a log-uniform draw")
            if kind == "normal" and b < 0:
                raise self.fail(f"{key}.{kind}", f"standard deviation {b:g} must be >= 0")
        return Distribution(kind, values)


def _check_path(data: Any, path: str) -> None:
    target = data
    for part in path.split("."):
        target = target[int(part)] if isinstance(target, list) else target[part]
    if isinstance(target, list) and len(target) == 2 and isinstance(target[0], (int, float)):
        return  # a complex root [re, im]
    if isinstance(target, bool) or not isinstance(target, (int, float)):
        raise ValueError(path)


def _nominal(run: Mapping[str, Any], name: str) -> float:
    from pendulab.model.parameters import PlantParameters

    return getattr(PlantParameters.preset(run["pendulum"], run["cart"]), name)


def calibration_spread(metadata: Mapping[str, Any]) -> dict[str, float]:
    """The standard spread a calibration file records per parameter (``spread`` or ``uncertainty``)."""
    for key in ("spread", "uncertainty"):
        table = metadata.get(key)
        if isinstance(table, Mapping):
            out = {n: float(v) for n, v in table.items() if n in SPREAD_NAMES and isinstance(v, (int, float)) and math.isfinite(v) and v > 0}
            if out:
                return out
    return {}


def runs_of(spec: SweepSpec, ids: Sequence[int] | None = None) -> Iterator[tuple[int, int, int, dict[str, Any]]]:
    """``(run_id, point index, sample index, varied inputs)`` of every run (or of ``ids``)."""
    points = spec.points()
    samples = spec.draws()
    for run_id in range(spec.n_runs) if ids is None else ids:
        g, s = divmod(run_id, spec.n_samples)
        yield run_id, g, s, {**points[g], **samples[s]}
