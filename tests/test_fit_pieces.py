"""Long logs are searched on pieces and checked on the whole (issue 19): one measure for every decision.

A log longer than ``STAGE_SECONDS`` is searched on its most informative pieces (the cart alone: first those
from one of its rests, as the whole log's replay restarts there); after the polish, the thresholds are
scanned once more on the whole log (pushes the pieces lack). The decisions after that (the
evolution strategy's start and its acceptance, which start values a parameter the log does not identify
may keep) compare costs on the pieces: the answer carries its cost there. It once carried the whole log's
cost, which any point's cost on the pieces beats by construction (on a 60 s log the evolution strategy
"lowered" 7.5e5 to 1.6e5 at the same replay RMS, in 25 CPU-s). Here the limits are made small so that a 4 s
log is cut into pieces.
"""

from __future__ import annotations

import numpy as np
import pytest

from pendulab.calibration import _polish  # private: the fit's stages are what this checks
from pendulab.calibration import fit as fit_module
from pendulab.calibration.synthetic import RIGS, synthetic_log
from pendulab.model.parameters import PlantParameters


def _searched_on_pieces(monkeypatch):
    """The setup and the polish's answer of a 4 s log searched on 2 s of pieces."""
    monkeypatch.setattr(fit_module, "STAGE_SECONDS", 2.0)
    monkeypatch.setattr(fit_module, "PIECE_SECONDS", 1.0)
    seen = {}
    evolved = fit_module._evolved

    def spy(setup, answer, start="answer", quiet=False):
        if start == "search":  # the polish's answer (the later searches get the global search's)
            seen["setup"], seen["answer"] = setup, answer
        return evolved(setup, answer, start, quiet)

    monkeypatch.setattr(fit_module, "_evolved", spy)
    log = synthetic_log("random steps", RIGS["unseen"], duration=4.0, voltage_noise=0.0)
    fit_module.fit_parameters([log], PlantParameters.preset("none"))
    return seen["setup"], seen["answer"]


def test_a_long_log_is_searched_on_pieces_and_the_answer_carries_its_cost_there(monkeypatch):
    setup, answer = _searched_on_pieces(monkeypatch)
    pieces, whole = answer.searched, answer.replays
    assert pieces is not whole and sum(a.n for a in pieces) <= 0.6 * sum(a.n for a in whole)  # 2 of 4 s
    theta = answer.polished.theta
    on_pieces = float(_polish.costs(pieces, setup.space, theta[None])[0])
    on_whole = float(_polish.costs(whole, setup.space, theta[None])[0])
    assert answer.polished.cost == pytest.approx(on_pieces, rel=1e-12)
    assert on_whole > 1.3 * on_pieces  # the two measures differ: comparing them would decide nothing


def test_a_search_better_on_the_pieces_but_worse_on_the_whole_log_leaves_the_answer(monkeypatch):
    """A 120 s log of slow ramps (unseen rig): the global search lowered the pieces' cost 1.86e6 -> 7.75e5 and took
    the whole log's replay from 157 um to 11 mm; the fit was refused. Such a point is not taken."""
    setup, answer = _searched_on_pieces(monkeypatch)
    theta = answer.polished.theta
    worse = setup.space.project(theta * np.where(np.array(setup.names) == "force_gain", 0.7, 1.0))
    assert fit_module._replay_rms(setup, answer.replays, worse) > 2 * answer.rms  # the whole log says it is worse
    claimed = _polish.Polished(worse, 0.5 * answer.polished.cost, 0.5 * answer.polished.cost, 1, 1)  # ... the pieces better
    monkeypatch.setattr(_polish, "evolve", lambda *args, **kwargs: (worse, claimed.cost))
    monkeypatch.setattr(_polish, "polish", lambda *args, **kwargs: claimed)
    monkeypatch.setattr(fit_module, "EVOLVE_ABOVE_STEPS", 0.0)  # it runs whatever the answer's replay
    kept = fit_module._evolved(setup, answer)
    assert kept is answer and np.array_equal(kept.polished.theta, theta)


@pytest.mark.parametrize("search_seconds", [1.0, None])
def test_cma_es_replays_at_most_search_seconds_of_a_long_log_and_all_of_a_short_one(monkeypatch, search_seconds):
    """Longer than STAGE_SECONDS (2 s here), the 4 s log's CMA-ES runs replay SEARCH_SECONDS (1 s) of pieces, and what
    each found is polished on the 2 s the polish sees; not longer (None: the limits as shipped), all see the whole log."""
    if search_seconds is not None:
        monkeypatch.setattr(fit_module, "STAGE_SECONDS", 2.0)
        monkeypatch.setattr(fit_module, "PIECE_SECONDS", 1.0)
        monkeypatch.setattr(fit_module, "SEARCH_SECONDS", search_seconds)
    calls = []  # (function, samples replayed), in order
    for name in ("evolve", "polish"):
        original = getattr(_polish, name)

        def spy(logs, *args, _original=original, _name=name, **kwargs):
            calls.append((_name, sum(a.n for a in logs)))
            found = _original(logs, *args, **kwargs)
            return (found[0], 0.0) if _name == "evolve" else found  # each run claims a lower cost: what it found is polished

        monkeypatch.setattr(_polish, name, spy)
    log = synthetic_log("random steps", RIGS["unseen"], duration=4.0, voltage_noise=0.0)
    fit_module.fit_parameters([log], PlantParameters.preset("none"))
    evolved = [n for name, n in calls if name == "evolve"]
    after = [calls[i + 1][1] for i, (name, _) in enumerate(calls[:-1]) if name == "evolve" and calls[i + 1][0] == "polish"]
    assert evolved and len(after) == len(evolved)  # the global search ran (it always does on a cart's log), and each answer was polished
    if search_seconds is None:
        assert set(evolved) == set(after) == {len(log) - 1}
    else:
        assert max(evolved) <= 1.1 / log.period  # a piece of 1 s
        assert min(after) >= 1.9 / log.period  # 2 pieces


