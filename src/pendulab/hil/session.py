"""The lab session: the simulation's controller and supervisor FMUs, with the plant replaced by the rig.

The loop is clocked by the rig: every SAMPLE is answered by one COMMAND computed by the same
Controller.fmu and Supervisor.fmu, wired by the same connections (:data:`pendulab.cosim.pendulum.CONNECTIONS`)
as in simulation. The plant's side of those connections is the rig: ``plant.alpha_measured`` is the rig's
pendulum encoder angle theta (0 hanging down, which the supervisor converts in ``rig_mode``; the
controller's connection takes it in the upright convention), ``plant.x_measured`` the cart encoder, and
``plant.V`` the rig's command.

Every way out (the end key, the stop time, Ctrl-C, a lost link, a rig fault, a restart, any exception)
turns the motor off first, then saves the log with the reason.
"""

from __future__ import annotations

import gc
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from pendulab.cosim.component import Port, SimulationError
from pendulab.cosim.master import Master
from pendulab.cosim.system import System
from pendulab.errors import UserError
from pendulab.fmu.models.supervisor.config import COMMANDS, KEYS, RUNNING, STATES, TRIP_REASONS, TRIPPED, rig_to_upright
from pendulab.hil import protocol as P
from pendulab.hil.link import Encoders, LinkLost, RigLink, RigRestarted

#: The rig's stand-in name in the wiring.
RIG = "plant"
#: Conversions on connections out of the rig: the controller takes the angle from upright.
RIG_ADAPTERS: dict[tuple[str, str], Callable[[float], float]] = {
    ("plant.alpha_measured", "controller.alpha_measured"): rig_to_upright,
}
#: Streamed log columns (rig_log.csv).
LOG_COLUMNS = ("t", "tick", "x", "theta", "alpha", "voltage_command", "voltage", "supervisor_state", "status", "latency_ms", "late",
               "reference", "recentring")
#: No sample for this long: ask the rig who it is; no answer: the link is lost.
SILENCE = 0.25


@dataclass
class Timing:
    """The loop's timing record (``timing.json``)."""

    latencies: list[float] = field(default_factory=list)
    samples: int = 0
    missed_samples: int = 0
    late_commands: int = 0
    crc_errors: int = 0
    lost_frames: int = 0

    def summary(self, delay: int, period: float, round_trips: list[float]) -> dict[str, Any]:
        lat = np.asarray(self.latencies) * 1e3
        pct = (lambda q: float(np.percentile(lat, q))) if lat.size else (lambda q: None)
        return {
            "samples": self.samples,
            "period_s": period,
            "delay_periods": delay,
            "answer_latency_ms": {"p50": pct(50), "p99": pct(99), "max": float(lat.max()) if lat.size else None},
            "late_commands": self.late_commands,
            "late_fraction": self.late_commands / self.samples if self.samples else 0.0,
            "missed_samples": self.missed_samples,
            "crc_errors": self.crc_errors,
            "lost_frames": self.lost_frames,
            "round_trip_ms": {"p50": float(np.percentile(round_trips, 50)) * 1e3, "max": max(round_trips) * 1e3} if round_trips else None,
        }


#: Largest share of late answers a delay may show when it is tried (the bar for a session is 0.1 %).
LATE_ALLOWED = 0.001


def choose_delay(link: RigLink, max_delay: int, *, samples: int = 1000, announce: Callable[[str], None] = print) -> int:
    """The smallest transport delay N (periods) at which the host's answers reach the rig in time.

    Tried on the sample stream itself (motor disabled, ``samples`` periods per N): N holds when at
    most :data:`LATE_ALLOWED` of the answers are late.
    """
    for n in range(1, max_delay + 1):
        link.configure(delay=n)
        link.stream(True)
        late = 0
        got = 0
        try:
            while got < samples:
                item = link.next_sample(SILENCE)
                if item is None:
                    raise LinkLost(f"link lost: no sample from the rig for {SILENCE * 1e3:.0f} ms while measuring the delay")
                sample = item[0]
                link.command(sample.seq, 0.0, enable=False, clear=got == 0)
                if got > n + 2 and sample.status & P.ST_LATE:
                    late += 1
                got += 1
        finally:
            link.stream(False)
        if late <= LATE_ALLOWED * samples:
            announce(f"transport delay: N = {n} period(s) holds ({late} of {samples} answers late)")
            return n
        announce(f"transport delay: N = {n} is too short ({late} of {samples} answers late)")
    raise UserError(
        f"the link is too slow for the rig: answers were late even with a delay of {max_delay} periods; connect the rig "
        f"directly (not through a hub), close other programs, or allow more with --max-delay"
    )


