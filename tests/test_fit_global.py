"""The fit's global search (issue 19) on the unseen rig's slow logs, where the cart stays in the slip region.

Slow ramps with holds (up to 1.6 V) and a triangle wave (3 V, 0.4 Hz) keep the cart in the slip region, leaving it only
by force near the peaks: the replay sees ``B + Beq`` and, through the inertia alone, the common scale of the gain,
forces and drags. The local stages (the polish's pattern search, the scans along the joint directions, the walk along
``F2, v2``) stop in the staircase the thresholds make of the replay cost: on the slow ramps with the force gain 6.6 %
low (``Beq`` +12 % before the short rests restarted the position only), on the triangle with ``Beq`` -15 %. CMA-ES from
the observer search's answer (``fit.AROUND_SIGMA``) steps over that staircase and finds the rig's basin.
"""

from __future__ import annotations

import pytest

from pendulab.calibration.fit import DEFAULT_FIT, fit_parameters
from pendulab.calibration.synthetic import closed_loop_log, closed_loop_params, corpus, held_out
from pendulab.model.parameters import PlantParameters

#: Per case, the bound asserted on the relative error of Beq and of the force gain. Measured (this note's machine):
#: the ramps Beq -0.9 %, gain -1.6 % (0.55 steps); the triangle -0.5 %, -0.1 % (0.60); the triangle with 10 mV on the
#: voltage -0.1 %, +4.8 % (0.64): within the issue's 5 % by 0.2 points, too close to assert the bar itself there.
CASES = {"ramps with holds | unseen | 0 mV": 0.05, "triangle | unseen | 0 mV": 0.05, "triangle | unseen | 10 mV": 0.065}


@pytest.mark.parametrize("name", list(CASES))
def test_the_global_search_finds_the_rigs_basin_where_the_cart_stays_in_the_slip_region(name):
    cases = corpus()
    case = next(c for c in cases if c.name == name)
    assert case.name not in held_out(cases)
    said: list[str] = []
    result = fit_parameters([case.log()], PlantParameters.preset("none"), on_progress=said.append)
    assert any(s.startswith("CMA-ES from the search's answer") for s in said), said  # the global search moved the answer
    assert any("beyond the slip region in only" in s for s in said), said  # and the log is one that stays in it
    true = case.params
    steps = result.forward_rms / result.encoder_step
    assert result.forward_ok and steps <= 1.5, steps  # the bar: 2 (measured 0.55-0.64)
    for name_ in ("Beq", "force_gain"):
        assert abs(result.values[name_] / getattr(true, name_) - 1) < CASES[name], (name_, result.values[name_])
    # A determined parameter within 3 of its uncertainties; a range holds the rig's value. Not F2's on the triangle: its
    # range (where the cost stays within twice the answer's, bounded from below only) starts 0.6 % above the rig's
    # value (+16 % with 10 mV), whose own values replay the log at 3.9 times the answer's cost (its first state's speed,
    # smoothed, 15 mm/s where the cart breaks away from rest).
    for name_, (low, high) in result.allowed.items():
        status = result.determination[name_]
        value = getattr(true, name_)
        if name_ == "F2" and name.startswith("triangle"):
            assert status != "determined" and high == float("inf"), (status, high)
            continue
        assert (status == "determined" and abs(result.values[name_] - value) <= 3 * result.uncertainty[name_]) or low <= value <= high, (
            name_, status, low, high)
    for name_, status in result.determination.items():
        assert status != "not identified" or result.values[name_] == result.initial[name_], (name_, result.values[name_])


def test_a_closed_loop_far_from_the_start_is_searched_again_from_the_global_searchs_answer():
    # A rig nobody here made (a probe of session 38: F1 3 N, v1 2 mm/s, F2 3.6 N, v2 0.02 m/s, B 60), its closed loop fitted from the lab's
    # values: the observer search ended with B +2129 %, and an upright pendulum's replay restarts from the observer's states at that answer,
    # so no later stage got below 4 encoder steps (6.6 over its 8 s log). The global search from the start (one seed with the pendulum) got
    # closer, and the search again from there replays this 4 s log at 1.59 steps, F1, B, Beq and the gain within 0.3 % (30 CPU-s). B is
    # only bounded since B's own check (fit.HOPPED): held 35 % off with the others polished, this short log replays within twice the cost.
    worn = PlantParameters.preset("none", Beq=6.0, force_gain=0.85, F1=3.0, v1=0.002, F2=3.6, v2=0.02, B=60.0)
    true, lab = closed_loop_params(worn), PlantParameters.preset("none")
    said: list[str] = []
    start = true.with_values(**{n: getattr(lab, n) for n in DEFAULT_FIT})
    result = fit_parameters([closed_loop_log(worn, duration=4.0)], start, on_progress=said.append)
    assert any(line.startswith("searched and polished again from there") for line in said)
    assert result.forward_rms < 2.0 * true.q_x
    for name in ("F1", "B", "Beq", "force_gain"):
        assert abs(result.values[name] / getattr(true, name) - 1) < 0.05
        if name == "B" and result.determination[name] == "bounded":
            low, high = result.allowed[name]
            assert low <= true.B <= high, (low, high)
            continue
        assert result.determination[name] == "determined"
        assert abs(result.values[name] - getattr(true, name)) <= 3 * result.uncertainty[name]
