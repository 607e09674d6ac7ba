"""The real rig (over the serial link) as a :class:`~pendulab.calibration.rig.Rig` for the ramp test.

The calibration procedure (:func:`pendulab.calibration.ramp.run_ramp_test`) is the same code as on
the virtual rig; here each ``step`` waits for the rig's next sample and answers it, so the rig's
clock paces the test. The commanded voltage reaches the cart N periods later (the link's transport
delay), which the slow ramps do not notice.

Every sample is streamed to a log (``t, V, x, tick``: the voltage the rig reports it applied) as it
arrives, so a crash or any ending keeps what was measured. Whatever ends the test early (a fault, a
restart, the rig's watchdog or track limit, a lost link) raises :class:`~pendulab.calibration.rig.RigEnded`
naming it, after that sample is logged.
"""

from __future__ import annotations

from typing import Any

from pendulab.calibration.rig import Rig, RigEnded
from pendulab.hil import protocol as P
from pendulab.hil.link import Encoders, LinkLost, RigLink, RigRestarted

#: Columns of the streamed ramp-test log ('pendulab fit' reads t, V, x).
LOG_COLUMNS = ("t", "V", "x", "tick")

#: No sample for this long during the ramp test: the link is lost.
SAMPLE_TIMEOUT = 0.25


class HilRig(Rig):
    """A rig on a :class:`RigLink` (already identified and configured)."""

    def __init__(self, link: RigLink, log: Any = None) -> None:
        if link.identity is None:
            raise ValueError("identify the rig first")
        self.link = link
        self.period = link.identity.period_us * 1e-6
        self.description = f"rig at {link.name}"
        self._encoders = Encoders(link.identity)
        self._pending: P.Sample | None = None
        self._k = 0
        self._first = True
        self._streaming = False
        #: The voltage the rig applied from each sample's tick on (its own report), one per sample.
        self.applied: list[float] = []
        #: A :class:`~pendulab.analysis.results.RunLog` with :data:`LOG_COLUMNS`, or None.
        self.log = log
        self._last_tick: int | None = None

    @property
    def time(self) -> float:
        return self._k * self.period

    def _sample(self) -> tuple[P.Sample, float]:
        """The next sample, logged, and the cart's position; :class:`RigEnded` when the rig ended the test."""
        try:
            item = self.link.next_sample(SAMPLE_TIMEOUT)
        except LinkLost as exc:  # the port itself failed (closed, unplugged): an ending like the others
            raise RigEnded(str(exc)) from None
        if item is None:
            cause = self.link.silence_cause(SAMPLE_TIMEOUT * 1e3)
            raise RigEnded(str(cause) if isinstance(cause, RigRestarted) else f"{cause} (no sample from {self.link.name})")
        sample: P.Sample = item[0]  # type: ignore[assignment]
        if self._last_tick is not None and sample.tick <= self._last_tick:
            raise RigEnded(f"the rig restarted (its tick went back from {self._last_tick} to {sample.tick})")
        self._last_tick = sample.tick
        x, _ = self._encoders.update(sample)
        applied = sample.voltage_mv / 1000.0
        if self.log is not None:
            self.log.append((self._k * self.period, applied, x, sample.tick))
        if sample.status & P.ST_FAULT:
            raise RigEnded("the rig reports a fault (amplifier or encoder); check the rig")
        # A flag latched before this test is cleared by the first command, which acts N periods later.
        settled = self._k > getattr(self.link, "delay", 1) + 1
        if sample.status & P.ST_WATCHDOG and settled:
            raise RigEnded("the rig's watchdog tripped: the host's answers stopped reaching it in time")
        if sample.status & P.ST_LIMIT and settled:
            raise RigEnded("the rig's own track limit cut the motor; centre the cart and start again")
        self._x = x
        return sample, applied

    def reset(self) -> float:
        if not self._streaming:
            self.link.stream(True)
            self._streaming = True
        self._k = 0
        self._pending, applied = self._sample()
        self.applied = [applied]
        return self._x

    def step(self, voltage: float) -> float:
        if self._pending is None:
            self.reset()
        assert self._pending is not None
        try:
            self.link.command(self._pending.seq, voltage, enable=True, clear=self._first)
        except LinkLost as exc:
            raise RigEnded(str(exc)) from None
        self._first = False
        self._k += 1
        self._pending, applied = self._sample()
        self.applied.append(applied)
        return self._x

    def acting_voltages(self, n: int):
        """The voltage that acted over each of the first ``n`` periods (the commands arrive N periods late).

        A ramp log records the voltage it commanded at each step; on the rig that voltage acts N periods
        later. The friction extraction needs the voltage that moved the cart: the rig's own report.
        """
        import numpy as np

        return np.asarray(self.applied[:n], dtype=float)

    def stop(self) -> None:
        if self._pending is not None:
            self.link.command(self._pending.seq, 0.0, enable=False)

    def close(self) -> None:
        self.link.motor_off(self._pending.seq if self._pending is not None else 0)
        self._streaming = False