class LabSession:
    """One session on the rig. ``run()`` returns the reason it ended and the exit status."""

    def __init__(
        self,
        link: RigLink,
        system: System,
        *,
        out_dir: Path,
        keys: Any,
        Lp: float,
        stop_time: float | None = None,
        announce: Callable[[str], None] = print,
        priority: str = "normal priority",
    ) -> None:
        self.link = link
        self.identity = link.identity
        assert self.identity is not None
        self.system = system
        self.out_dir = Path(out_dir)
        self.keys = keys
        self.Lp = Lp
        self.stop_time = stop_time
        self.announce = announce
        self.period = self.identity.period_us * 1e-6
        self.timing = Timing()
        self.reason = ""
        self.priority = priority

    # ------------------------------------------------------------------ wiring
    def _wire(self, master: Master) -> None:
        """Ports and copy lists from the system's connections; the rig stands in for ``plant``."""
        self.order = [name for name in self.system.components if name != RIG]
        # Each input and output with its place in its port's buffers, found once (not per sample).
        Slot = tuple[str, str, int]  # "component.variable", base type, index in the port's buffer
        self.inputs: dict[str, tuple[Port, list[tuple[Slot, Callable[[float], float] | None]]]] = {}
        self.outputs: dict[str, tuple[Port, list[Slot]]] = {}
        for name in self.order:
            inst = master.instances[name]
            conns = [c for c in self.system.connections if c.target == name]
            port = inst.port([c.target_variable for c in conns])
            self.inputs[name] = (port, [
                ((f"{c.source}.{c.source_variable}", *port.index(c.target_variable)),
                 RIG_ADAPTERS.get((f"{c.source}.{c.source_variable}", f"{c.target}.{c.target_variable}")))
                for c in conns
            ])
            needed = [c.source_variable for c in self.system.connections if c.source == name]
            if name == "supervisor":
                needed += ["state", "trip_reason", "motor_enable", "r", "recentring", "misses"]
            needed = list(dict.fromkeys(needed))
            out = inst.port(needed)
            self.outputs[name] = (out, [(f"{name}.{var}", *out.index(var)) for var in needed])
        to_rig = [c for c in self.system.connections if c.target == RIG]
        if len(to_rig) != 1 or to_rig[0].target_variable != "V":
            raise UserError("the lab's wiring needs exactly one connection into plant.V")
        self.voltage_source = f"{to_rig[0].source}.{to_rig[0].source_variable}"
        self.command_port = master.instances["supervisor"].port(["command"])

    def _initial_outputs(self, master: Master) -> dict[str, float]:
        """Every component's outputs after initialization (its inputs at their start values)."""
        values: dict[str, float] = {}
        for name in self.order:
            out, slots = self.outputs[name]
            master.instances[name].read(out)
            for path, t, i in slots:
                values[path] = out.values[t][i]
        return values

    def _evaluate(self, master: Master, values: dict[str, float]) -> None:
        for name in self.order:
            inst = master.instances[name]
            port, wiring = self.inputs[name]
            for (source, t, i), adapt in wiring:
                value = values[source]
                port.values[t][i] = adapt(value) if adapt else value
            inst.write(port)
            out, slots = self.outputs[name]
            inst.read(out)
            for path, t, i in slots:
                values[path] = out.values[t][i]

    # ------------------------------------------------------------------ the loop
    def run(self) -> tuple[str, int]:
        from pendulab.analysis.results import RunLog

        sub = System(step=self.period)
        for name, component in self.system.components.items():
            if name != RIG:
                sub.add(name, component.fmu, component.start_values)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        log = RunLog(self.out_dir / "rig_log.csv", LOG_COLUMNS, flush_every=50)
        self.log_path = log.path
        status = 1
        last_seq = 0
        master = Master(sub)
        try:
            master.initialize(0.0, self.stop_time)
            self._wire(master)
            sup, ctrl = master.instances["supervisor"], master.instances["controller"]
            encoders = Encoders(self.identity)
            link = self.link
            # A full garbage collection of everything the FMUs and libraries loaded takes milliseconds,
            # more than a period: freeze what exists now, and collect no cycles during the session
            # (the loop makes none; everything it allocates is freed by reference counting).
            gc.collect()
            gc.freeze()
            gc.disable()
            link.stream(True)
            swing_up = bool(self.system.components["supervisor"].start_values.get("swing_up"))
            self.announce("streaming: press s to start, p to pause, e to end (r re-arms after a trip); " + (
                "s swings the pendulum up from hanging, the controller takes it inside the catch window" if swing_up else
                "raise the pendulum by hand, the controller takes it inside the capture window"))
            # Inputs fed by a component evaluated later (the supervisor's r and engagement of the controller)
            # take that component's outputs of the previous sample; before the first, its outputs now.
            values: dict[str, float] = self._initial_outputs(master)
            recentring = False
            state = -1
            first_tick: int | None = None
            prev_tick: int | None = None
            clear = True
            silent_since = time.perf_counter()
            limit_said = False
            t = 0.0
            timing = self.timing
            while True:
                item = link.next_sample(0.05)
                if item is None:
                    if time.perf_counter() - silent_since > SILENCE:
                        self._check_rig_after_silence()
                    if "e" in self.keys.poll():
                        self.reason = "ended by the operator (e) while the rig was silent"
                        status = 0
                        break
                    continue
                sample, received = item
                silent_since = received
                if prev_tick is not None:
                    gap = sample.tick - prev_tick
                    if gap <= 0:
                        raise RigRestarted(f"the rig restarted (its tick went back from {prev_tick} to {sample.tick})")
                    timing.missed_samples += gap - 1
                else:
                    first_tick = sample.tick
                prev_tick = sample.tick
                t = (sample.tick - (first_tick or 0)) * self.period
                x, theta = encoders.update(sample)
                values["plant.alpha_measured"] = theta
                values["plant.x_measured"] = x
                command = 0
                for key in self.keys.poll():
                    if key in KEYS:
                        command = COMMANDS[KEYS[key]]
                        self.announce(f"[{t:8.3f} s] key {key!r}: {KEYS[key]}")
                self.command_port.values["Integer"][0] = command
                sup.write(self.command_port)
                self._evaluate(master, values)
                voltage = values[self.voltage_source]
                enable = bool(values["supervisor.motor_enable"])
                link.command(sample.seq, voltage if enable else 0.0, enable=enable, clear=clear)
                sent = time.perf_counter()
                clear = False
                last_seq = sample.seq
                timing.latencies.append(sent - received)
                timing.samples += 1
                if sample.status & P.ST_LATE:
                    timing.late_commands += 1
                new_state = int(values["supervisor.state"])
                alpha = rig_to_upright(theta)
                log.append((t, sample.tick, x, theta, alpha, values["controller.V_command"], sample.voltage_mv / 1000.0,
                            new_state, sample.status, (sent - received) * 1e3, sample.late, values["supervisor.r"],
                            int(values["supervisor.recentring"])))
                if bool(values["supervisor.recentring"]) != recentring:
                    recentring = not recentring
                    self.announce(f"[{t:8.3f} s] re-centring {'engaged' if recentring else 'released'} (x = {x:+.3f} m)")
                if new_state != state:
                    why = ""
                    if STATES.get(new_state) == "tripped":
                        why = f" ({TRIP_REASONS.get(int(values['supervisor.trip_reason']), '?')})"
                    if STATES.get(state) == "swinging up" and new_state == RUNNING:
                        why = f" (caught at x = {x:+.3f} m, alpha = {math.degrees(alpha):+.1f} deg)"
                    elif state == RUNNING and STATES.get(new_state) == "swinging up":
                        why = f" (catch missed: {int(values['supervisor.misses'])} so far)"
                    self.announce(f"[{t:8.3f} s] {STATES.get(new_state, new_state)}{why}")
                    if state == RUNNING and new_state != RUNNING:
                        # The controller starts from a reset state each time it engages.
                        master.reinitialize("controller", t)
                    state = new_state
                if sample.status & P.ST_FAULT:
                    raise RigFault("the rig reports a fault (amplifier or encoder); check the rig")
                if sample.status & P.ST_WATCHDOG and not clear and timing.samples > 3 * link.delay + 5:
                    raise RigFault("the rig's watchdog tripped: the host's answers stopped reaching it in time")
                if sample.status & P.ST_LIMIT and not limit_said:
                    limit_said = True
                    self.announce(f"[{t:8.3f} s] the rig's own track limit cut the motor")
                if STATES.get(state) == "ended":
                    self.reason = "ended by the operator (e)"
                    status = 0
                    break
                if self.stop_time is not None and t >= self.stop_time:
                    self.reason = f"stop time {self.stop_time:g} s reached"
                    status = 0
                    break
                sup.step(t, self.period)
                if state == RUNNING:
                    ctrl.step(t, self.period)
        except KeyboardInterrupt:
            self.reason, status = "interrupted (Ctrl-C)", 130
        except (LinkLost, RigRestarted, RigFault) as exc:
            self.reason, status = str(exc), 1
        except SimulationError as exc:
            self.reason, status = f"an FMU failed: {exc}", 1
        except UserError:
            raise
        except Exception as exc:  # noqa: BLE001 - any error: motor off, log kept, reason recorded
            self.reason, status = f"error: {type(exc).__name__}: {exc}", 1
        finally:
            self.link.motor_off(last_seq)
            gc.enable()
            gc.unfreeze()
            log.close()
            master.close()
            timing.crc_errors = self.link.reader.errors
            timing.lost_frames = self.link.reader.lost
        self.announce(f"motor off; session ended: {self.reason}")
        return self.reason, status

    def _check_rig_after_silence(self) -> None:
        """Samples stopped: a restarted rig answers with a new boot id; a dead link does not answer."""
        old = self.identity
        self.link.send(P.Identify, protocol=P.PROTOCOL_VERSION)
        item = self.link.expect(P.Identity, 0.3)
        if item is None:
            raise LinkLost(f"link lost: no data from the rig for {SILENCE * 1e3 + 300:.0f} ms")
        identity = item[0]
        if old is not None and identity.boot_id != old.boot_id:  # type: ignore[attr-defined]
            raise RigRestarted(f"the rig restarted (boot id {old.boot_id:#010x} -> {identity.boot_id:#010x})")  # type: ignore[attr-defined]
        raise LinkLost("link lost: the rig answers but stopped streaming samples")


