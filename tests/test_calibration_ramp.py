"""Virtual rig, ramp-test procedure and friction extraction (must-show 1 of the calibration issue)."""

from __future__ import annotations

import numpy as np
import pytest

from pendulab.calibration.extract import extract_friction, mass_ratio
from pendulab.calibration.logs import RampLog
from pendulab.calibration.ramp import run_ramp_test
from pendulab.calibration.rig import VirtualRig
from pendulab.calibration.synthetic import TEST_RIG
from pendulab.errors import CalibrationError
from pendulab.model.parameters import PlantParameters

TRUE = TEST_RIG.friction  # a non-default friction vector


@pytest.fixture(scope="module")
def ramp_log() -> RampLog:
    with VirtualRig(friction=TRUE, x0=0.06) as rig:
        return run_ramp_test(rig, iterations=2)


def test_virtual_rig_sticks_below_F1_and_moves_above():
    K = 1.72646  # N/V of the IP02 motor at rest
    with VirtualRig(friction=TRUE, x0=0.0) as rig:
        rig.reset()
        for _ in range(300):
            x = rig.step(0.95 * TRUE[0] / K)
        assert x == 0.0 and rig.time == pytest.approx(0.3)
        for _ in range(300):
            x = rig.step(1.05 * TRUE[0] / K)
        assert x > 0.005


def test_fmu_and_casadi_virtual_rigs_agree():
    voltages = np.r_[np.linspace(0, 2.0, 800), np.zeros(200)]
    traces = []
    for backend in ("fmu", "casadi"):
        with VirtualRig(friction=TRUE, x0=0.01, backend=backend) as rig:
            rig.reset()
            traces.append([rig.step(v) for v in voltages])
    assert np.ptp(traces[0]) > 0.01
    assert np.allclose(traces[0], traces[1], atol=1e-9)


def test_ramp_test_announces_iterations_and_covers_both_directions(ramp_log):
    assert not ramp_log.interrupted
    texts = [text for _, text in ramp_log.events]
    assert [t for t in texts if t.startswith("iteration")] == ["iteration 1", "iteration 2"]
    assert sum(t.startswith("breakaway +") for t in texts) == 4  # slow ramp and probe, per iteration
    assert sum(t.startswith("breakaway -") for t in texts) == 4
    assert sum(t.startswith("centred") for t in texts) == sum(t == "centring" for t in texts) >= 8
    assert ramp_log.x.max() > 0.05 and ramp_log.x.min() < -0.05
    assert ramp_log.V[-1] == 0.0 and abs(ramp_log.x[-1]) <= 0.01  # ends centred, motor off


def test_ctrl_c_keeps_what_was_measured():
    seen = []

    def stop_at_second(i: int, n: int) -> None:
        seen.append(i)
        if i == 2:
            raise KeyboardInterrupt

    with VirtualRig(friction=TRUE) as rig:
        log = run_ramp_test(rig, iterations=5, on_iteration=stop_at_second)
        stopped_at = rig.time
    assert seen == [1, 2] and log.interrupted
    assert log.duration > 5 and log.t[-1] < stopped_at
    assert any("interrupted" in text for _, text in log.events)
    estimate = extract_friction(log)  # the first iteration is complete: still usable
    assert abs(estimate.measured[0] / TRUE[0] - 1) < 0.1
    assert any("interrupted" in note for note in estimate.notes)


def test_track_limit_cuts_the_voltage_and_the_cart_is_backed_off():
    with VirtualRig(friction=TRUE, x0=0.0) as rig:
        log = run_ramp_test(rig, iterations=1, track_limit=0.04, motion_distance=0.5)
    limits = [t for t, text in log.events if text.startswith("track limit")]
    assert limits
    following = [t for t, text in log.events if t > limits[0]]
    cut = (log.t >= limits[0]) & (log.t < following[0])
    assert cut.sum() > 10 and np.all(log.V[cut] == 0.0)  # motor off until the cart stands still
    assert np.abs(log.x).max() < 0.04 + 0.05  # coasting after the cut, no more pushing
    assert abs(log.x[-1]) <= 0.01


def test_extraction_recovers_the_friction_vector_of_the_virtual_rig(ramp_log):
    estimate = extract_friction(ramp_log)
    F1, v1, F2, v2, B = estimate.measured
    assert abs(F1 / TRUE[0] - 1) < 0.10
    assert abs(F2 / TRUE[2] - 1) < 0.10
    assert abs(B / TRUE[4] - 1) < 0.10
    assert abs(v1 / TRUE[1] - 1) < 0.2 and abs(v2 / TRUE[3] - 1) < 0.2
    assert estimate.counts["F1"] == 4 and estimate.counts["B"] >= 4
    assert all(estimate.spread[n] < 0.05 * abs(v) for n, v in zip(("F1", "v1", "F2", "v2", "B"), estimate.measured))
    assert abs(estimate.Beq / PlantParameters().Beq - 1) < 0.05
    assert estimate.friction == estimate.measured  # mass ratio 1: unscaled


def test_mass_ratio_scales_the_forces_only(ramp_log):
    ratio = mass_ratio(PlantParameters.preset("long"))
    assert ratio == pytest.approx((0.57 + 0.230) / 0.57)
    estimate = extract_friction(ramp_log, mass_ratio=ratio)
    F1, v1, F2, v2, B = estimate.friction
    assert F1 == pytest.approx(ratio * estimate.measured[0]) and F2 == pytest.approx(ratio * estimate.measured[2])
    assert (v1, v2, B) == (estimate.measured[1], estimate.measured[3], estimate.measured[4])
    cal = estimate.to_calibration(rig="test")
    assert cal.friction == estimate.friction and cal.metadata["mass_ratio"] == ratio


def test_logs_without_a_breakaway_are_rejected(ramp_log):
    short = ramp_log.between(0.0, 0.05)
    with pytest.raises(CalibrationError, match="no voltage ramp|no breakaway"):
        extract_friction(short)
    # Ramps too weak to move the cart: no breakaway.
    t = np.arange(2000) * 1e-3
    V = np.where(t > 0.5, np.minimum((t - 0.5) * 1.0, 0.5), 0.0)
    with pytest.raises(CalibrationError, match="no breakaway"):
        extract_friction(RampLog(t, V, np.zeros_like(t)))
    with pytest.raises(CalibrationError, match="mass ratio"):
        extract_friction(ramp_log, mass_ratio=-1.0)
