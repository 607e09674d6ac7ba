"""The real rig (over the serial link) as a :class:`~pendulab.calibration.rig.Rig` for the ramp test.

The calibration procedure (:func:`pendulab.calibration.ramp.run_ramp_test`) is the same code as on
the virtual rig; here each ``step`` waits for the rig's next sample and answers it, so the rig's
clock paces the test. The commanded voltage reaches the cart N periods later (the link's transport
delay), which the slow ramps do not notice.
"""

from __future__ import annotations

from pendulab.calibration.rig import Rig
from pendulab.errors import CalibrationError
from pendulab.hil import protocol as P
from pendulab.hil.link import Encoders, LinkLost, RigLink

#: No sample for this long during the ramp test: the link is lost.
SAMPLE_TIMEOUT = 0.25


class HilRig(Rig):
    """A rig on a :class:`RigLink` (already identified and configured)."""

    def __init__(self, link: RigLink) -> None:
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

    @property
    def time(self) -> float:
        return self._k * self.period

    def _sample(self) -> P.Sample:
        item = self.link.next_sample(SAMPLE_TIMEOUT)
        if item is None:
            raise CalibrationError(f"link lost: no sample from {self.link.name} for {SAMPLE_TIMEOUT * 1e3:.0f} ms; the motor is off")
        sample: P.Sample = item[0]  # type: ignore[assignment]
        if sample.status & P.ST_FAULT:
            raise CalibrationError("the rig reports a fault; the motor is off")
        # A flag latched before this test is cleared by the first command, which acts N periods later.
        settled = self._k > getattr(self.link, "delay", 1) + 1
        if sample.status & P.ST_WATCHDOG and settled:
            raise CalibrationError("the rig's watchdog tripped (answers stopped reaching it); the motor is off")
        return sample

    def reset(self) -> float:
        if not self._streaming:
            self.link.stream(True)
            self._streaming = True
        self._k = 0
        self._pending = self._sample()
        self.applied = [self._pending.voltage_mv / 1000.0]
        x, _ = self._encoders.update(self._pending)
        return x

    def step(self, voltage: float) -> float:
        if self._pending is None:
            self.reset()
        assert self._pending is not None
        try:
            self.link.command(self._pending.seq, voltage, enable=True, clear=self._first)
        except LinkLost as exc:
            raise CalibrationError(str(exc)) from None
        self._first = False
        self._pending = self._sample()
        if self._pending.status & P.ST_LIMIT and self._k > getattr(self.link, "delay", 1) + 1:
            raise CalibrationError("the rig's own track limit cut the motor; centre the cart and start again")
        self._k += 1
        self.applied.append(self._pending.voltage_mv / 1000.0)
        x, _ = self._encoders.update(self._pending)
        return x

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
