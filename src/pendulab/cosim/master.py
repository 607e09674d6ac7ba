"""The co-simulation master: fixed macro step, connections by name, a fast path for the step loop.

fmpy loads the FMUs and provides the FMI calls; in the loop the master calls the FMUs' C functions
through ctypes pointers it cached once (fmpy's per-call Python wrappers cost more than the plant's
step itself).

Examples
--------
>>> from pendulab.control import demo_controller, discretize
>>> from pendulab.cosim.master import Master
>>> from pendulab.cosim.pendulum import pendulum_system
>>> from pendulab.model.parameters import PlantParameters
>>> system = pendulum_system(PlantParameters.preset(), discretize(demo_controller(), h=1e-3).to_parameters())
>>> with Master(system) as master:
...     log = master.run(stop_time=0.5, record=["plant.x", "supervisor.state"])
>>> len(log["time"]), sorted(log)
(501, ['plant.x', 'supervisor.state', 'time'])
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from pendulab.cosim.component import BASE_TYPES, C_TYPES, Component, SimulationError
from pendulab.cosim.system import System
from pendulab.errors import UserError

__all__ = ["Event", "Master", "SimulationError", "native_runner"]

@dataclass
class Event:
    """Set ``component.variable = value`` at the first communication point at or after ``time``."""

    time: float
    target: str
    value: Any


class Master:
    """Runs a :class:`~pendulab.cosim.system.System` with a fixed macro step.

    Use as a context manager so the FMU instances and their unpacked folders are freed.
    """

    def __init__(self, system: System, *, native: bool = True):
        self.native = native
        if not system.components:
            raise UserError("the system has no components")
        self.system = system
        self.instances: dict[str, Component] = {}
        # The last run's plan and what it was built for: runs of the same wiring reuse it (a sweep's do).
        self._plan: tuple[Any, _Plan] | None = None
        try:
            for name, component in system.components.items():
                self.instances[name] = Component(name, component.fmu, component.start_values)
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------------ life cycle
    def __enter__(self) -> "Master":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._plan = None
        for instance in self.instances.values():
            instance.close()
        self.instances.clear()

    def reset(self, system: System | None = None) -> None:
        """Reset every FMU (``fmi2Reset``) for another :meth:`run`, optionally of another ``system``.

        The new system must have the same components with the same FMUs; its start values and
        connections (e.g. another controller, other plant parameters, another delay) apply from the
        next run. A sweep runs thousands of runs on one set of instances this way instead of
        unpacking and instantiating the FMUs for each.
        """
        if system is not None:
            mine = {n: c.fmu for n, c in self.system.components.items()}
            if {n: c.fmu for n, c in system.components.items()} != mine:
                raise ValueError("reset(system): the system must have the same components and FMUs as the master's")
            self.system = system
        for name, instance in self.instances.items():
            instance.fmu.reset()
            instance.start_values = dict(self.system.components[name].start_values)

    def initialize(self, start_time: float, stop_time: float | None = None) -> None:
        """Set every component's start values and initialize it (``run`` does this itself)."""
        for instance in self.instances.values():
            instance.setup(start_time, stop_time=stop_time)

    def reinitialize(self, name: str, start_time: float, values: Mapping[str, Any] | None = None) -> None:
        """Reset one component (``fmi2Reset``) and initialize it again at ``start_time``.

        Its start values apply, with ``values`` (e.g. a new initial state) on top. Used where a loop
        outside :meth:`run` restarts a component: the lab's controller each time it engages, the rig
        emulator's plant when a hand moves the pendulum.
        """
        self.instances[name].reset(start_time, values)

    def _check_wiring(self, record: Sequence[str]) -> None:
        """Every connection joins an output to an input of the same type; recorded names exist."""
        for c in self.system.connections:
            source = self.instances[c.source].variable(c.source_variable)
            target = self.instances[c.target].variable(c.target_variable)
            if source.causality != "output":
                raise UserError(f"connection {c} starts at {c.source}.{c.source_variable} (causality {source.causality}); a connection starts at an output")
            if target.causality != "input":
                raise UserError(f"connection {c} ends at {c.target}.{c.target_variable} (causality {target.causality}); a connection ends at an input")
            if _base(source.type) != _base(target.type):
                raise UserError(f"connection {c} joins a {_base(source.type)} to a {_base(target.type)}; connect variables of the same type")
        for path in record:
            component, _, variable = path.partition(".")
            self.instances[component].variable(variable)

    # ------------------------------------------------------------------ the loop
    def _apply_events(self, pending: list[Event], t: float, reset_after_step: list) -> None:
        for inst, name, value in reset_after_step:
            inst.set_value(name, value)
        reset_after_step.clear()
        while pending and pending[0].time <= t + 1e-12:
            event = pending.pop(0)
            comp, _, var = event.target.partition(".")
            inst = self.instances[comp]
            inst.set_value(var, event.value)
            start = inst.variable(var).start
            reset_after_step.append((inst, var, start if start is not None else 0))

    def _run_native(self, runner: Any, plan: "_Plan", time: np.ndarray, n_steps: int, h: float,
                    pending: list[Event], stop_when: Any, progress: Any) -> dict[str, np.ndarray]:
        """The same plan, run by the compiled runner between the points where Python must act."""
        ops, names = plan.native_ops()
        reset_after_step: list = []
        failed_at = ctypes.c_long(0)
        k = 0
        t0 = float(time[0])
        while k <= n_steps:
            if reset_after_step or (pending and pending[0].time <= time[k] + 1e-12):
                self._apply_events(pending, time[k], reset_after_step)
            # Run up to the next point where an event, a reset, a stop check or progress is due.
            end = n_steps + 1
            if reset_after_step:
                end = k + 1
            elif pending:
                end = min(end, max(k + 1, int(np.searchsorted(time, pending[0].time - 1e-12))))
            if stop_when is not None or progress is not None:
                # Back in Python every 100 steps for a stop check, every 1000 for progress alone (each
                # return costs about as much as 15 steps of the loop).
                chunk = 100 if stop_when is not None else 1000
                end = min(end, (k // chunk + 1) * chunk)
            failed = runner(ops, len(ops), k, end, n_steps, t0, h, ctypes.byref(failed_at))
            if failed >= 0:
                raise SimulationError(f"{names[failed]} failed at t={time[failed_at.value]:.4f} s (the FMU's log has the reason)")
            k = end
            if k <= n_steps and k % 100 == 0:
                if stop_when is not None and stop_when(plan.row(k - 1)):
                    return {"time": time[:k], **plan.columns(k)}
                if progress is not None and k % 1000 == 0:
                    progress(float(time[k - 1]) + h)
        return {"time": time, **plan.columns(n_steps + 1)}

    def run(
        self,
        stop_time: float,
        record: Sequence[str],
        *,
        start_time: float = 0.0,
        events: Sequence[Event] = (),
        stop_when: Callable[[dict[str, float]], bool] | None = None,
        progress: Callable[[float], None] | None = None,
    ) -> dict[str, np.ndarray]:
        """Simulate from ``start_time`` to ``stop_time`` and return the recorded signals.

        Parameters
        ----------
        record : sequence of str
            ``"component.variable"`` names to log at every communication point.
        events : sequence of Event
            Operator actions (e.g. supervisor commands), applied for one step each.
        stop_when : callable, optional
            Called with the latest recorded values every 100 steps; ``True`` ends the run early.

        Returns
        -------
        dict
            ``"time"`` and every recorded name, arrays of equal length.
        """
        h = self.system.step
        n_steps = int(round((stop_time - start_time) / h))
        if n_steps < 1:
            raise UserError(f"stop time {stop_time} must be at least one step ({h} s) after the start time {start_time}")
        for path in record:
            if path.partition(".")[0] not in self.instances:
                raise UserError(f"cannot record {path!r}: no component {path.partition('.')[0]!r}")
        pending = sorted(events, key=lambda e: e.time)
        for event in pending:
            component, _, name = event.target.partition(".")
            if component not in self.instances:
                raise UserError(f"event target {event.target!r} names no component")
            variable = self.instances[component].variable(name)
            # FMI 2.0 allows only inputs and tunable parameters to change during the run.
            if variable.causality != "input" and not (variable.causality == "parameter" and variable.variability == "tunable"):
                raise UserError(f"event target {event.target!r} is a {variable.variability} {variable.causality}; an event sets an input")
        # The plan depends on the wiring (delays included), what is recorded and the number of steps, on nothing
        # a run sets (start values, events): a run like the last one reuses it, its log rows overwritten.
        key = (tuple(self.system.connections), tuple(record), n_steps)
        if self._plan is None or self._plan[0] != key:
            self._plan = None
            self._check_wiring(record)
        self.initialize(start_time, stop_time)
        if self._plan is None:
            self._plan = (key, _Plan(self, n_steps, record))
        plan = self._plan[1]
        time = start_time + h * np.arange(n_steps + 1)
        reset_after_step: list[tuple[Component, str, Any]] = []
        phase_a, late, recorders, steps = plan.phase_a, plan.late, plan.recorders, plan.steps

        runner = native_runner() if self.native else None
        if runner is not None:
            return self._run_native(runner, plan, time, n_steps, h, pending, stop_when, progress)
        for k in range(n_steps + 1):
            t = time[k]
            if reset_after_step or (pending and pending[0].time <= t + 1e-12):
                self._apply_events(pending, t, reset_after_step)
            # Components in order: inputs from the outputs already known at this point, then outputs.
            # (A get or set that fails stops the run, as in the native runner.)
            for copies, sets, gets in phase_a:
                for src, offset, dst, di in copies:
                    dst[di] = src[k * offset[0] + offset[1]]
                for f, handle, vrs, n, buf in sets:
                    if f(handle, vrs, n, buf) > 1:
                        plan.fail(f, t)
                for f, handle, vrs, n, base, row in gets:
                    if f(handle, vrs, n, base + k * row) > 1:
                        plan.fail(f, t)
            # Inputs fed by components evaluated later (the plant's voltage), then what they change.
            for src, offset, dst, di in late[0]:
                dst[di] = src[k * offset[0] + offset[1]]
            for f, handle, vrs, n, buf in late[1]:
                if f(handle, vrs, n, buf) > 1:
                    plan.fail(f, t)
            for f, handle, vrs, n, base, row in recorders:
                if f(handle, vrs, n, base + k * row) > 1:
                    plan.fail(f, t)
            if k == n_steps:
                break
            for name, do_step, handle in steps:
                if do_step(handle, t, h, 1) > 1:
                    raise SimulationError(f"{name}: fmi2DoStep failed at t={t:.4f} s (the FMU's log has the reason)")
            if stop_when is not None and k % 100 == 99:
                if stop_when(plan.row(k)):
                    return {"time": time[: k + 1], **plan.columns(k + 1)}
            if progress is not None and k % 1000 == 999:
                progress(t + h)
        return {"time": time, **plan.columns(n_steps + 1)}


class _Op(ctypes.Structure):
    """One operation of the native plan runner (see cosim/c/plan_runner.c)."""

    _fields_ = [
        ("kind", ctypes.c_int32),
        ("pad", ctypes.c_int32),
        ("fn", ctypes.c_void_p),
        ("handle", ctypes.c_void_p),
        ("vrs", ctypes.c_void_p),
        ("n", ctypes.c_size_t),
        ("base", ctypes.c_void_p),
        ("row", ctypes.c_ssize_t),
        ("target", ctypes.c_void_p),
    ]


_OP_ACCESS, _OP_COPY_F64, _OP_COPY_I32, _OP_BARRIER, _OP_STEP = range(5)
_RUNNER: list[Any] = []


#: The plan runner's source, and its compiler flags (part of the library's name: the wheel's prebuilt
#: runner is found by them).
PLAN_RUNNER_SOURCE = Path(__file__).parent / "c" / "plan_runner.c"
PLAN_RUNNER_FLAGS = ("-O2", "-std=c99")


def native_runner() -> Any | None:
    """The compiled plan runner (prebuilt in a wheel, else compiled on first use); None without one.

    :meth:`Master.run` with ``native=True`` runs its step loop through it; without it (no C compiler
    and no prebuilt runner) the Python loop runs the same plan, slower, with bit-identical logs.

    Returns
    -------
    ctypes function or None
        ``pendulab_run_plan`` of the shared library built from :data:`PLAN_RUNNER_SOURCE` with
        :data:`PLAN_RUNNER_FLAGS` (found or built once per process), or ``None``.

    Examples
    --------
    >>> runner = native_runner()
    >>> runner is None or runner.__name__ == "pendulab_run_plan"
    True
    """
    if not _RUNNER:
        from pendulab.native import shared_library

        try:
            library = shared_library(PLAN_RUNNER_SOURCE, flags=PLAN_RUNNER_FLAGS)
            if library is None:
                raise OSError("no C compiler and no prebuilt plan runner")
            f = ctypes.CDLL(str(library.path)).pendulab_run_plan
            f.argtypes = [ctypes.c_void_p, ctypes.c_long, ctypes.c_long, ctypes.c_long, ctypes.c_long, ctypes.c_double, ctypes.c_double,
                          ctypes.POINTER(ctypes.c_long)]
            f.restype = ctypes.c_long
            _RUNNER.append(f)
        except (OSError, AttributeError):  # the Python loop runs the same plan, slower
            _RUNNER.append(None)
    return _RUNNER[0]


_GET = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)
_STEP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)
_NUMPY = {"Real": np.float64, "Integer": np.int32, "Boolean": np.int32}


