"""The lab session: the simulation's controller and supervisor FMUs, with the plant replaced by the rig.

The loop is clocked by the rig: every SAMPLE is answered by one COMMAND computed by the same
Controller.fmu and Supervisor.fmu, wired by the same connections (:data:`pendulab.cosim.pendulum.CONNECTIONS`)
as in simulation. The plant's side of those connections is the rig: ``plant.alpha_measured`` is the rig's
pendulum encoder angle theta (0 hanging down, which the supervisor converts in ``rig_mode``; the
controller's connection takes it in the upright convention), ``plant.x_measured`` the cart encoder, and
``plant.V`` the rig's command.

The seesaw's rig stands in for ``seesaw`` (:data:`pendulab.cosim.seesaw.CONNECTIONS`): its tilt encoder (0 level,
no conversion anywhere) feeds ``seesaw.theta_measured``, its cart encoder ``seesaw.x_measured``.

Every way out (the end key, the stop time, Ctrl-C, a lost link, a rig fault, a restart, any exception)
turns the motor off first, then saves the log with the reason.
"""

from __future__ import annotations

import contextlib
import json
import math
import time
from dataclasses import dataclass, field, replace
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
from pendulab.hil.realtime import Terminated, no_garbage_collection

#: The rig's stand-in name in the wiring.
RIG = "plant"
#: The rig's stand-in names (the pendulum's, the seesaw's) -> the variables its angle and cart encoders feed.
RIG_SIGNALS = {RIG: ("alpha_measured", "x_measured"), "seesaw": ("theta_measured", "x_measured")}
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


#: A cart driven at least this hard (V, the rig's applied voltage; the lab's cart breaks away at about 0.9 V) ...
DRIVE_VOLTAGE = 1.5
#: ... for this long in all (s) since the cart encoder's last count has moved: a dead or frozen encoder.
DRIVE_TIME = 0.15
#: While the controller balances the pendulum, the cart moves all the time: no count for this long (s) while
#: the motor applied at least BALANCE_VOLTAGE (V) for BALANCE_DRIVE (s) of it is a dead or frozen cart encoder.
BALANCE_STILL = 1.0
BALANCE_VOLTAGE = 1.0
BALANCE_DRIVE = 0.1
#: The cart travelled this far (m) with the pendulum up and its encoder gave no count for PIVOT_STILL (s): a dead
#: or frozen encoder (moving the pivot 15 mm turns a balanced pendulum by far more than its encoder's step). The
#: time matters at a swing's turning point: after a swing-up's catch the cart runs at 0.3 m/s while a 3 degree
#: swing dwells about 50 ms within one count (a healthy encoder, measured: issue 21).
PIVOT_TRAVEL = 0.015
PIVOT_STILL = 0.15


class EncoderWatch:
    """Finds a dead or frozen encoder from the motion the rig's own numbers imply.

    The cart: the motor drives it (``|V| >=`` :data:`DRIVE_VOLTAGE` for :data:`DRIVE_TIME` in all), or the
    controller balances the pendulum for :data:`BALANCE_STILL` (which moves the cart all the time), and its
    count does not change. The pendulum: held up by the controller while the cart travels :data:`PIVOT_TRAVEL`, its
    count does not change for :data:`PIVOT_STILL`. :meth:`update` returns what is wrong, in words, or None.

    Examples
    --------
    >>> watch = EncoderWatch(period=0.001)          # 5 V on a cart whose count never changes:
    >>> next(k for k in range(1000) if watch.update(0.0, 0.0, 5.0, running=False))   # periods until it is found
    150
    """

    def __init__(self, period: float) -> None:
        self.period = period
        self.x: float | None = None
        self.theta: float | None = None
        self.driven = self.still = self.pushed = 0.0
        self.x_at_theta = 0.0
        self.theta_still = 0.0

    def update(self, x: float, theta: float, voltage: float, *, running: bool) -> str | None:
        if x != self.x:
            self.x, self.driven, self.still, self.pushed = x, 0.0, 0.0, 0.0
        else:
            self.still += self.period
            if abs(voltage) >= DRIVE_VOLTAGE:
                self.driven += self.period
                if self.driven > DRIVE_TIME:
                    return (f"the cart encoder gave no count while the motor drove the cart at {abs(voltage):.1f} V for "
                            f"{self.driven * 1e3:.0f} ms: a dead or frozen cart encoder")
            if abs(voltage) >= BALANCE_VOLTAGE and running:
                self.pushed += self.period
            if not running:
                self.still = self.pushed = 0.0
            elif self.still > BALANCE_STILL and self.pushed > BALANCE_DRIVE:
                return (f"the cart encoder gave no count for {self.still:.1f} s while the controller balanced the pendulum "
                        f"(the motor at {BALANCE_VOLTAGE:g} V or more for {self.pushed * 1e3:.0f} ms of it): a dead or frozen cart encoder")
        if theta != self.theta or not running:
            self.theta, self.x_at_theta, self.theta_still = theta, x, 0.0
            return None
        self.theta_still += self.period
        if self.theta_still > PIVOT_STILL and abs(x - self.x_at_theta) > PIVOT_TRAVEL:
            return (f"the pendulum encoder gave no count while the cart moved {abs(x - self.x_at_theta) * 1e3:.0f} mm under the "
                    "balanced pendulum: a dead or frozen pendulum encoder")
        return None


