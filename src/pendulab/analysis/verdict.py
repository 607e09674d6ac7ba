"""The verdict of a poke run: did the pendulum stay up, and should the student trust it on the rig?

One verdict, computed here from a run's columns and the supervisor's record, for every caller (the
``simulate`` command, the GUI, ``lab``, ``compare``). Its **outcome** is one of

* ``balanced`` -- the pendulum stayed up until the end of the run;
* ``cut`` -- the supervisor cut the motor for a reason other than the angle (the track limit, a
  non-finite command or measurement; on the rig also a lost link), with the pendulum still up;
* ``fell`` -- the angle passed the supervisor's angle limit (or, without a supervisor, 90°);
* ``not tested`` -- the run had no disturbance (a poke of size or length 0): any controller
  "stays up" then, so nothing was tested.

Beside the outcome, a list of **warnings**, each with the number that raised it and what to try:

========================  =========================================================================
warning                   raised when (after the poke, up to the end or the cut)
========================  =========================================================================
``saturation``            the applied voltage is at the amplifier's limit (``V_max``, 10 V) for
                          more than :data:`SATURATION_SHARE` of the time
``chattering``            the voltage switches between ``+V_big`` and ``-V_big`` more than
                          :data:`CHATTER_RATE` times a second, with ``V_big`` =
                          :data:`CHATTER_LEVEL` of ``V_max``
``drift``                 the cart's speed over the last :data:`DRIFT_WINDOW` s would take it to the
                          supervisor's track limit within :data:`DRIFT_HORIZON` s after the run
``small margin``          the largest ``|alpha|`` exceeds :data:`ANGLE_MARGIN` of the angle limit, or
                          the largest ``|x|`` exceeds :data:`TRACK_MARGIN` of the track limit
========================  =========================================================================

Where the thresholds come from
------------------------------
Every threshold is a fraction of one of the rig's own limits (``PlantParameters.V_max``, the
supervisor's ``alpha_max`` and ``x_max``), so it moves with them:

* **Saturation, 5 % of the time.** At the voltage limit the loop is open: the controller asks for more
  than the amplifier gives, and the linear design (root locus, margins) no longer describes the loop.
  A hard poke saturates for a few tens of milliseconds while the loop catches the pendulum (the demo
  under the lab's 220 rad/s² poke: 1 %); 5 % of a 5 s run is 0.2 s -- ten times the cart's electrical
  and mechanical time constant (the cart pole of alpha/V at -16 rad/s, 60 ms) -- which no poke
  response needs.
* **Chattering: more than 10 sign changes a second between ±25 % of V_max.** 2.5 V is about three
  times the voltage that breaks the cart free of its static friction (``F1·Rm·r_mp/(Kg·Kt)``, 0.87 V
  with the lab's friction), so each switch really moves the cart. 10 changes a second is a 5 Hz square
  wave, twice the cart's bandwidth (16 rad/s, 2.6 Hz): the voltage changes faster than the cart can
  follow, which shakes the cart and heats the motor rather than move it. The friction and
  quantization limit cycle of a good design (the demo: ±0.7° at 10 rad/s, under 2 V) stays below both.
* **Drift: the track limit within 20 s after the run.** A controller on the angle alone cannot see
  the cart's position (``alpha/V`` has a zero at s = 0), so a cart speed left at the end of a run
  carries on. A student's poke test on the rig is the 5 s run plus about 15 s of watching, the 20 s
  that ``bench/verdict.py`` checks the verdict against; the speed is extrapolated as constant, and
  the horizon has a third more than those 15 s for drifts that speed up (in the bench, a drift
  predicted to reach the limit 16.8 s after a 5 s run reached it after 13 s). Speeds below one
  cart-encoder step per window are not a trend.
* **Small margin: ``|alpha|`` beyond half the angle limit, ``|x|`` beyond 75 % of the track limit.** On the
  rig the poke is a hand's tap and varies by about a factor of two; a response that used more than
  half the angle limit would be cut by a tap twice as hard. The cart's excursion is mostly drift (not
  proportional to the poke), so its margin is the last quarter of the track limit (10 cm of 40 cm).

``bench/verdict.py`` checks these choices against the outcome of 20 s runs (the issue's Must show 3).

The seesaw
----------
A seesaw run (``plant="seesaw"``: the tilt ``theta`` where the pendulum has ``alpha``, the tap as its
poke) is judged by the same rules with the seesaw's limits (the supervisor's tilt limit, 10°, and cart
limit, 0.35 m; :data:`pendulab.cosim.seesaw.SUPERVISOR_LIMITS`) and told in its own words:

* ``balanced`` is **held level**: the tilt came back within :data:`TILT_BAND` (2°) of level after the
  tap and stayed there for the last :data:`TILT_HOLD` s of the run (Quanser's lab asks for 2° within
  3 s of a 5° tap); a seesaw held up but still beyond 2° gets the warning ``unsettled``;
* ``fell``: the tilt passed the supervisor's limit (the motor is cut, and the seesaw then comes to rest
  on its tilt stop, 11.5°: the headline says when it hit it) or reached the tilt stop itself;
* ``cut``: the cart reached the track limit with the seesaw still up.

Its measures (in ``metrics.json`` too): the tap's peak tilt and when it came, the time the tilt took to
settle within 2°, the largest tilt over the last second (:data:`RESIDUAL_WINDOW`) and the cart's
largest excursion; the friction and quantization limit cycle is the SPEC's
``limit_cycle_amplitude_rad`` of the tilt (it appears once the tilt has converged: a 20 s run).
The small-margin warning reads the tilt against :data:`TILT_MARGIN` (3/4) of its limit instead of half:
Quanser's lab prescribes the tap (about 5°), so it varies less than a free poke of the pendulum, and
a response beyond 3/4 of the limit is cut by a tap a third harder. The drift is the cart's trend over
:data:`SEESAW_DRIFT_WINDOW` (2 s, the held seesaw's cart keeps swinging in the friction limit cycle), judged
only in a run that goes on that long after the tilt settled.

Examples
--------
>>> import numpy as np
>>> t = np.linspace(0.0, 5.0, 5001)
>>> cols = {"t": t, "x": np.zeros_like(t), "alpha": 0.01 * np.exp(-t) * np.sin(9 * t),
...         "voltage": np.zeros_like(t), "supervisor_state": np.full_like(t, 2.0)}
>>> v = judge(cols, poke_start=1.0)
>>> v.outcome, v.warnings, v.headline()
('balanced', (), 'BALANCED for 5 s with no warning')
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Mapping

import numpy as np

from pendulab.fmu.models.supervisor.config import RECENTRE_X_ON, TRIP_ANGLE, TRIP_CATCH, TRIP_REASONS, TRIP_TRACK, TRIPPED

#: Share of the time after the poke at the voltage limit that raises the saturation warning.
SATURATION_SHARE = 0.05
#: "Large" voltage of the chattering measure, as a fraction of ``V_max``.
CHATTER_LEVEL = 0.25
#: Sign changes of the voltage (between ±CHATTER_LEVEL·V_max) per second that raise the chattering warning.
CHATTER_RATE = 10.0
#: Window at the end of the run over which the cart's trend (speed) is fitted (s).
DRIFT_WINDOW = 1.0
#: The drift warning: the cart would reach the track limit within this long after the run (s).
DRIFT_HORIZON = 20.0
#: Small margin: the largest ``|alpha|`` beyond this fraction of the angle limit ...
ANGLE_MARGIN = 0.5
#: ... or the largest ``|x|`` beyond this fraction of the track limit.
TRACK_MARGIN = 0.75
#: Without a supervisor an angle beyond this (rad) means the pendulum fell.
FALLEN_ANGLE = math.pi / 2

#: The plants a verdict knows (their words differ; the rules are the same).
PLANTS = ("pendulum", "seesaw")
#: The seesaw is held level when its tilt comes back within this of level (rad): Quanser's 2°.
TILT_BAND = math.radians(2.0)
#: ... and stays inside the band for at least this long before the end of the run (s): longer than
#: a swing through the band takes (the demo's closed loop swings at about 2.5 rad/s: a 3° swing
#: crosses the 2° band in 0.6 s).
TILT_HOLD = 1.0
#: The seesaw's small margin: the largest tilt beyond this fraction of the tilt limit.
TILT_MARGIN = 0.75
#: Window at the end of a seesaw run over which the residual tilt is read (s).
RESIDUAL_WINDOW = 1.0
#: The seesaw's drift window (s): its state feedback holds the cart, which keeps swinging a few mm in the
#: friction limit cycle (periods of 1.3 to 1.7 s in the demo with and without quantization); a trend
#: fitted over 1 s reads a swing's half as a drift (a false "19 s to the track end" in a 20 s demo run
#: with ideal encoders), over 2 s it does not (220 s). The drift is judged only when the run goes on for this
#: long after the tilt settled: before that the cart is still in the tap's response (in a 3 s demo run its
#: return from 17 cm read as "the track end 5.5 s after the run").
SEESAW_DRIFT_WINDOW = 2.0

#: The warnings, worst first (the order of the first line and of the list under it).
WARNING_ORDER = ("chattering", "saturation", "unsettled", "drift", "small margin")
#: Warnings named on the first line; the others are listed under it.
HEADLINE_WARNINGS = 2

#: Trip reasons that mean the pendulum fell (the others cut the motor with the pendulum still up).
FELL_REASONS = (TRIP_REASONS[TRIP_ANGLE], TRIP_REASONS[TRIP_CATCH])

#: The outcomes, and their words on the first line.
OUTCOMES = ("balanced", "cut", "fell", "not tested")

#: ``supervisor_state`` code of a latched trip, and ``trip_reason`` codes -> names: the Supervisor FMU's own.
_TRIPPED = TRIPPED
_TRIP_NAMES = TRIP_REASONS
#: What a cut's reason means, in the first line's words.
_CUT_WORDS = {
    "track limit": "the cart reached the track limit",
    "non-finite voltage command": "the controller's voltage command was not finite (the supervisor cut the motor)",
    "non-finite measurement": "a measurement was not finite (the supervisor cut the motor)",
    "link": "the link to the rig was lost (motor off)",
    "rig fault": "the rig reported a fault (motor off)",
}


@dataclass(frozen=True)
class Limits:
    """The rig's limits the verdict measures against (defaults: the lab's rig and supervisor)."""

    V_max: float = 10.0
    alpha_max: float = math.radians(15.0)
    x_max: float = 0.40
    q_alpha: float = 0.001
    q_x: float = 22.75e-6
    #: The seesaw's tilt stop (rad), where it rests when the motor is cut; None for the pendulum.
    angle_stop: float | None = None
    #: Where the supervisor's re-centring engages (m).
    recentre_x_on: float = RECENTRE_X_ON

    @classmethod
    def of(cls, params: Any = None, supervisor: Mapping[str, Any] | None = None) -> "Limits":
        """The limits of plant parameters (``V_max``, encoder steps; the seesaw's ``q_theta`` and
        ``theta_stop``) and supervisor start values.

        Examples
        --------
        >>> from pendulab.model.seesaw import SeesawParameters
        >>> limits = Limits.of(SeesawParameters(), {"alpha_max": math.radians(10), "x_max": 0.35})
        >>> round(math.degrees(limits.angle_stop), 1), limits.x_max
        (11.5, 0.35)
        """
        sup = dict(supervisor or {})
        base = cls()
        seesaw = hasattr(params, "theta_stop")
        values = {
            "V_max": float(getattr(params, "V_max", base.V_max)),
            "q_alpha": float(getattr(params, "q_theta" if seesaw else "q_alpha", base.q_alpha)),
            "q_x": float(getattr(params, "q_x", base.q_x)),
            "alpha_max": float(sup.get("alpha_max", base.alpha_max)),
            "x_max": float(sup.get("x_max", base.x_max)),
            "angle_stop": float(params.theta_stop) if seesaw else None,
            "recentre_x_on": float(sup.get("recentre_x_on", base.recentre_x_on)),
        }
        return cls(**values)


@dataclass(frozen=True)
class Warning:  # noqa: A001 - the verdict's word; shadows the builtin only inside this module
    """One warning: its kind, the number that raised it, what was seen and what to try."""

    kind: str
    value: float
    unit: str
    text: str
    advice: str
    short: str  # the words used on the first line

    def line(self) -> str:
        return f"{self.kind}: {self.text}; {self.advice}"


@dataclass(frozen=True)
class Verdict:
    """Outcome, when and why a run ended early, the warnings, and the numbers behind them."""

    outcome: str
    end_time: float
    cut_reason: str | None = None
    cut_time: float | None = None
    warnings: tuple[Warning, ...] = ()
    measures: dict[str, Any] = field(default_factory=dict)
    plant: str = "pendulum"

    @property
    def clean(self) -> bool:
        """Balanced with no warning: the only verdict shown in green."""
        return self.outcome == "balanced" and not self.warnings

    def headline(self) -> str:
        """The first line a student reads: the outcome and the worst warnings."""
        if self.measures.get("before_poke"):
            return f"CUT at t = {self.cut_time:.3f} s before the poke: {self.cut_reason}; there is no response to measure"
        if self.plant == "seesaw":
            text = self._seesaw_text()
            if self.outcome == "not tested" or (self.outcome == "balanced" and not self.warnings):
                return text
        elif self.outcome == "not tested":
            return "NOT TESTED: the run had no disturbance (a poke of size or length 0), so any controller stays up"
        elif self.outcome == "fell":
            where = {"angle limit": f"the angle passed the {self._angle_limit()} limit",
                     "catch missed": "the swing-up's catch missed"}.get(str(self.cut_reason), "the pendulum fell")
            text = f"FELL at t = {self.cut_time:.3f} s: {where}"
        elif self.outcome == "cut":
            text = f"CUT at t = {self.cut_time:.3f} s: {_CUT_WORDS.get(str(self.cut_reason), f'the session ended early ({self.cut_reason})')}"
            if self.cut_reason == "track limit":
                text += f" ({self.measures.get('x_max', 0.4):.2f} m) with the pendulum still up"
        else:
            text = f"BALANCED for {self.end_time:g} s"
            if not self.warnings:
                return text + " with no warning"
        phrases = self._phrases()
        if not phrases:
            return text
        shown = phrases[:HEADLINE_WARNINGS]
        joined = shown[0] if len(shown) == 1 else ", ".join(shown[:-1]) + " and " + shown[-1]
        more = len(phrases) - len(shown)
        tail = f" ({more} more warning{'s' if more > 1 else ''} below)" if more else ""
        return text + (", but " if self.outcome == "balanced" else "; before that ") + joined + tail

    def _phrases(self) -> list[str]:
        """The warnings' short words, worst first; saturation joins chattering when both are raised."""
        by_kind = {w.kind: w for w in self.warnings}
        phrases = []
        for kind in WARNING_ORDER:
            w = by_kind.get(kind)
            if w is None:
                continue
            if kind == "saturation" and "chattering" in by_kind:
                phrases[0] += f" (at the limit {100 * w.value:.0f} % of the time)"
                continue
            phrases.append(w.short)
        return phrases

    def _angle_limit(self) -> str:
        return f"{math.degrees(self.measures.get('alpha_max', math.radians(15))):.0f}°"

    def _seesaw_text(self) -> str:
        """The seesaw's first line before its warnings: held level (the tap's peak and the settling), fell
        (the tilt limit, the tilt stop), cut (the track), not tested."""
        m = self.measures
        if self.outcome == "not tested":
            return "NOT TESTED: the run had no disturbance (a tap of size or length 0), so any controller holds the seesaw level"
        if self.outcome == "fell":
            stop = f"its {math.degrees(m.get('angle_stop') or 0.0):.1f}° tilt stop"
            if self.cut_reason == "tilt stop":
                return f"FELL at t = {self.cut_time:.3f} s: the seesaw hit {stop}"
            text = f"FELL at t = {self.cut_time:.3f} s: the tilt passed the {self._angle_limit()} limit (the supervisor cut the motor)"
            if m.get("stop_time_s") is not None:
                text += f" and the seesaw hit {stop} at t = {m['stop_time_s']:.3f} s"
            return text
        if self.outcome == "cut":
            text = f"CUT at t = {self.cut_time:.3f} s: {_CUT_WORDS.get(str(self.cut_reason), f'the session ended early ({self.cut_reason})')}"
            if self.cut_reason == "track limit":
                text += f" ({m.get('x_max', 0.35):.2f} m) with the seesaw still up"
                if m.get("tilt_at_cut_rad") is not None:
                    text += f" (tilt {math.degrees(m['tilt_at_cut_rad']):.1f}°)"
            return text
        peak = math.degrees(abs(m.get("peak_tilt_rad") or 0.0))
        settled = m.get("tilt_settling_time_s")
        band = f"{math.degrees(TILT_BAND):.0f}°"
        if settled is None:
            return f"HELD UP for {self.end_time:g} s (the tap tilted it {peak:.1f}°)"
        if settled == 0.0:
            return f"HELD LEVEL for {self.end_time:g} s: the tap tilted it {peak:.1f}°, within {band} throughout"
        return f"HELD LEVEL for {self.end_time:g} s: the tap's {peak:.1f}° tilt settled within {band} in {settled:.2f} s"

    def lines(self) -> list[str]:
        """The headline, then one line per warning (with its advice)."""
        return [self.headline(), *(f"  warning: {w.line()}" for w in self.warnings)]

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON data (``metrics.json``'s ``verdict``; ``plant`` only for a plant other than the pendulum)."""
        data = {
            "outcome": self.outcome,
            "headline": self.headline(),
            "clean": self.clean,
            "end_time_s": self.end_time,
            "cut_reason": self.cut_reason,
            "cut_time_s": self.cut_time,
            "warnings": [asdict(w) for w in self.warnings],
            "measures": dict(self.measures),
        }
        if self.plant != "pendulum":
            data["plant"] = self.plant
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Verdict":
        """The verdict read back from ``metrics.json``."""
        warnings = tuple(Warning(**w) for w in data.get("warnings") or ())
        return cls(
            str(data["outcome"]), float(data.get("end_time_s") or 0.0), data.get("cut_reason"), data.get("cut_time_s"),
            warnings, dict(data.get("measures") or {}), str(data.get("plant") or "pendulum"),
        )


# --------------------------------------------------------------------------------------- judging
def judge(
    columns: Mapping[str, Any],
    *,
    poke_start: float,
    limits: Limits | None = None,
    poke: tuple[float, float] | None = None,
    end_reason: str | None = None,
    recentre: bool = False,
    caught: bool = False,
    plant: str = "pendulum",
) -> Verdict:
    """The verdict of a run from its columns.

    Parameters
    ----------
    columns : mapping of name -> 1-D array
        ``t``, ``alpha`` (the true angle, or the measured one on the rig), and where present ``x``,
        ``voltage`` (applied), ``supervisor_state`` and ``trip_reason`` (Supervisor FMU codes).
    poke_start : float
        When the poke starts (s); the warnings are measured from it on.
    limits : Limits, optional
        The rig's limits (default: the lab's).
    poke : (magnitude, duration), optional
        A poke of size or length 0 gives the outcome ``not tested``.
    end_reason : str, optional
        Why a rig session ended early when the supervisor did not cut (``"link"``, ``"rig fault"``);
        the run is then ``cut`` with this reason at the last sample.
    recentre : bool
        The supervisor's re-centring was on (the drift warning's advice changes).
    caught : bool
        The run starts at a swing-up's catch (``poke_start`` is the catch): the angle is then up to
        the capture window by design, so its margin is not judged (the cart's is).
    plant : {"pendulum", "seesaw"}
        The seesaw's columns have the tilt ``theta`` (and ``theta_measured``) where the pendulum's have
        ``alpha``; ``poke_start`` is its tap. Give it ``Limits.of(SeesawParameters, its supervisor)``.
        Its verdict has its own words and measures (the module's "The seesaw").

    Examples
    --------
    >>> t = np.linspace(0.0, 5.0, 5001)
    >>> tilt = np.where(t < 1.0, 0.0, 0.09 * np.exp(-2 * (t - 1)) * np.sin(8 * (t - 1)))
    >>> cols = {"t": t, "x": 0 * t, "theta": tilt, "voltage": 0 * t, "supervisor_state": np.full_like(t, 2.0)}
    >>> seesaw = Limits(alpha_max=math.radians(10), x_max=0.35, angle_stop=math.radians(11.5))
    >>> judge(cols, poke_start=1.0, limits=seesaw, plant="seesaw").headline()
    "HELD LEVEL for 5 s: the tap's 3.6° tilt settled within 2° in 0.30 s"
    """
    if plant not in PLANTS:
        raise ValueError(f"unknown plant {plant!r}; one of {', '.join(PLANTS)}")
    seesaw = plant == "seesaw"
    if seesaw:
        columns = _tilt_as_angle(columns)
    limits = limits or Limits()
    t = np.asarray(columns["t"], dtype=float)
    alpha = np.asarray(columns["alpha"], dtype=float)
    measures: dict[str, Any] = {"alpha_max": limits.alpha_max, "x_max": limits.x_max, "V_max": limits.V_max}
    end_time = float(t[-1]) if t.size else 0.0

    cut_time, cut_reason = _supervisor_cut(t, columns, limits)
    outcome = "balanced"
    if cut_time is not None:
        outcome = "fell" if cut_reason in FELL_REASONS else "cut"
    else:
        # Without a trip: the seesaw fell when it reached its tilt stop, the pendulum past 90 degrees.
        fallen_at = limits.angle_stop * (1 - 1e-6) if seesaw and limits.angle_stop else FALLEN_ANGLE
        fallen = np.flatnonzero(~np.isfinite(alpha) | (np.abs(np.nan_to_num(alpha, nan=np.inf)) >= fallen_at))
        if fallen.size:
            outcome, cut_time, cut_reason = "fell", float(t[fallen[0]]), ("tilt stop" if seesaw and np.isfinite(alpha[fallen[0]]) else None)
        elif end_reason:
            outcome, cut_time, cut_reason = "cut", end_time, end_reason
    if poke is not None and (poke[0] == 0 or poke[1] <= 0) and outcome == "balanced":
        outcome = "not tested"

    last = cut_time if cut_time is not None else end_time
    window = (t >= poke_start) & (t <= last)
    warnings: list[Warning] = []
    if window.sum() >= 3:
        tw = t[window]
        span = max(float(tw[-1] - tw[0]), 1e-9)
        if "voltage" in columns:
            warnings += _voltage_warnings(tw, np.asarray(columns["voltage"], dtype=float)[window], span, limits, measures)
        if outcome in ("balanced", "not tested"):
            x = np.asarray(columns["x"], dtype=float)[window] if "x" in columns else None
            warnings += _cart_and_margin_warnings(tw, None if caught else alpha[window], x, limits, measures, recentre,
                                                  angle_margin=TILT_MARGIN if seesaw else ANGLE_MARGIN,
                                                  drift_window=SEESAW_DRIFT_WINDOW if seesaw else DRIFT_WINDOW)
    if seesaw:
        x_all = np.asarray(columns["x"], dtype=float) if "x" in columns else None
        warnings = _seesaw_warnings(warnings, t, alpha, x_all, poke_start, cut_time, outcome, limits, measures)
    warnings.sort(key=lambda w: WARNING_ORDER.index(w.kind))
    return Verdict(outcome, end_time, cut_reason, cut_time, tuple(warnings), measures, plant)


def _tilt_as_angle(columns: Mapping[str, Any]) -> dict[str, Any]:
    """A seesaw run's columns with its tilt under the pendulum's angle names (the rules read ``alpha``)."""
    out = dict(columns)
    if "theta" in columns:
        out["alpha"] = columns["theta"]
        out["alpha_measured"] = columns.get("theta_measured", columns["theta"])
    return out


#: The seesaw's advice per warning (its controller is a state feedback: the LQR's weights are its knobs).
_SEESAW_ADVICE = {
    "saturation": "raise R (pendulab lqr --r, the GUI's R) or lower the Q weights, so that K asks for less voltage",
    "chattering": "raise R (pendulab lqr --r) for smaller gains, or lower the derivative filters' frequency",
    "drift": "the state feedback should hold the cart: weight x more (the first Q weight) or keep the integral on",
    "small margin": "weight the tilt more (the second Q weight) for a smaller tilt, or x (the first) for less cart travel",
}


def _seesaw_warnings(warnings: list[Warning], t: np.ndarray, theta: np.ndarray, x: np.ndarray | None, tap_start: float,
                     cut_time: float | None, outcome: str, limits: Limits, measures: dict[str, Any]) -> list[Warning]:
    """The seesaw's measures (tap peak, settling within 2 degrees, residual tilt, the tilt stop, the cart's
    excursion up to the end or the cut) and its words."""
    last = cut_time if cut_time is not None else (float(t[-1]) if t.size else 0.0)
    window = (t >= tap_start) & (t <= last)
    tilt = np.nan_to_num(theta)
    measures["angle_stop"] = limits.angle_stop
    if x is not None and window.any():
        measures.setdefault("largest_x_m", float(np.max(np.abs(np.nan_to_num(x[window])))))
    if window.any():
        i = int(np.flatnonzero(window)[np.argmax(np.abs(tilt[window]))])
        measures["peak_tilt_rad"] = float(tilt[i])
        measures["peak_tilt_time_s"] = float(t[i] - tap_start)
    if limits.angle_stop:
        at_stop = np.flatnonzero(np.abs(tilt) >= limits.angle_stop * (1 - 1e-6))
        measures["stop_time_s"] = float(t[at_stop[0]]) if at_stop.size else None
    if outcome == "cut" and cut_time is not None:
        measures["tilt_at_cut_rad"] = float(np.interp(cut_time, t, tilt))
    measures["tilt_settling_time_s"] = None
    largest = measures.get("largest_alpha_rad")
    harder = f"(a tap about {100 * (limits.alpha_max / largest - 1):.0f} % harder would reach it)" if largest else ""
    if outcome not in ("balanced", "not tested") or not window.any():
        return [_reworded(w, harder) for w in warnings]
    tw, yw = t[window], tilt[window]
    outside = np.flatnonzero(np.abs(yw) > TILT_BAND)
    tail = tw >= tw[-1] - RESIDUAL_WINDOW
    measures["residual_tilt_rad"] = float(np.max(np.abs(yw[tail])))
    if not outside.size:
        measures["tilt_settling_time_s"] = 0.0
    elif outside[-1] + 1 < tw.size and tw[-1] - tw[outside[-1]] >= TILT_HOLD:
        measures["tilt_settling_time_s"] = float(tw[outside[-1] + 1] - tap_start)
    settled_at = None if measures["tilt_settling_time_s"] is None else tap_start + measures["tilt_settling_time_s"]
    if settled_at is None or last - settled_at < SEESAW_DRIFT_WINDOW:
        warnings = [w for w in warnings if w.kind != "drift"]
        measures["drift_not_judged"] = (f"the run ends less than {SEESAW_DRIFT_WINDOW:g} s after the tilt settled: the cart is still "
                                        "in the tap's response (run longer to judge its drift)")
    out = [_reworded(w, harder) for w in warnings]
    if measures["tilt_settling_time_s"] is None:
        band = math.degrees(TILT_BAND)
        end_tilt = math.degrees(float(yw[-1]))
        out.append(Warning(
            "unsettled", float(np.max(np.abs(yw[tail]))), "rad in the last second",
            f"the tilt did not stay within {band:.0f}° of level for the last {TILT_HOLD:g} s of the run "
            f"(it is {end_tilt:+.1f}° at the end, up to {math.degrees(measures['residual_tilt_rad']):.1f}° in the last second)",
            "run longer (--stop-time 10) to see whether it settles, or weight the tilt and its integral more "
            "(the second and fifth Q weights)",
            f"the tilt did not settle within {band:.0f}° ({end_tilt:+.1f}° at the end)",
        ))
    return out


def _reworded(w: Warning, harder: str) -> Warning:
    """A warning in the seesaw's words: its tilt, its tap (``harder``: how much harder a tap reaches the limit), its advice."""
    text = w.text.replace("the angle reached", "the tilt reached").replace("after the poke", "after the tap")
    text = text.replace("(a hand's poke on the rig varies by about a factor of two)", harder)
    return Warning(w.kind, w.value, w.unit, text, _SEESAW_ADVICE.get(w.kind, w.advice), w.short)


def _supervisor_cut(t: np.ndarray, columns: Mapping[str, Any], limits: Limits | None = None) -> tuple[float | None, str | None]:
    """Time and reason of the supervisor's first trip (None, None without one)."""
    reasons = np.asarray(columns["trip_reason"], dtype=float) if "trip_reason" in columns else None
    states = np.asarray(columns["supervisor_state"], dtype=float) if "supervisor_state" in columns else None
    tripped = np.zeros(t.size, dtype=bool)
    if reasons is not None:
        tripped |= reasons > 0
    if states is not None:
        tripped |= states == _TRIPPED
    hits = np.flatnonzero(tripped)
    if not hits.size:
        return None, None
    i = int(hits[0])
    code = 0
    if reasons is not None:
        coded = reasons[hits][reasons[hits] > 0]
        code = int(coded[0]) if coded.size else 0
    if code == 0 and limits is not None:
        # A log without the supervisor's reason (the rig's): read it from the measurements at the trip.
        alpha = np.asarray(columns.get("alpha_measured", columns["alpha"]), dtype=float)
        x = np.asarray(columns["x"], dtype=float) if "x" in columns else np.zeros_like(t)
        near = slice(max(0, i - 2), i + 1)
        if np.any(np.abs(alpha[near]) >= limits.alpha_max * (1 - 1e-6)):
            code = TRIP_ANGLE
        elif np.any(np.abs(x[near]) >= limits.x_max * (1 - 1e-6)):
            code = TRIP_TRACK
    return float(t[i]), _TRIP_NAMES.get(code, "supervisor (reason not recorded)")


def _voltage_warnings(t: np.ndarray, v: np.ndarray, span: float, limits: Limits, measures: dict[str, Any]) -> list[Warning]:
    out: list[Warning] = []
    v = np.nan_to_num(v)
    at_limit = np.abs(v) >= limits.V_max * (1 - 1e-6)
    share = float(np.mean(at_limit))
    measures["saturation_share"] = share
    # Sign changes between +big and -big (hysteresis: a value in between keeps the last side).
    big = CHATTER_LEVEL * limits.V_max
    side = np.where(v > big, 1, np.where(v < -big, -1, 0))
    marked = side[side != 0]
    switches = int(np.count_nonzero(np.diff(marked))) if marked.size > 1 else 0
    rate = switches / span
    measures["voltage_switches_per_s"] = rate
    peak = float(np.max(np.abs(v))) if v.size else 0.0
    if share > SATURATION_SHARE:
        out.append(Warning(
            "saturation", share, "share of the time",
            f"the voltage is at the amplifier's ±{limits.V_max:g} V limit for {100 * share:.0f} % of the time after the poke "
            f"(above {100 * SATURATION_SHARE:.0f} %: the loop is open there and the linear design does not hold)",
            "lower the gain, or slow the controller's fastest pole, until the voltage stays inside the limit",
            f"the voltage is at ±{limits.V_max:g} V {100 * share:.0f} % of the time",
        ))
    if rate > CHATTER_RATE:
        out.append(Warning(
            "chattering", rate, "sign changes per second",
            f"the voltage swings from beyond +{big:g} V to beyond -{big:g} V and back {rate:.0f} times a second, up to ±{peak:.3g} V "
            f"(above {CHATTER_RATE:g}/s the cart cannot follow: on the rig it shakes the cart and heats the motor)",
            "lower the gain until the sampled linear loop is stable (the 'linear model' line), or roll the controller off "
            "sooner (one more filter pole, e.g. a compensator 'none;-80')",
            f"the voltage chatters at ±{peak:.2g} V",
        ))
    return out


def _cart_and_margin_warnings(t: np.ndarray, alpha: np.ndarray | None, x: np.ndarray | None, limits: Limits, measures: dict[str, Any],
                              recentre: bool = False, angle_margin: float = ANGLE_MARGIN,
                              drift_window: float = DRIFT_WINDOW) -> list[Warning]:
    out: list[Warning] = []
    largest_alpha = float(np.max(np.abs(alpha))) if alpha is not None else 0.0
    if alpha is not None:
        measures["largest_alpha_rad"] = largest_alpha
    small: list[str] = []
    if largest_alpha > angle_margin * limits.alpha_max:
        small.append(f"the angle reached {math.degrees(largest_alpha):.1f}° of the {math.degrees(limits.alpha_max):.0f}° limit")
    if x is not None:
        x = np.nan_to_num(x)
        largest_x = float(np.max(np.abs(x)))
        measures["largest_x_m"] = largest_x
        if largest_x > TRACK_MARGIN * limits.x_max:
            small.append(f"the cart reached {largest_x:.3f} m of the {limits.x_max:.2f} m track limit")
        # The cart's trend: a straight line through the last DRIFT_WINDOW s (the seesaw's: SEESAW_DRIFT_WINDOW).
        tail = t >= t[-1] - drift_window
        if tail.sum() >= 3:
            speed, offset = np.polyfit(t[tail] - t[-1], x[tail], 1)
            speed, x_end = float(speed), float(offset)
            measures["cart_end_speed_m_s"] = speed
            measures["cart_end_position_m"] = x_end
            noise = max(limits.q_x, 1e-6) / max(float(t[tail][-1] - t[tail][0]), 1e-9)
            if abs(speed) > noise:
                target = math.copysign(limits.x_max, speed)
                to_limit = max(0.0, (target - x_end) / speed)
                measures["time_to_track_limit_s"] = to_limit
                # With re-centring on, a cart that ends inside the band where it engages is not yet the re-centring's
                # to hold: it engages further out (a swing-up demo ended 0.3 cm from the centre at -3.9 cm/s, just
                # after re-centring had let go, and was warned of a drift that re-centring would catch).
                engaged = not recentre or abs(x_end) >= limits.recentre_x_on
                if to_limit < DRIFT_HORIZON and engaged:
                    out.append(Warning(
                        "drift", to_limit, "s after the run",
                        f"the cart ends at {100 * x_end:+.1f} cm moving at {100 * speed:+.1f} cm/s: it would reach the "
                        f"{limits.x_max:.2f} m track limit about {_seconds(to_limit)} after the run ends if nothing changed",
                        ("re-centring is on but does not hold this drift: a slower drift (move a compensator zero so that the "
                         "cart's speed decays after the poke) or a faster re-centring" if recentre else
                         "the controller sees only the angle, so nothing holds the cart: turn on the supervisor's re-centring "
                         "(simulate --recentre, the GUI's re-centring switch), or run longer (--stop-time 20) to see the cut"),
                        f"the cart is drifting to the track end (about {_seconds(to_limit)} after the run ends)",
                    ))
    if small:
        out.append(Warning(
            "small margin", max(largest_alpha / limits.alpha_max, measures.get("largest_x_m", 0.0) / limits.x_max), "of the limit",
            "; ".join(small) + " (a hand's poke on the rig varies by about a factor of two)",
            "make the response smaller (more gain at the poke's frequencies) or keep the cart nearer the centre",
            "little margin to the supervisor's limits",
        ))
    return out


# ------------------------------------------------------------------------------ metrics + verdict
#: The response metrics that describe a decaying second-order-like swing (SPEC §7).
RESPONSE_METRICS = ("natural_frequency_rad_s", "peak_time_s", "overshoot_percent", "settling_time_s")


def assess(
    columns: Mapping[str, Any],
    *,
    poke_start: float,
    limits: Limits | None = None,
    poke: tuple[float, float] | None = None,
    safety_cut_time: float | None = None,
    end_reason: str | None = None,
    recentre: bool = False,
    caught: bool = False,
    plant: str = "pendulum",
) -> tuple[dict[str, Any], Verdict]:
    """``metrics.json``'s content for a run: the metrics where they mean something, and the verdict.

    The metrics of :func:`pendulab.analysis.metrics.compute_metrics`, then:

    * ``natural_frequency_rad_s``, ``peak_time_s``, ``overshoot_percent`` and ``settling_time_s``
      are ``null`` where they would not describe a decaying response, and ``not_reported`` gives
      the reason for each (the loop chatters; no swing above the encoder's resolution; the swings do
      not decay; cut before the response settled);
    * ``safety_cut_reason``: which limit the supervisor cut at (``null`` without a cut);
    * ``verdict``: :meth:`Verdict.to_dict`; ``stable`` is true exactly when the outcome is ``balanced``;
    * the seesaw's (``plant="seesaw"``; the SPEC's metrics are then its tilt's): :data:`SEESAW_METRICS`,
      each ``null`` with its reason in ``not_reported`` where it does not apply.

    Returns
    -------
    metrics : dict
    verdict : Verdict
    """
    from pendulab.analysis.metrics import compute_metrics

    limits = limits or Limits()
    if plant == "seesaw":
        columns = _tilt_as_angle(columns)
    t = np.asarray(columns["t"], dtype=float)
    verdict = judge(columns, poke_start=poke_start, limits=limits, poke=poke, end_reason=end_reason, recentre=recentre, caught=caught,
                    plant=plant)
    cut = safety_cut_time if safety_cut_time is not None else (verdict.cut_time if verdict.cut_reason is not None else None)
    metrics = compute_metrics(
        t, columns["alpha"], poke_start=poke_start, q_alpha=limits.q_alpha,
        xdot=columns.get("xdot"), safety_cut_time=cut,
    )
    cycle = (metrics.get("limit_cycle_amplitude_rad"), metrics.get("limit_cycle_frequency_rad_s"))
    if cycle[0] is not None and any(w.kind == "chattering" for w in verdict.warnings):
        verdict = _with_limit_cycle(verdict, cycle)
    reasons = _not_reported(metrics, verdict, columns, poke_start, limits)
    for key in reasons:
        metrics[key] = None
    metrics["not_reported"] = reasons
    metrics["stable"] = verdict.outcome == "balanced"
    metrics["safety_cut_reason"] = verdict.cut_reason if verdict.outcome in ("cut", "fell") else None
    if plant == "seesaw":
        metrics.update(_seesaw_metrics(verdict, metrics, reasons))
    metrics["verdict"] = verdict.to_dict()
    return metrics, verdict


#: The seesaw's own metrics (``metrics.json``): the tap's peak tilt, the time the tilt took to come back
#: within :data:`TILT_BAND` of level for good, the largest tilt over the last :data:`RESIDUAL_WINDOW` s,
#: and the cart's largest excursion.
SEESAW_METRICS = ("peak_tilt_rad", "tilt_settling_time_s", "residual_tilt_rad", "max_abs_x_m")


def _seesaw_metrics(verdict: Verdict, metrics: Mapping[str, Any], reasons: dict[str, str]) -> dict[str, Any]:
    """The seesaw's metrics from its verdict's measures; ``reasons`` gains why one is left out."""
    m = verdict.measures
    values = {"peak_tilt_rad": m.get("peak_tilt_rad"), "tilt_settling_time_s": m.get("tilt_settling_time_s"),
              "residual_tilt_rad": m.get("residual_tilt_rad"), "max_abs_x_m": m.get("largest_x_m")}
    ended = {"fell": "the seesaw fell", "cut": "the run was cut"}.get(verdict.outcome)
    band = f"{math.degrees(TILT_BAND):.0f}°"
    why = {
        "peak_tilt_rad": "no sample after the tap",
        "tilt_settling_time_s": (f"{ended} before the tilt settled" if ended else
                                 f"the tilt did not stay within {band} of level for the last {TILT_HOLD:g} s of the run"),
        "residual_tilt_rad": f"{ended}: the residual tilt is read over the last second of a run that holds the seesaw",
        "max_abs_x_m": "no cart position after the tap",
    }
    reasons.update({key: why[key] for key in SEESAW_METRICS if values[key] is None})
    if verdict.outcome == "balanced" and metrics.get("limit_cycle_amplitude_rad") is None:
        for key in ("limit_cycle_amplitude_rad", "limit_cycle_frequency_rad_s"):
            reasons.setdefault(key, "no steady oscillation in the second half of the run: the tilt may still be converging "
                                    "(a friction and quantization limit cycle shows once it has: run longer, e.g. --stop-time 20)")
    return values


def _with_limit_cycle(verdict: Verdict, cycle: tuple[float, float]) -> Verdict:
    """The chattering warning names the limit cycle the angle keeps (amplitude, frequency)."""
    amplitude, frequency = cycle
    warnings = tuple(
        Warning(w.kind, w.value, w.unit,
                w.text + f"; the angle keeps a limit cycle of ±{math.degrees(amplitude):.2f}° at {frequency:.3g} rad/s",
                w.advice, w.short) if w.kind == "chattering" else w
        for w in verdict.warnings
    )
    return Verdict(verdict.outcome, verdict.end_time, verdict.cut_reason, verdict.cut_time, warnings, verdict.measures)


def _not_reported(metrics: Mapping[str, Any], verdict: Verdict, columns: Mapping[str, Any], poke_start: float, limits: Limits) -> dict[str, str]:
    """Which response metrics to leave out, with the reason (what a student would read instead)."""
    chatter = next((w for w in verdict.warnings if w.kind == "chattering"), None)
    if chatter is not None:
        why = (f"the loop chatters (the voltage switches sign {chatter.value:.0f} times a second): "
               "the angle's swings are the chattering, not a response to the poke")
        return {key: why for key in RESPONSE_METRICS}
    reasons: dict[str, str] = {}
    if verdict.outcome in ("cut", "fell") and metrics.get("settling_time_s") is None:
        why = f"{'cut' if verdict.outcome == 'cut' else 'fell'} before the response settled"
        return {key: why for key in RESPONSE_METRICS}
    if metrics.get("peak_time_s") is None:
        t = np.asarray(columns["t"], dtype=float)
        alpha = np.asarray(columns["alpha"], dtype=float)
        after = alpha[t >= poke_start]
        before = alpha[(t < poke_start) & (t >= poke_start - 0.1)]
        swing = float(np.max(np.abs(after - (np.median(before) if before.size else 0.0)))) if after.size else 0.0
        why = (f"no swing above the encoder's resolution ({limits.q_alpha * 1e3:.3g} mrad) after the poke" if swing <= limits.q_alpha
               else "no oscillation: the angle did not swing back after the poke")
        return {key: why for key in RESPONSE_METRICS}
    if (metrics.get("overshoot_percent") or 0.0) > 100.0:
        # A swing back larger than the first peak (the pendulum leaning as the cart brakes after a hard
        # poke): no decaying second-order response swings back further than it went, so the percentage
        # would describe nothing. The first peak's time and the swings' frequency are still read.
        reasons["overshoot_percent"] = (f"the swing after the first peak is larger than the peak ({metrics['overshoot_percent']:.0f} % "
                                        "of it): not the overshoot of a decaying oscillation")
    largest = verdict.measures.get("largest_alpha_rad")
    t = np.asarray(columns["t"], dtype=float)
    alpha = np.asarray(columns["alpha"], dtype=float)
    end = verdict.cut_time if verdict.cut_time is not None else t[-1]
    window = (t >= poke_start) & (t <= end)
    if largest is not None and window.sum() > 8:
        aw = alpha[window]
        quarter = aw[-max(2, aw.size // 4):]
        first = float(np.max(np.abs(aw[: max(2, aw.size // 4)])))
        if float(np.max(np.abs(quarter))) > first + limits.q_alpha:
            reasons.update({key: "the swings do not decay (the end of the run swings more than the response to the poke)"
                            for key in RESPONSE_METRICS})
    if metrics.get("settling_time_s") is None and "settling_time_s" not in reasons:
        reasons["settling_time_s"] = ("the angle keeps a limit cycle (friction and quantization) and never stays in the 2 % band"
                                      if metrics.get("limit_cycle_amplitude_rad") is not None else
                                      "the angle did not stay in the settling band until the end of the run")
    if metrics.get("overshoot_percent") is None and "overshoot_percent" not in reasons:
        reasons["overshoot_percent"] = ("the swing after the first peak is the limit cycle, not an overshoot"
                                        if metrics.get("limit_cycle_amplitude_rad") is not None else
                                        "no swing back past the final value was seen")
    if metrics.get("natural_frequency_rad_s") is None and "natural_frequency_rad_s" not in reasons:
        reasons["natural_frequency_rad_s"] = "too few swings to measure a frequency"
    return reasons


def _seconds(value: float) -> str:
    """A time to two significant digits: ``0.04 s``, ``4.3 s``, ``12 s``."""
    return f"{float(f'{value:.2g}'):g} s"


def cut_before_poke(cut_time: float, reason: str, end_time: float | None = None) -> tuple[dict[str, Any], Verdict]:
    """``metrics.json``'s content for a rig session cut before its poke: no response, the verdict ``cut``.

    Every metric is None; ``not_reported`` says why for each response metric; the verdict's
    ``measures`` mark it (``before_poke``), which ``compare`` reads to refuse aligning such a run.

    Examples
    --------
    >>> m, v = cut_before_poke(0.919, "the rig's watchdog tripped")
    >>> v.headline()
    "CUT at t = 0.919 s before the poke: the rig's watchdog tripped; there is no response to measure"
    >>> m["stable"], m["not_reported"]["peak_time_s"]
    (False, "cut before the poke (the rig's watchdog tripped at t = 0.919 s): there is no response to measure")
    """
    from pendulab.analysis.metrics import METRIC_KEYS

    verdict = Verdict("cut", float(end_time if end_time is not None else cut_time), reason, float(cut_time),
                      measures={"before_poke": True})
    why = f"cut before the poke ({reason} at t = {cut_time:.3f} s): there is no response to measure"
    metrics: dict[str, Any] = {key: None for key in METRIC_KEYS}
    metrics.update(safety_cut_time_s=float(cut_time), stable=False, not_reported={key: why for key in RESPONSE_METRICS},
                   safety_cut_reason=reason, verdict=verdict.to_dict())
    return metrics, verdict


def was_cut_before_poke(metrics: Mapping[str, Any]) -> bool:
    """Whether ``metrics.json`` is that of a run cut before its poke (:func:`cut_before_poke`)."""
    verdict = metrics.get("verdict")
    return isinstance(verdict, Mapping) and bool((verdict.get("measures") or {}).get("before_poke"))