class RigFault(Exception):
    """The rig or an FMU reported a fault during the session."""


def rig_columns(log_path: Path, Lp: float) -> dict[str, np.ndarray]:
    """The run's columns (SPEC §7 names) from the streamed rig log.

    The rig measures no speed: ``xdot`` is the cart position's central difference over 10 ms, and
    ``alpha`` is the measured angle (the rig has no other).
    """
    data = np.genfromtxt(log_path, delimiter=",", names=True)
    data = np.atleast_1d(data)
    t = np.asarray(data["t"], dtype=float)
    x = np.asarray(data["x"], dtype=float)
    alpha = np.asarray(data["alpha"], dtype=float)
    if t.size > 1:
        period = float(np.median(np.diff(t)))
        w = max(1, int(round(0.005 / period)))
        xdot = np.zeros_like(x)
        xdot[w:-w] = (x[2 * w:] - x[: -2 * w]) / (t[2 * w:] - t[: -2 * w]) if x.size > 2 * w else 0.0
    else:
        xdot = np.zeros_like(x)
    return {
        "t": t,
        "x": x,
        "xdot": xdot,
        "alpha": alpha,
        "alpha_measured": alpha,
        "tip": Lp * alpha,
        "voltage_command": np.asarray(data["voltage_command"], dtype=float),
        "voltage": np.asarray(data["voltage"], dtype=float),
        "supervisor_state": np.asarray(data["supervisor_state"], dtype=float),
        "latency_ms": np.asarray(data["latency_ms"], dtype=float),
        **{name: np.asarray(data[name], dtype=float) for name in ("reference", "recentring") if name in (data.dtype.names or ())},
    }


