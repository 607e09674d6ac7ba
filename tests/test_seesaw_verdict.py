"""The seesaw's verdict (issue 20): held level / settled within 2 degrees / fell onto the tilt stop / cut at
the track, told in the seesaw's words, with its numbers read independently from the run's columns."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import pendulab
from pendulab.analysis.compare import load_compared
from pendulab.analysis.verdict import TILT_BAND, Limits, assess, judge
from pendulab.cli.main import main
from pendulab.cosim.seesaw import seesaw_spec, verdict_limits
from pendulab.fmu.models.supervisor.config import TRIP_TRACK
from pendulab.model.seesaw import SeesawParameters
from pendulab.spec import Poke, Timing

LIMITS = verdict_limits()


def test_the_seesaw_s_limits_are_its_supervisor_s_and_its_tilt_stop() -> None:
    params = SeesawParameters()
    assert LIMITS == Limits(V_max=params.V_max, alpha_max=math.radians(10.0), x_max=0.35, q_alpha=params.q_theta,
                            q_x=params.q_x, angle_stop=params.theta_stop)


def test_a_hard_tap_fells_it_onto_its_tilt_stop_and_the_line_says_when(tmp_path) -> None:
    """8 rad/s^2 for 0.1 s (2.4 times the demo's tap): the supervisor cuts at 10 degrees, the seesaw falls onto its stop."""
    result = pendulab.simulate(seesaw_spec(poke=Poke(8.0, 0.1, 1.0), timing=Timing(stop_time=2.5)))
    c, v = result.columns, result.verdict
    t, theta = c["t"], c["theta"]
    trip = t[np.flatnonzero(c["trip_reason"] > 0)[0]]
    stop = t[np.flatnonzero(np.abs(theta) >= SeesawParameters().theta_stop * (1 - 1e-6))[0]]
    assert v.outcome == "fell" and v.cut_reason == "angle limit" and trip < stop
    assert np.degrees(np.abs(theta[t < trip]).max()) <= 10.0 + 0.1  # up to the cut, within a step of the limit
    assert v.headline().startswith(f"FELL at t = {trip:.3f} s: the tilt passed the 10° limit (the supervisor cut the motor) "
                                   f"and the seesaw hit its 11.5° tilt stop at t = {stop:.3f} s")
    m = result.metrics
    assert not m["stable"] and m["safety_cut_reason"] == "angle limit" and m["tilt_settling_time_s"] is None
    assert m["not_reported"]["tilt_settling_time_s"] == "the seesaw fell before the tilt settled"
    assert m["max_abs_x_m"] == pytest.approx(np.abs(c["x"][(t >= 1.0) & (t <= trip)]).max())  # the cart up to the cut
    # The run read back (no metrics.json: judged again, as a seesaw) gives the same verdict.
    result.write(tmp_path)
    (tmp_path / "metrics.json").unlink()
    run = load_compared(tmp_path)
    assert run.poke_start == 1.0 and "theta" in run.columns and "alpha" not in run.columns
    assert run.metrics["verdict"]["headline"] == v.headline() and run.metrics["verdict"]["plant"] == "seesaw"


def _columns(theta: np.ndarray, t: np.ndarray, x: np.ndarray | None = None, **more: np.ndarray) -> dict[str, np.ndarray]:
    return {"t": t, "theta": theta, "x": np.zeros_like(t) if x is None else x, "voltage": np.zeros_like(t),
            "supervisor_state": np.full_like(t, 2.0), **more}


T = np.arange(0, 5001) * 1e-3
TAPPED = T >= 1.0


def test_held_up_but_not_settled_is_a_warning_with_the_tilt_at_the_end() -> None:
    slow = np.where(TAPPED, np.radians(6.0) * np.exp(-0.2 * (T - 1.0)), 0.0)  # still 2.7 degrees at 5 s
    v = judge(_columns(slow, T), poke_start=1.0, limits=LIMITS, plant="seesaw")
    assert v.outcome == "balanced" and not v.clean and [w.kind for w in v.warnings] == ["unsettled"]
    end = math.degrees(slow[-1])
    assert v.headline() == f"HELD UP for 5 s (the tap tilted it 6.0°), but the tilt did not settle within 2° ({end:+.1f}° at the end)"
    metrics, _ = assess(_columns(slow, T), poke_start=1.0, limits=LIMITS, plant="seesaw")
    assert metrics["tilt_settling_time_s"] is None and "did not stay within 2°" in metrics["not_reported"]["tilt_settling_time_s"]


@pytest.mark.parametrize("peak_deg, warned", [(7.0, False), (8.0, True)])
def test_the_tilt_s_margin_is_three_quarters_of_its_limit(peak_deg: float, warned: bool) -> None:
    swing = np.where(TAPPED, np.radians(peak_deg) * np.exp(-3 * (T - 1.0)), 0.0)
    v = judge(_columns(swing, T), poke_start=1.0, limits=LIMITS, plant="seesaw")
    # Independently: the tap to the last sample beyond the band, and the next sample.
    settled = T[np.flatnonzero(np.abs(swing) > TILT_BAND)[-1] + 1] - 1.0
    assert v.measures["tilt_settling_time_s"] == pytest.approx(settled)
    margin = [w for w in v.warnings if w.kind == "small margin"]
    assert bool(margin) is warned
    if warned:
        assert margin[0].text.startswith(f"the tilt reached {peak_deg:.1f}° of the 10° limit") and "Q weight" in margin[0].advice
        assert v.headline() == (f"HELD LEVEL for 5 s: the tap's {peak_deg:.1f}° tilt settled within 2° in {settled:.2f} s, "
                                "but little margin to the supervisor's limits")
    else:
        assert v.clean


def test_the_cart_s_limit_cycle_is_not_a_drift_but_a_trend_is() -> None:
    """The held seesaw's cart swings in the friction limit cycle (±7 mm at 4.9 rad/s in a 20 s demo run with ideal
    encoders): over the pendulum's 1 s window its last half-swing looks like a drift to the track end; the seesaw's
    2 s window sees no trend. A cart that really creeps (2 cm/s) is still named."""
    swing = np.where(TAPPED, 0.008 * np.sin(4.87 * (T - 1.0) + 1.83), 0.0)
    level = np.where(TAPPED, np.radians(0.2) * np.sin(4.87 * (T - 1.0)), 0.0)
    assert "drift" in [w.kind for w in judge({**_columns(level, T, swing), "alpha": level}, poke_start=1.0, limits=LIMITS).warnings]
    assert judge(_columns(level, T, swing), poke_start=1.0, limits=LIMITS, plant="seesaw").clean
    creep = swing + np.where(TAPPED, 0.02 * (T - 1.0), 0.0)
    drift = [w for w in judge(_columns(level, T, creep), poke_start=1.0, limits=LIMITS, plant="seesaw").warnings if w.kind == "drift"]
    assert drift and "weight x more" in drift[0].advice


def test_cut_at_the_track_names_the_tilt_at_the_cut() -> None:
    x = np.where(TAPPED, 0.2 * (T - 1.0), 0.0)  # reaches 0.35 m at t = 2.75 s
    reason = np.where(T >= 2.75, float(TRIP_TRACK), 0.0)
    tilt = np.where(TAPPED, np.radians(1.5), 0.0)
    v = judge(_columns(tilt, T, x, trip_reason=reason), poke_start=1.0, limits=LIMITS, plant="seesaw")
    assert v.outcome == "cut" and v.cut_reason == "track limit"
    assert v.headline() == "CUT at t = 2.750 s: the cart reached the track limit (0.35 m) with the seesaw still up (tilt 1.5°)"


def test_no_tap_tests_nothing_and_simulate_refuses_it(capsys, tmp_path) -> None:
    v = judge(_columns(0 * T, T), poke_start=1.0, limits=LIMITS, poke=(0.0, 0.1), plant="seesaw")
    assert v.outcome == "not tested" and "a tap of size or length 0" in v.headline()
    status = main(["simulate", "--plant", "seesaw", "--demo", "--poke", "0,0.1,1", "--out", str(tmp_path / "no")])
    err = capsys.readouterr().err.strip()
    assert status == 2 and len(err.splitlines()) == 1 and "a tap of size 0 disturbs nothing" in err
    assert not (tmp_path / "no").exists()


def test_the_pendulum_s_words_stay_the_pendulum_s() -> None:
    """The same swing judged as a pendulum keeps the pendulum's line and its to_dict has no plant key."""
    swing = np.where(TAPPED, 0.01 * np.exp(-3 * (T - 1.0)), 0.0)
    cols = {"t": T, "alpha": swing, "x": 0 * T, "voltage": 0 * T, "supervisor_state": np.full_like(T, 2.0)}
    v = judge(cols, poke_start=1.0)
    assert v.headline() == "BALANCED for 5 s with no warning" and "plant" not in v.to_dict()
    assert json.loads(json.dumps(v.to_dict())) == v.to_dict()
