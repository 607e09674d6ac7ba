"""The fit's compiled replay (:mod:`pendulab.calibration._replay`): the plant's own equations, its constant divisions made
multiplications by their reciprocals (a division costs several multiplications' time), and still the plant's motion."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from pendulab.calibration._replay import _split, _step, replay  # private: the compiled step and the key it is built for
from pendulab.calibration.synthetic import RIGS, synthetic_log
from pendulab.model.plant import PlantModel

FREE = ("F1", "v1", "F2", "v2", "B", "Beq", "force_gain")


def test_the_compiled_step_divides_by_no_constant():
    p = RIGS["sticky"]
    free, fixed = _split(np.asarray(p.as_vector(), dtype=float), FREE)
    step = _step(free, fixed)
    # The cart's step divides only by constants (masses, motor constants, the RK4 weights): none is left.
    divisions = [k for k in range(step.n_instructions()) if step.instruction_id(k) == ca.OP_DIV]
    assert not divisions, f"{len(divisions)} divisions left"
    assert step.n_instructions() > 200  # an RK4 sub-step of the cart (330 instructions), not an empty function


@pytest.mark.parametrize("shape", ["chirp", "random steps"])
def test_the_replay_follows_the_plants_own_simulation(shape):
    p = RIGS["unseen"]
    log = synthetic_log(shape, p, duration=3.0, voltage_noise=0.0)
    x0 = np.array([log.x[0], 0.0, 0.0, 0.0])
    ours = replay([p], log.V[:-1], log.t[:-1], x0, free=FREE)[0, :, 0]
    plants = PlantModel().simulate(p, log.V[:-1], log.period, x0)[1:, 0]  # the RK4 of plant_equations as written, divisions and all
    assert np.ptp(plants) > 0.01  # the cart moves
    assert np.max(np.abs(ours - plants)) < 1e-9


def test_a_held_parameter_stays_an_input_of_the_same_build():
    # Held at a value (the F2 check's e^-0.3 and e^0.3, the common scale's force gain), a parameter was compiled in as a constant: each
    # held value built its own replay and observer (3-5 s of gcc each, a third of the fit tests' builds). It is an input of the fit's.
    from pendulab.calibration import _polish, _replay  # private: the search's space, the compiled replay's builds

    p = RIGS["unseen"]
    log = synthetic_log("chirp", p, duration=1.0, voltage_noise=0.0)
    a = _polish.Anchors(log.V[:-1], log.t[:-1], log.x[1:, None], np.array([1e-5]), np.array([log.x[0], 0.0, 0.0, 0.0]), {}, np.array([0]))
    n = len(FREE)
    space = _polish.Space(p, FREE, np.array([getattr(p, name) for name in FREE]), np.full(n, 1e-3), np.full(n, 1e3))
    theta, j = np.ones(n), FREE.index("F2")
    _polish.costs([a], space, theta[None])
    built = _replay._compiled.cache_info().currsize
    held = space.holding("F2", 1.2)
    assert held.names == tuple(name for name in FREE if name != "F2") and held.inputs == FREE
    moved = theta.copy()
    moved[j] = 1.2
    assert _polish.costs([a], held, np.delete(theta, j)[None])[0] == _polish.costs([a], space, moved[None])[0]  # the same bits
    assert _replay._compiled.cache_info().currsize == built  # and no new build