def write_lab_results(session: LabSession, *, Lp: float, q_alpha: float, meta: dict[str, Any], round_trips: list[float]) -> tuple[dict, dict]:
    """run.mat, run.csv, metrics.json and timing.json from the streamed log."""
    from pendulab.analysis.metrics import compute_metrics
    from pendulab.analysis.results import atomic_write, write_results

    columns = rig_columns(session.log_path, Lp)
    t = columns["t"]
    running = np.flatnonzero(columns["supervisor_state"] == RUNNING)
    cut = None
    tripped = np.flatnonzero(columns["supervisor_state"] == TRIPPED)
    if tripped.size:
        cut = float(t[tripped[0]])
    # The poke is looked for while the controller holds the pendulum (after the capture, before a cut).
    from pendulab.analysis.compare import detect_poke

    poke = detect_poke(t, columns["alpha"], q_alpha=q_alpha, after=float(t[running[0]]) + 0.1, before=cut) if running.size else None
    metrics: dict[str, Any]
    if poke is not None and t.size > 10 and poke < t[-1] - 0.05:
        try:
            metrics = compute_metrics(t, columns["alpha"], poke_start=poke, q_alpha=q_alpha, xdot=columns["xdot"], safety_cut_time=cut)
        except Exception as exc:  # noqa: BLE001 - a log too short or odd for metrics still gets its files
            metrics = {"error": f"metrics could not be computed: {exc}"}
    else:
        metrics = {"error": "no poke found in the measured angle while the controller was engaged"}
    metrics["poke_start_detected_s"] = poke
    metrics["end_reason"] = session.reason
    meta = {**meta, "end_reason": session.reason, "source": "rig", "delay": session.link.delay}
    if meta.get("recentre") or meta.get("swing_up"):
        from pendulab.analysis.modes import mode_events, mode_metrics

        metrics.update(mode_metrics(t, columns["supervisor_state"], recentring=columns.get("recentring"), x=columns["x"]))
        meta["mode_events"] = mode_events(t, columns["supervisor_state"], recentring=columns.get("recentring"))
    else:  # the run's files as before the modes existed
        columns.pop("reference", None)
        columns.pop("recentring", None)
    write_results(session.out_dir, columns, meta, metrics)
    timing = session.timing.summary(session.link.delay, session.period, round_trips)
    timing["host_scheduling"] = session.priority
    atomic_write(session.out_dir / "timing.json", lambda f: f.write(json.dumps(timing, indent=2).encode()))
    return metrics, timing

