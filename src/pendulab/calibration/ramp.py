"""The ramp test (SPEC §8): find where the cart breaks away, how it slows down and sticks again.

One iteration, for each direction (+ then -):

1. **centre** the cart: a P loop on the position (with a slow integral that breaks stiction) until the cart rests within ``centre_tolerance`` of 0;
2. **slow ramp**: the voltage rises from 0 at ``ramp_rate`` until the cart breaks away (``F1``) and then moves ``motion_distance`` freely;
3. **release**: the voltage drops to 0 and the cart coasts to a stop; the decay of its speed gives ``v2``, ``B`` and ``v1``;
4. **probe**: a steep ramp (``probe_rate``) from rest to ``probe_factor`` times the breakaway voltage, held until the cart has moved
   ``probe_distance``, then released: only a force rising faster than the cart can follow shows ``F2`` (a slow ramp leaves the drag by speed first).

Whenever the cart passes ``track_limit`` the voltage drops to 0 and the next centring backs it off. Ctrl-C (or any ``KeyboardInterrupt``, also from a
callback or a signal) and a rig that ends the test (:class:`~pendulab.calibration.rig.RigEnded`) switch the motor off and return what was measured:
``log.interrupted`` is then true, ``log.end_reason`` says why, and ``log.iterations_done`` iterations finished by ``log.iterations_done_at``.

Examples
--------
>>> from pendulab.calibration.rig import VirtualRig
>>> from pendulab.calibration.ramp import run_ramp_test
>>> with VirtualRig(x0=0.04) as rig:
...     log = run_ramp_test(rig, iterations=1)
>>> log.duration > 5, log.interrupted
(True, False)
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import Callable

import numpy as np

from pendulab.calibration.logs import RampLog
from pendulab.calibration.rig import Rig, RigEnded
from pendulab.errors import CalibrationError


@dataclass(frozen=True)
class RampSettings:
    """Knobs of the ramp test (SI units: V, V/s, m, s)."""

    ramp_rate: float = 1.0
    probe_rate: float = 100.0
    probe_factor: float = 2.5
    max_voltage: float = 6.0
    motion_distance: float = 0.08
    probe_distance: float = 0.03
    breakaway_distance: float = 1e-4
    track_limit: float = 0.30
    centre_tolerance: float = 0.01
    centre_gain: float = 200.0
    centre_integral: float = 400.0
    centre_max_voltage: float = 3.0
    still_time: float = 0.3
    still_band: float = 1e-5  # less than one IP02 encoder step: 'still' means no count for still_time
    phase_timeout: float = 15.0

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise CalibrationError(f"ramp setting {name}={value!r} must be a positive number")


class _Stopped(Exception):
    """A phase could not finish (timeout); the iteration goes on with the next phase."""


class _Run:
    """Bookkeeping of one ramp test: applies voltages, records the log, checks the track limits."""

    def __init__(self, rig: Rig, settings: RampSettings) -> None:
        self.rig, self.s = rig, settings
        self.t, self.V, self.x = [], [], []  # the log's columns (floats)
        self.events: list[tuple[float, str]] = []
        self.position = rig.reset()

    def note(self, text: str) -> None:
        self.events.append((self.rig.time, text))

    def apply(self, voltage: float) -> float:
        """Record ``(t, V, x)`` and apply ``voltage`` for one period; returns the new position."""
        self.t.append(self.rig.time)
        self.V.append(voltage)
        self.x.append(self.position)
        self.position = self.rig.step(voltage)
        return self.position

    def steps(self, seconds: float) -> int:
        return max(1, int(round(seconds / self.rig.period)))

    def is_still(self) -> bool:
        n = self.steps(self.s.still_time)
        recent = self.x[-n:] + [self.position]
        return len(self.x) >= n and max(recent) - min(recent) <= self.s.still_band

    def centre(self) -> None:
        """P loop on x, with an integral that only acts while the cart is stuck off centre."""
        s, dt = self.s, self.rig.period
        integral = 0.0
        self.note("centring")
        for _ in range(self.steps(s.phase_timeout)):
            x = self.position
            if abs(x) <= s.centre_tolerance:
                integral = voltage = 0.0
                if self.is_still():
                    self.note(f"centred at x={x * 1e3:.2f} mm")
                    return
            else:
                integral += x * dt
                voltage = float(np.clip(-s.centre_gain * x - s.centre_integral * integral, -s.centre_max_voltage, s.centre_max_voltage))
            self.apply(voltage)
        self.note("timeout centring the cart")
        raise CalibrationError(f"the cart could not be centred within {s.phase_timeout:g} s (x={self.position * 1e3:.1f} mm); check the rig")

    def push(self, direction: int, phase: str, rate: float, target: float, distance: float) -> float | None:
        """Centre the cart, ramp (``phase``) at ``rate`` towards ``direction*target``, stop after moving ``distance`` past breakaway, release.

        Returns the voltage at breakaway (``None`` if the cart never moved), once the cart is still again.
        """
        s, dt = self.s, self.rig.period
        sign = "+" if direction > 0 else "-"
        self.centre()
        self.note(f"{phase} {sign}")
        start = self.position
        breakaway_at: float | None = None
        voltage, held = 0.0, 0
        for _ in range(self.steps(s.phase_timeout)):
            voltage = direction * min(abs(voltage) + rate * dt, target)
            if abs(self.position) >= s.track_limit and np.sign(voltage) == np.sign(self.position):  # pushing past a limit
                self.note(f"track limit at x={self.position * 1e3:.1f} mm: voltage off")
                break
            x = self.apply(voltage)
            moved = direction * (x - start)
            if breakaway_at is None and moved >= s.breakaway_distance:
                breakaway_at = voltage
                self.note(f"breakaway {sign} at V={voltage:.3f}")
                start = x
            elif breakaway_at is not None and moved >= distance:
                break
            if abs(voltage) >= target:
                held += 1
                if held > self.steps(0.5):
                    if breakaway_at is None:
                        self.note(f"no breakaway up to {target:g} V")
                    break
        self.note(f"release {sign}")
        for _ in range(self.steps(s.phase_timeout)):  # motor off until the cart has not moved for still_time
            self.apply(0.0)
            if self.is_still():
                return breakaway_at
        self.note("timeout waiting for the cart to stop")
        raise _Stopped


def run_ramp_test(
    rig: Rig,
    iterations: int = 5,
    *,
    on_iteration: Callable[[int, int], None] | None = None,
    on_progress: Callable[[str], None] | None = None,
    **overrides: float,
) -> RampLog:
    """Run the ramp test on ``rig`` and return the log (SPEC §8).

    Parameters
    ----------
    rig : Rig
        The real rig (HIL) or a :class:`~pendulab.calibration.rig.VirtualRig`.
    iterations : int
        Number of iterations (default 5); each ramps in both directions.
    on_iteration : callable(i, n), optional
        Called at the start of iteration ``i`` (1-based) of ``n``.
    on_progress : callable(str), optional
        Short progress messages (breakaways, track limits).
    **overrides : float
        Fields of :class:`RampSettings` (rates, distances, limits) to change from their defaults.

    Returns
    -------
    RampLog
        ``t``, ``V``, ``x``; ``events`` lists what happened; ``interrupted`` is true after Ctrl-C.
    """
    if not isinstance(iterations, int) or iterations < 1:
        raise CalibrationError(f"iterations={iterations!r} must be a whole number >= 1")
    unknown = sorted(set(overrides) - set(RampSettings.__dataclass_fields__))
    if unknown:
        raise CalibrationError(f"unknown ramp setting {unknown[0]!r}; known ones are {', '.join(RampSettings.__dataclass_fields__)}")
    settings = RampSettings(**overrides)
    progress = on_progress or (lambda text: None)
    run = _Run(rig, settings)
    interrupted, reason, done, done_at = False, "", 0, 0.0
    try:
        for i in range(1, iterations + 1):
            run.note(f"iteration {i}")
            if on_iteration:
                on_iteration(i, iterations)
            for direction, sign in ((1, "+"), (-1, "-")):
                try:
                    breakaway = run.push(direction, "slow ramp", settings.ramp_rate, settings.max_voltage, settings.motion_distance)
                    if breakaway is None:
                        progress(f"iteration {i} {sign}: no breakaway up to {settings.max_voltage:g} V")
                        continue
                    progress(f"iteration {i} {sign}: breakaway at {breakaway:.3f} V")
                    target = min(settings.max_voltage, settings.probe_factor * abs(breakaway))
                    run.push(direction, "probe", settings.probe_rate, target, settings.probe_distance)
                except _Stopped:
                    progress(f"iteration {i} {sign}: a phase timed out; going on")
            done, done_at = i, rig.time
        run.centre()
    except (KeyboardInterrupt, RigEnded) as exc:
        # Ctrl-C, a signal (pendulab.hil.realtime.Terminated) or the rig itself: keep what was measured.
        interrupted, reason = True, str(exc) or "interrupted (Ctrl-C)"
        run.note(f"ended early: {reason}; motor off")
        progress(f"{reason}: motor off, keeping what was measured ({done} of {iterations} iteration(s) finished)")
    finally:
        with contextlib.suppress(Exception):  # the log matters more than a failing stop on a broken link
            rig.stop()
    if len(run.t) < 2:
        raise CalibrationError("the ramp test was stopped before anything was measured")
    return RampLog(
        t=np.asarray(run.t),
        V=np.asarray(run.V),
        x=np.asarray(run.x),
        source=getattr(rig, "description", "rig"),
        interrupted=interrupted,
        events=tuple(run.events),
        end_reason=reason,
        iterations_done=done,
        iterations_done_at=done_at if interrupted else float(run.t[-1]),
    )