def test_a_cart_log_s_pieces_start_at_its_rests_and_replay_as_the_whole_log_does_there(monkeypatch):
    """The cart alone: each piece starts where the whole log's replay restarts at a rest, so that its replay errors are the
    whole log's on those samples. From smoothed speeds mid-motion instead, a 30 s slow-ramp log fitted the force gain
    20 % low (2.4 encoder steps, 37 CPU-s; from its rests: 10 % and 1.0 step, 15 CPU-s)."""
    setup, answer = _searched_on_pieces(monkeypatch)
    whole = answer.replays[0]
    firsts = [first for _, _, first in setup.pieces]
    assert len(firsts) == 2 and all(first in whole.restarts for first in firsts)
    theta = setup.space.vectors(answer.polished.theta[None])
    on_whole = _polish.replay_errors([whole], theta, setup.names)[0]
    for piece, first in zip(answer.searched, firsts):
        on_piece = _polish.replay_errors([piece], theta, setup.names)[0]
        assert np.array_equal(on_piece, on_whole[first : first + piece.n])


def test_a_search_run_that_ends_above_the_answer_is_not_polished(monkeypatch):
    """CMA-ES from the search's answer: a run whose best replays worse than the answer where it searched is left (the
    dev corpus's 9 such runs stayed above the answer when polished); one below it is polished."""
    setup, answer = _searched_on_pieces(monkeypatch)
    here = float(_polish.costs(fit_module._sampled(setup, answer), setup.space, answer.polished.theta[None])[0])
    polished = []
    monkeypatch.setattr(_polish, "polish", lambda logs, space, theta, **kwargs: polished.append(theta) or answer.polished)
    for claimed, runs in [(1.5 * here, 0), (0.5 * here, 2)]:
        polished.clear()
        monkeypatch.setattr(_polish, "evolve", lambda *args, **kwargs: (answer.polished.theta * 1.01, claimed))
        assert fit_module._evolved(setup, answer, "search") is answer
        assert len(polished) == runs


def test_the_common_scale_s_search_does_not_lower_the_slip_region_s_ends(monkeypatch):
    """Along the common scale (a cart that stays in the slip region), F2 and v2 are bounded from below only: lowered on
    8 s of a 60 s log's pieces, the cart left the slip region in the others. A scan that lowers them is projected back."""
    setup, answer = _searched_on_pieces(monkeypatch)
    names, theta = setup.names, answer.polished.theta
    scan = _polish.scan_directions

    def lowering(logs, space, th, *args, **kwargs):  # the scan "finds" both ends halved
        found = scan(logs, space, th, *args, **kwargs)
        low = found.theta.copy()
        for n in ("F2", "v2"):
            low[space.names.index(n)] *= 0.5
        return _polish.Polished(low, found.cost, found.start_cost, found.iterations, found.replays)

    monkeypatch.setattr(_polish, "scan_directions", lowering)
    moved = _polish.moved(setup.space, theta, "scale", 0.04)
    found = fit_module._at_scale(setup, answer.searched, theta, 0.04)
    for n in ("F2", "v2"):
        assert found.theta[names.index(n)] >= moved[names.index(n)] * (1 - 1e-12)


def test_a_30_s_slow_ramp_log_searched_on_pieces_from_its_rests_finds_the_rig():
    """The limits as shipped: 30 s of slow ramps is searched on 20 s of pieces. Started from smoothed speeds mid-motion,
    they fitted the force gain 20 % low (2.35 encoder steps); from the cart's rests, 1.6 % (0.58 steps)."""
    true = RIGS["unseen"]
    log = synthetic_log("ramps with holds", true, duration=30.0, voltage_noise=0.0)
    result = fit_module.fit_parameters([log], PlantParameters.preset("none"))
    assert result.searched_seconds <= fit_module.STAGE_SECONDS + 1.0
    assert result.forward_ok and result.forward_rms < 1.0 * true.q_x  # measured 0.58 steps
    assert abs(result.values["force_gain"] / true.force_gain - 1) < 0.05  # measured -1.6 %