#: Largest share of late answers a delay may show when it is tried (the bar for a session is 0.1 %).
LATE_ALLOWED = 0.001


def choose_delay(link: RigLink, max_delay: int, *, samples: int = 1000, announce: Callable[[str], None] = print) -> int:
    """The smallest transport delay N (periods) at which the host's answers reach the rig in time.

    Tried on the sample stream itself (motor disabled, ``samples`` periods per N): N holds when at
    most :data:`LATE_ALLOWED` of the answers are late, not counting the answers a noisy link explains.
    A corrupted frame is an answer missed whatever N is: a sample the host never received (a CRC error
    or a gap in the sample numbers, both counted here) gets no answer, and a command corrupted on its
    way to the rig arrives as nothing; the second kind is as frequent as the first on a link that
    corrupts both directions alike. Those late answers are allowed (and said: a noisy link needs a
    cable, not a longer delay); when even that does not hold at ``max_delay``, the error names the
    cause it measured.
    """
    last_late, last_corrupted = 0, 0
    for n in range(1, max_delay + 1):
        link.configure(delay=n)
        errors0, lost0 = link.reader.errors, link.reader.lost
        link.stream(True)
        late = 0
        got = 0
        try:
            while got < samples:
                item = link.next_sample(SILENCE)
                if item is None:
                    link.stream(False)
                    cause = link.silence_cause(SILENCE * 1e3)
                    if isinstance(cause, RigRestarted) or link.identity is None:
                        raise cause
                    if "answered again" not in str(cause):
                        raise LinkLost(f"{cause} while measuring the delay")
                    # The rig is there but its samples stalled (a busy host or link): N failed, try the next.
                    late = samples
                    break
                sample = item[0]
                link.command(sample.seq, 0.0, enable=False, clear=got == 0)
                if got > n + 2 and sample.status & P.ST_LATE:
                    late += 1
                got += 1
        finally:
            link.stream(False)
        corrupted = (link.reader.errors - errors0) + (link.reader.lost - lost0)
        # Each corrupted frame coming in costs one answer; as many going out, half again for safety.
        explained = int(np.ceil(2.5 * corrupted))
        last_late, last_corrupted = late, corrupted
        noisy = f"; {corrupted} frames from the rig corrupted or lost: a noisy link, each costs an answer" if corrupted else ""
        if late <= LATE_ALLOWED * samples + explained:
            announce(f"transport delay: N = {n} period(s) holds ({late} of {samples} answers late{noisy})")
            return n
        announce(f"transport delay: N = {n} is too short ({late} of {samples} answers late{noisy})")
    if last_corrupted and last_late <= 4 * LATE_ALLOWED * samples + 2.5 * last_corrupted * 2:
        raise UserError(
            f"the link corrupts frames: {last_corrupted} of {samples} frames from the rig arrived corrupted or not at all "
            f"(CRC errors), and {last_late} answers were late even with a delay of {max_delay} periods; check the USB cable "
            f"and its connectors, use a shorter cable or another USB port, keep it away from the motor's power leads"
        )
    raise UserError(
        f"the link is too slow for the rig: answers were late even with a delay of {max_delay} periods"
        + (f" ({last_corrupted} frames also arrived corrupted)" if last_corrupted else "")
        + "; connect the rig directly (not through a hub), close other programs, or allow more with --max-delay"
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
        self.status = 1
        self.priority = priority
        self.rig = next((name for name in RIG_SIGNALS if name in system.components), RIG)
        # The angle in the log's "alpha" column: the pendulum's from upright; the seesaw's tilt as measured.
        self.seesaw = self.rig == "seesaw"
        self.upright: Callable[[float], float] = (lambda theta: theta) if self.seesaw else rig_to_upright

    # ------------------------------------------------------------------ wiring
    def _wire(self, master: Master) -> None:
        """Ports and copy lists from the system's connections; the rig stands in for ``plant``."""
        self.order = [name for name in self.system.components if name != self.rig]
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
        to_rig = [c for c in self.system.connections if c.target == self.rig]
        if len(to_rig) != 1 or to_rig[0].target_variable != "V":
            raise UserError(f"the lab's wiring needs exactly one connection into {self.rig}.V")
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
            if name != self.rig:
                sub.add(name, component.fmu, component.start_values)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        log = RunLog(self.out_dir / "rig_log.csv", LOG_COLUMNS, flush_every=50)
        self.log_path = log.path
        status = 1
        last_seq = 0
        master = Master(sub)
        quiet = contextlib.ExitStack()
        try:
            master.initialize(0.0, self.stop_time)
            self._wire(master)
            sup, ctrl = master.instances["supervisor"], master.instances["controller"]
            encoders = Encoders(self.identity)
            watch = EncoderWatch(self.period)
            link = self.link
            quiet.enter_context(no_garbage_collection())
            link.stream(True)
            swing_up = bool(self.system.components["supervisor"].start_values.get("swing_up"))
            self.announce("streaming: press s to start, p to pause, e to end (r re-arms after a trip); " + (
                "hold the seesaw level by hand, press s and let go: the controller has it" if self.seesaw else
                "s swings the pendulum up from hanging, the controller takes it inside the catch window" if swing_up else
                "raise the pendulum by hand, the controller takes it inside the capture window"))
            angle_in, x_in = (f"{self.rig}.{name}" for name in RIG_SIGNALS[self.rig])
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
                values[angle_in] = theta
                values[x_in] = x
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
                if command == COMMANDS["start"] and self.seesaw and STATES.get(new_state) in ("idle", "tripped"):
                    # (the supervisor's start rule: level_start; its own log is off in the lab)
                    self.announce(f"[{t:8.3f} s] start refused: the seesaw's tilt is {math.degrees(theta):+.1f} deg; hold it level, then press s")
                alpha = self.upright(theta)
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
                wrong = watch.update(x, theta, sample.voltage_mv / 1000.0, running=state == RUNNING)
                if wrong:
                    raise RigFault(f"{wrong}; check its cable and coupling")
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
        except Terminated as exc:
            self.reason, status = f"ended by {exc.signal} (a closed terminal, 'timeout' or a process manager)", exc.exit_status
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
            quiet.close()
            log.close()
            master.close()
            self.timing.crc_errors = self.link.reader.errors  # (self.: an error before the loop leaves no local)
            self.timing.lost_frames = self.link.reader.lost
        self.status = status
        self.announce(f"motor off; session ended: {self.reason}")
        return self.reason, status

    def _check_rig_after_silence(self) -> None:
        """Samples stopped: a restarted rig answers with a new boot id; a dead link does not answer."""
        raise self.link.silence_cause(SILENCE * 1e3)


class RigFault(Exception):
    """The rig or an FMU reported a fault during the session."""


def rig_columns(log_path: Path, Lp: float, *, seesaw: bool = False) -> dict[str, np.ndarray]:
    """The run's columns (SPEC §7 names) from the streamed rig log.

    The rig measures no speed: ``xdot`` is the cart position's central difference over 10 ms, and
    ``alpha`` is the measured angle (the rig has no other). The seesaw's run has the seesaw's columns
    (:data:`pendulab.analysis.results.SEESAW_COLUMNS`): ``theta`` and ``theta_measured`` are its measured tilt,
    ``x`` and ``x_measured`` the cart encoder.
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
    if seesaw:
        return {"t": t, "x": x, "xdot": xdot, "theta": alpha, "theta_measured": alpha, "x_measured": x,
                **{name: np.asarray(data[name], dtype=float) for name in ("voltage_command", "voltage", "supervisor_state", "latency_ms")}}
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


#: After the hand lets go, the controller's catch is not a poke: the poke is looked for from this long after.
RELEASE_SETTLE = 0.2
#: The verdict of a session that ended before its poke (the one verdict in pendulab.analysis maps it).


def hand_release_time(columns: dict[str, np.ndarray], *, at_start: bool = False) -> float | None:
    """When the hand let go of the pendulum: the first sample at which the controller runs and the motor acts.

    The person holds the raised pendulum until the controller has it, which is when the rig first
    applies a voltage in the running state (the emulator releases it then too). The seesaw's hand
    (``at_start``) lets go at the start: the first running sample.
    """
    running = columns["supervisor_state"] == RUNNING
    acting = np.flatnonzero(running if at_start else running & (np.abs(columns["voltage"]) > 0))
    return float(columns["t"][acting[0]]) if acting.size else None


def lab_metrics(columns: dict[str, np.ndarray], *, q_alpha: float, end_reason: str, ended_early: bool,
                seesaw: bool = False) -> dict[str, Any]:
    """The metrics of a rig session from its columns (:func:`rig_columns`).

    The response is read from the poke, found after the hand let go (:func:`hand_release_time`) and
    before any cut (the seesaw's: its tilt, released at the start): the supervisor's trip, or the end of a session that ended by itself
    (``ended_early``: the rig's watchdog, a fault, a lost link, a signal). A session cut before its
    poke has no response: every metric is None, with ``not_reported`` saying why, and the verdict (of
    :mod:`pendulab.analysis.verdict`, like every run's) ``cut`` before the poke.

    Examples
    --------
    >>> t = np.arange(0, 0.92, 0.001)
    >>> cols = {"t": t, "alpha": 0.01 * np.sin(20 * t), "xdot": 0 * t, "voltage": 1 + 0 * t,
    ...         "supervisor_state": np.full(t.size, float(RUNNING))}
    >>> m = lab_metrics(cols, q_alpha=0.0015, end_reason="the rig's watchdog tripped", ended_early=True)
    >>> m["verdict"]["headline"], m["stable"], m["overshoot_percent"], m["safety_cut_time_s"]
    ("CUT at t = 0.919 s before the poke: the rig's watchdog tripped; there is no response to measure", False, None, 0.919)
    """
    from pendulab.analysis.compare import detect_poke
    from pendulab.analysis.metrics import METRIC_KEYS
    from pendulab.analysis.verdict import Limits, assess, cut_before_poke

    t = columns["t"]
    cut = cut_reason = None
    tripped = np.flatnonzero(columns["supervisor_state"] == TRIPPED)
    if tripped.size:
        cut, cut_reason = float(t[tripped[0]]), "the supervisor tripped"
    elif ended_early and t.size:
        cut, cut_reason = float(t[-1]), end_reason
    release = hand_release_time(columns, at_start=seesaw) if t.size else None
    poke = None
    if release is not None:
        poke = detect_poke(t, columns["alpha"], q_alpha=q_alpha, after=release + RELEASE_SETTLE, before=cut, long_pulse=seesaw)
    last = cut if cut is not None else (float(t[-1]) if t.size else 0.0)
    metrics: dict[str, Any]
    if poke is not None and t.size > 10 and poke < last - 0.05:
        try:
            limits = Limits(q_alpha=q_alpha)
            if seesaw:  # judged as a seesaw: its limits (tilt, cart, tilt stop) with the rig's tilt step
                from pendulab.cosim.seesaw import verdict_limits

                limits = replace(verdict_limits(), q_alpha=q_alpha)
            # The verdict reads the run from the hand's release: before it the pendulum hangs or is held (the log can
            # start with it hanging, |alpha| about pi), which is not a fall.
            held = t >= release
            judged = {k: (v[held] if isinstance(v, np.ndarray) and v.shape[:1] == t.shape else v) for k, v in columns.items()}
            metrics, _ = assess(judged, poke_start=poke, limits=limits, safety_cut_time=cut,
                                end_reason=end_reason if ended_early and not tripped.size else None, plant="seesaw" if seesaw else "pendulum")
        except Exception as exc:  # noqa: BLE001 - a log too short or odd for metrics still gets its files
            metrics = {"error": f"metrics could not be computed: {exc}"}
    elif cut is not None:
        metrics, _ = cut_before_poke(cut, str(cut_reason), float(t[-1]))
        poke = None
    else:
        metrics = {key: None for key in METRIC_KEYS}
        metrics["error"] = ("no poke found in the measured angle while the controller held the pendulum"
                            + ("" if release is not None else " (the motor never acted with the controller running)"))
    if cut is not None and not metrics.get("safety_cut_reason"):
        metrics["safety_cut_reason"] = cut_reason
    metrics["hand_release_s"] = release
    metrics["poke_start_detected_s"] = poke
    metrics["end_reason"] = end_reason
    return metrics


def write_lab_results(session: LabSession, *, Lp: float, q_alpha: float, meta: dict[str, Any], round_trips: list[float]) -> tuple[dict, dict]:
    """run.mat, run.csv, metrics.json and timing.json from the streamed log."""
    from pendulab.analysis.results import write_results
    from pendulab.outputs import atomic_write

    columns = rig_columns(session.log_path, Lp, seesaw=session.seesaw)
    t = columns["t"]
    # The seesaw's response is its tilt's (the metrics are the pendulum's, of the angle the loop holds).
    angle = {**columns, "alpha": columns["theta"]} if session.seesaw else columns
    metrics = lab_metrics(angle, q_alpha=q_alpha, end_reason=session.reason, ended_early=session.status != 0, seesaw=session.seesaw)
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