class _Plan:
    """The step loop compiled to flat lists of C calls on fixed addresses.

    Each component's outputs (connected or recorded) are read straight into a log array, one row
    per communication point; connections copy from that row into the target's input buffer.
    """

    def __init__(self, master: "Master", n_steps: int, record: Sequence[str]):
        system = master.system
        order = list(master.instances)
        position = {name: k for k, name in enumerate(order)}
        self._keep: list[Any] = []  # ctypes objects whose addresses the plan uses
        self._native: tuple[Any, list[str]] | None = None
        self._labels: dict[int, str] = {}
        self._logs: dict[tuple[str, str], tuple[np.ndarray, list[str]]] = {}
        self._record = list(record)

        read: dict[str, list[str]] = {n: [] for n in order}
        for c in system.connections:
            read[c.source].append(c.source_variable)
        for path in record:
            comp, _, var = path.partition(".")
            read[comp].append(var)
        flat: dict[tuple[str, str], Any] = {}
        # A delayed connection reads an earlier row of its source's log: the log gets that many
        # leading rows holding the source's start value (what the target sees before the first output).
        self._pad: dict[str, int] = {n: 0 for n in order}
        for c in system.connections:
            self._pad[c.source] = max(self._pad[c.source], c.delay)
        self.phase_a: list[tuple[list, list, list]] = []
        gets_of: dict[str, list] = {}
        for name in order:
            inst = master.instances[name]
            gets = []
            by_type: dict[str, list[str]] = {t: [] for t in BASE_TYPES}
            for var in dict.fromkeys(read[name]):
                by_type[_base(inst.variable(var).type)].append(var)
            for t, names in by_type.items():
                if not names:
                    continue
                pad = self._pad[name]
                full = np.zeros((n_steps + 1 + pad, len(names)), dtype=_NUMPY[t])
                if pad and t == "Real":
                    full[:pad] = [float(inst.variable(v).start or 0.0) for v in names]
                log = full[pad:]
                self._logs[(name, t)] = (log, names)
                flat[(name, t)] = (ctypes.c_double if t == "Real" else ctypes.c_int32) * full.size
                flat[(name, t)] = flat[(name, t)].from_buffer(full)
                vrs = (ctypes.c_uint * len(names))(*(inst.variable(v).valueReference for v in names))
                self._keep += [vrs, flat[(name, t)]]
                f = _GET((f"fmi2Get{t}".encode(), inst.fmu.dll))
                self._keep.append(f)
                self._labels[id(f)] = f"{name}: fmi2Get{t}"
                gets.append((f, inst.handle, ctypes.addressof(vrs), len(names), log.ctypes.data, log.strides[0]))
            gets_of[name] = gets

        early_copies: dict[str, list] = {n: [] for n in order}
        late_copies: list = []
        inputs: dict[tuple[str, str, bool], tuple[Any, list[str]]] = {}
        sets: dict[str, list] = {n: [] for n in order}
        late_sets: list = []
        # An input fed by a component evaluated at or after its own is set late (after that component's
        # outputs at the same point, before the step); the others are set before the component's outputs.
        late_input = {(c.target, c.target_variable): position[c.source] >= position[c.target] for c in system.connections}
        for name in order:
            inst = master.instances[name]
            targets = [c.target_variable for c in system.connections if c.target == name]
            for t in BASE_TYPES:
                for is_late in (False, True):
                    names = [v for v in dict.fromkeys(targets) if _base(inst.variable(v).type) == t and late_input[(name, v)] == is_late]
                    if not names:
                        continue
                    buf = (C_TYPES[t] * len(names))()
                    vrs = (ctypes.c_uint * len(names))(*(inst.variable(v).valueReference for v in names))
                    f = _GET((f"fmi2Set{t}".encode(), inst.fmu.dll))
                    self._keep += [buf, vrs, f]
                    self._labels[id(f)] = f"{name}: fmi2Set{t}"
                    inputs[(name, t, is_late)] = (buf, names)
                    call = (f, inst.handle, ctypes.addressof(vrs), len(names), ctypes.addressof(buf))
                    (late_sets if is_late else sets[name]).append(call)
        for c in system.connections:
            src_inst, dst_inst = master.instances[c.source], master.instances[c.target]
            st = _base(src_inst.variable(c.source_variable).type)
            tt = _base(dst_inst.variable(c.target_variable).type)
            if st != tt:
                raise UserError(f"connection {c} joins a {st} to a {tt}; connect variables of the same type")
            log, names = self._logs[(c.source, st)]
            is_late = late_input[(c.target, c.target_variable)]
            buf, in_names = inputs[(c.target, tt, is_late)]
            first = (self._pad[c.source] - c.delay) * len(names)  # index in the padded log of row k = 0
            copy = (flat[(c.source, st)], (len(names), first + names.index(c.source_variable)), buf, in_names.index(c.target_variable))
            (late_copies if is_late else early_copies[c.target]).append(copy)
        self.phase_a = [(early_copies[n], sets[n], gets_of[n]) for n in order]
        self.late = (late_copies, late_sets)
        late_components = {c.target for c in system.connections if position[c.source] >= position[c.target]}
        self.recorders = [g for n in order if n in late_components for g in gets_of[n]]
        self.steps = []
        for name in order:
            f = _STEP((b"fmi2DoStep", master.instances[name].fmu.dll))
            self._keep.append(f)
            self.steps.append((name, f, master.instances[name].handle))

    def native_ops(self) -> tuple[Any, list[str]]:
        """The plan as an array of :class:`_Op` (and a label per operation for error messages); built once."""
        if self._native is None:
            self._native = self._native_ops()
        return self._native

    def _native_ops(self) -> tuple[Any, list[str]]:
        ops: list[_Op] = []
        labels: list[str] = []

        def address(fn: Any) -> int:
            return ctypes.cast(fn, ctypes.c_void_p).value or 0

        def copies(items: list) -> None:
            for src, (m, si), dst, di in items:
                size = ctypes.sizeof(src._type_)
                kind = _OP_COPY_F64 if src._type_ is ctypes.c_double else _OP_COPY_I32
                ops.append(_Op(kind, 0, None, None, None, 0, ctypes.addressof(src) + si * size, m * size, ctypes.addressof(dst) + di * size))
                labels.append("copy")

        def calls(items: list, fixed: bool) -> None:
            for item in items:
                if fixed:
                    f, handle, vrs, n, buf = item
                    base, row = buf, 0
                else:
                    f, handle, vrs, n, base, row = item
                ops.append(_Op(_OP_ACCESS, 0, address(f), handle, vrs, n, base, row, None))
                labels.append(self._labels.get(id(f), "fmi2Get/Set"))

        for conn, sets, gets in self.phase_a:
            copies(conn)
            calls(sets, True)
            calls(gets, False)
        copies(self.late[0])
        calls(self.late[1], True)
        calls(self.recorders, False)
        ops.append(_Op(_OP_BARRIER, 0, None, None, None, 0, None, 0, None))
        labels.append("barrier")
        for name, f, handle in self.steps:
            ops.append(_Op(_OP_STEP, 0, address(f), handle, None, 0, None, 0, None))
            labels.append(f"{name}: fmi2DoStep")
        array = (_Op * len(ops))(*ops)
        self._keep.append(array)
        return array, labels

    def fail(self, f: Any, t: float) -> None:
        """Raise the error of a failed get/set call ``f`` at time ``t`` (worded as the native runner's)."""
        raise SimulationError(f"{self._labels.get(id(f), 'fmi2Get/Set')} failed at t={t:.4f} s (the FMU's log has the reason)")

    def _lookup(self, path: str) -> tuple[np.ndarray, int]:
        comp, _, var = path.partition(".")
        for (name, _t), (log, names) in self._logs.items():
            if name == comp and var in names:
                return log, names.index(var)
        raise KeyError(path)

    def columns(self, length: int) -> dict[str, np.ndarray]:
        out = {}
        for path in self._record:
            log, j = self._lookup(path)
            out[path] = log[:length, j].astype(float)
        return out

    def row(self, k: int) -> dict[str, float]:
        return {path: float(self._lookup(path)[0][k, self._lookup(path)[1]]) for path in self._record}


def _base(type_name: str) -> str:
    return "Integer" if type_name == "Enumeration" else type_name
