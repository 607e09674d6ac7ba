"""The Supervisor FMU (SPEC §5), driven step by step through fmpy's FMU2Slave.

Each communication step of the harness does what a master does: set the inputs at time t, read the
outputs (the same communication point), then doStep(t, h). "Within one control period" therefore
means: the output read in the very step whose inputs cross a limit already shows V = 0.
"""

from __future__ import annotations

import itertools
import math
from ctypes import byref

import pytest
from fmi_harness import Slave
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException, printLogMessage
from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

from pendulab.fmu.models.supervisor.config import (
    ALPHA_MAX_DEFAULT,
    CAPTURE_WINDOW_DEFAULT,
    COMMANDS,
    ENDED,
    IDLE,
    PAUSED,
    RUNNING,
    STATES,
    TRIP_ANGLE,
    TRIP_MEASUREMENT,
    TRIP_REASONS,
    TRIP_TRACK,
    TRIP_VOLTAGE,
    TRIPPED,
    WAITING,
    X_MAX_DEFAULT,
    rig_to_upright,
)

H = 1e-3  # control period
DEG = math.pi / 180

# ---------------------------------------------------------------- logging
# fmpy formats an FMU's variadic log call in a native proxy that forwards to ONE process-wide Python
# logger (the last one registered). Ours captures the messages of this module's instances and prints
# everyone else's as fmpy's default logger does; it is restored to fmpy's printer after the module.
MESSAGES: dict[str, list[tuple[int, str, str]]] = {}
_PREFIX = "supervisor-test-"


def _capture(env, instance_name, status, category, message):
    name = instance_name.decode()
    if name.startswith(_PREFIX):
        MESSAGES.setdefault(name, []).append((status, category.decode(), message.decode()))
    else:
        printLogMessage(env, instance_name, status, category, message)


_CAPTURE = fmi2CallbackLoggerTYPE(_capture)
_PRINT = fmi2CallbackLoggerTYPE(printLogMessage)
_KEEP: list = []


def _callbacks(logger) -> fmi2CallbackFunctions:
    from fmpy import calloc, free
    from fmpy.fmi2 import fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE
    from fmpy.logging import addLoggerProxy

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = logger
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    addLoggerProxy(byref(callbacks))
    return callbacks


@pytest.fixture(scope="module")
def callbacks():
    cb = _callbacks(_CAPTURE)
    yield cb
    _KEEP.append(_callbacks(_PRINT))  # kept alive: the proxy calls fmpy's printer from now on


# ---------------------------------------------------------------- the FMU
@pytest.fixture(scope="module")
def unpacked(supervisor_fmu, tmp_path_factory):
    unzipdir = extract(str(supervisor_fmu), unzipdir=str(tmp_path_factory.mktemp("Supervisor")))
    return read_model_description(str(supervisor_fmu)), unzipdir


_names = itertools.count()


class Supervisor:
    """One Supervisor instance, stepped like a master does."""

    last_name = ""

    def __init__(self, unpacked, callbacks, **parameters):
        md, unzipdir = unpacked
        self.variables = {v.name: v for v in md.modelVariables}
        self.name = Supervisor.last_name = f"{_PREFIX}{next(_names)}"
        MESSAGES[self.name] = []
        self.slave = Slave(unzipdir, parameters, name=self.name, callbacks=callbacks, logging=True, description=md)
        self.fmu = self.slave.fmu
        self.t = 0.0

    def set(self, **values):
        self.slave.set(values)

    def get(self, *names):
        names = names or [n for n, v in self.variables.items() if v.causality == "output"]
        return dict(zip(names, self.slave.get(names)))

    def tick(self, command: str | None = None, **inputs):
        """One communication step: inputs at t, outputs at t, doStep.

        As a master does, every signal input is set at every step (0 unless given); a command is set
        for this step only; ``iteration`` keeps its last value.
        """
        signals = {"V_command": 0.0, "alpha_measured": 0.0, "x_measured": 0.0}
        self.set(command=COMMANDS[command] if command else 0, **{**signals, **inputs})
        out = self.get()
        out["t"] = self.t
        self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=H)
        self.t += H
        return out

    @property
    def log(self) -> list[str]:
        return [m for _, _, m in MESSAGES[self.name]]

    def close(self):
        self.fmu.freeInstance()


@pytest.fixture
def make(unpacked, callbacks):
    made = []

    def factory(**parameters) -> Supervisor:
        s = Supervisor(unpacked, callbacks, **parameters)
        made.append(s)
        return s

    yield factory
    for s in made:
        s.close()


# ---------------------------------------------------------------- model description
def test_every_variable_is_described_and_physical_reals_have_units(unpacked):
    md, _ = unpacked
    assert md.coSimulation is not None and md.modelExchange is None
    for v in md.modelVariables:
        assert v.description, v.name
        if v.type == "Real":
            assert v.unit, v.name
    start = {v.name: v.start for v in md.modelVariables}
    assert float(start["alpha_max"]) == pytest.approx(15 * DEG)
    assert float(start["x_max"]) == pytest.approx(0.40)
    assert start["auto_start"] in ("true", True) and start["rig_mode"] in ("false", False)


# ---------------------------------------------------------------- trips
LIMITS = [
    ("alpha_measured", +1, TRIP_ANGLE, ALPHA_MAX_DEFAULT),
    ("alpha_measured", -1, TRIP_ANGLE, ALPHA_MAX_DEFAULT),
    ("x_measured", +1, TRIP_TRACK, X_MAX_DEFAULT),
    ("x_measured", -1, TRIP_TRACK, X_MAX_DEFAULT),
]


@pytest.mark.parametrize("signal, sign, reason, limit", LIMITS, ids=["alpha+", "alpha-", "x+", "x-"])
def test_trip_cuts_voltage_in_the_step_of_the_crossing_and_latches(make, signal, sign, reason, limit):
    s = make()
    # A ramp through the limit, 1 % of the limit per control period, with the limit itself hit exactly.
    ramp = [sign * (limit if k == 100 else limit * k / 100) for k in range(90, 111)]
    rows = [s.tick(V_command=3.0, **{signal: value}) for value in ramp]
    crossing = next(k for k, value in enumerate(ramp) if abs(value) > limit)
    assert crossing == 11  # the ramp point exactly on the limit (k = 100) does not trip
    before, at = rows[crossing - 1], rows[crossing]
    assert before["state"] == RUNNING and before["V"] == 3.0 and before["motor_enable"]
    # Same communication step: the voltage is already cut and the trip shown.
    assert at["V"] == 0.0 and not at["motor_enable"]
    assert at["state"] == TRIPPED and at["trip_reason"] == reason
    assert at["trip_time"] == pytest.approx(at["t"])
    # Latched: back inside the limits, commands other than re-arm do not clear it.
    for command in (None, "pause", None, None):
        row = s.tick(command, V_command=3.0)
        assert row["state"] == TRIPPED and row["V"] == 0.0 and row["trip_reason"] == reason
    for _ in range(50):
        row = s.tick(V_command=3.0)
    assert row["state"] == TRIPPED and row["V"] == 0.0 and row["trip_time"] == pytest.approx(at["t"])
    tripped = [m for m in s.log if "running -> tripped" in m]
    assert len(tripped) == 1 and TRIP_REASONS[reason] in tripped[0] and tripped[0].startswith(f"t={at['t']:.3f} s")
    # Re-arm: back to idle with the trip cleared; the voltage stays off until start.
    row = s.tick("rearm", V_command=3.0)
    assert (row["state"], row["trip_reason"], row["trip_time"], row["V"]) == (IDLE, 0, -1.0, 0.0)
    assert s.tick(V_command=3.0)["V"] == 0.0
    row = s.tick("start", V_command=3.0)
    assert row["state"] == RUNNING and row["V"] == 3.0


def test_rearm_is_refused_while_still_beyond_the_limit(make):
    s = make()
    s.tick(x_measured=0.41)
    row = s.tick("rearm", x_measured=0.45)
    assert row["state"] == TRIPPED
    assert any("re-arm refused" in m and "track limit" in m for m in s.log)
    row = s.tick("start", x_measured=0.45)
    assert row["state"] == TRIPPED and row["V"] == 0.0
    assert any("start refused" in m for m in s.log)
    row = s.tick("rearm", x_measured=0.1)
    assert row["state"] == IDLE


def test_start_after_a_trip_rearms_and_starts(make):
    s = make()
    s.tick(V_command=1.0, alpha_measured=-0.3)
    row = s.tick("start", V_command=1.0, alpha_measured=0.01)
    assert row["state"] == RUNNING and row["V"] == 1.0 and row["trip_reason"] == 0
    assert any("tripped -> running (re-armed by start)" in m for m in s.log)


def test_a_held_start_does_not_rearm_a_later_trip(make):
    s = make(auto_start=False)
    assert s.tick("start")["state"] == RUNNING
    assert s.tick("start", x_measured=-0.5)["state"] == TRIPPED  # start still held: acted on once only
    for _ in range(5):
        assert s.tick("start", x_measured=0.0)["state"] == TRIPPED
    assert s.tick(x_measured=0.0)["state"] == TRIPPED
    assert s.tick("start", x_measured=0.0)["state"] == RUNNING  # a new press


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf], ids=["nan", "inf", "-inf"])
def test_non_finite_voltage_command_trips(make, bad):
    s = make()
    assert s.tick(V_command=2.0)["V"] == 2.0
    row = s.tick(V_command=bad)
    assert row["V"] == 0.0 and row["state"] == TRIPPED and row["trip_reason"] == TRIP_VOLTAGE
    row = s.tick("rearm", V_command=bad)
    assert row["state"] == TRIPPED  # the fault is still there
    s.tick()  # the controller recovers (e.g. reset); the key is released
    assert s.tick("rearm")["state"] == IDLE


@pytest.mark.parametrize("signal", ["alpha_measured", "x_measured"])
def test_non_finite_measurement_trips(make, signal):
    s = make()
    row = s.tick(V_command=2.0, **{signal: math.nan})
    assert row["V"] == 0.0 and row["trip_reason"] == TRIP_MEASUREMENT


def test_voltage_is_clamped_to_v_limit(make):
    s = make(V_limit=6.0)
    assert s.tick(V_command=25.0)["V"] == 6.0
    assert s.tick(V_command=-25.0)["V"] == -6.0
    assert s.tick(V_command=-2.5)["V"] == -2.5


# ---------------------------------------------------------------- operator commands
def test_pause_and_resume(make):
    s = make()
    assert s.tick(V_command=2.0)["V"] == 2.0
    row = s.tick("pause", V_command=2.0)
    assert (row["state"], row["V"], row["motor_enable"]) == (PAUSED, 0.0, False)
    for _ in range(3):
        row = s.tick(V_command=2.0, alpha_measured=0.5)  # the pendulum falls while paused: no trip
    assert row["state"] == PAUSED and row["trip_reason"] == 0
    row = s.tick("start", V_command=2.0)
    assert (row["state"], row["V"]) == (RUNNING, 2.0)
    # Resuming with the pendulum beyond the limit trips at once.
    s.tick("pause")
    row = s.tick("start", V_command=2.0, alpha_measured=0.5)
    assert (row["state"], row["V"], row["trip_reason"]) == (TRIPPED, 0.0, TRIP_ANGLE)
    assert any("running -> paused (pause)" in m for m in s.log)
    assert any("paused -> running (resume)" in m for m in s.log)


def test_end_is_final(make):
    s = make()
    row = s.tick("end", V_command=2.0)
    assert (row["state"], row["V"], row["motor_enable"]) == (ENDED, 0.0, False)
    for command in ("start", None, "rearm", None, "pause", None, "start"):
        row = s.tick(command, V_command=2.0)
        assert (row["state"], row["V"]) == (ENDED, 0.0)
    assert any("start ignored" in m for m in s.log)


def test_end_after_a_trip_keeps_the_trip_record(make):
    s = make()
    s.tick(x_measured=0.5)
    row = s.tick("end", x_measured=0.5)
    assert (row["state"], row["trip_reason"], row["trip_time"]) == (ENDED, TRIP_TRACK, 0.0)


def test_lab_waits_for_start_and_announces_every_state_change(make):
    s = make(auto_start=False)
    rows = [s.tick(V_command=1.0) for _ in range(3)]
    assert all(r["state"] == IDLE and r["V"] == 0.0 for r in rows)
    s.tick("start", V_command=1.0)
    s.tick("pause")
    s.tick("start")
    s.tick("end")
    changes = [m for m in s.log if "->" in m]
    assert changes == [
        "t=0.003 s: idle -> running (start)",
        "t=0.004 s: running -> paused (pause)",
        "t=0.005 s: paused -> running (resume)",
        "t=0.006 s: running -> ended (end)",
    ]


def test_auto_start_runs_from_initialization(make):
    s = make()
    assert s.log == ["t=0.000 s: idle -> running (start)"]
    assert s.tick(V_command=-1.5)["V"] == -1.5


def test_unknown_command_is_ignored_and_logged(make):
    s = make()
    s.set(command=9)
    assert s.get("state")["state"] == RUNNING
    s.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=H)
    assert any("unknown command 9" in m for m in s.log)


def test_reset_returns_to_the_start(make):
    s = make()
    s.tick(x_measured=0.5)
    s.fmu.reset()
    s.fmu.setupExperiment(startTime=0.0)
    s.fmu.enterInitializationMode()
    s.fmu.exitInitializationMode()
    s.t = 0.0
    row = s.tick(V_command=1.0)
    assert (row["state"], row["trip_reason"], row["V"]) == (RUNNING, 0, 1.0)


# ---------------------------------------------------------------- the rig: upright capture
def theta_for(alpha: float) -> float:
    """The rig encoder's reading (0 hanging down, counting up to 2 pi) for an upright angle."""
    return (alpha + math.pi) % (2 * math.pi)


def test_rig_mode_engages_only_inside_the_capture_window(make):
    s = make(rig_mode=True, auto_start=False)
    row = s.tick(alpha_measured=0.0, V_command=4.0)  # hanging down
    assert row["alpha"] == pytest.approx(math.pi) and row["state"] == IDLE
    row = s.tick("start", alpha_measured=0.0, V_command=4.0)
    assert (row["state"], row["V"], row["motor_enable"]) == (WAITING, 0.0, False)
    # Brought up by hand from the hanging position: not engaged, and no angle trip, outside the window.
    for theta in (0.5, 1.5, 2.5, math.pi - 10 * DEG, math.pi + 2.5 * DEG, math.pi - 2.1 * DEG):
        row = s.tick(alpha_measured=theta, V_command=4.0)
        assert (row["state"], row["V"]) == (WAITING, 0.0), theta
        assert row["alpha"] == pytest.approx(theta - math.pi)
    # Inside the window: engaged in the same step, and the voltage passes through.
    row = s.tick(alpha_measured=math.pi - 1.5 * DEG, V_command=4.0)
    assert (row["state"], row["V"], row["motor_enable"]) == (RUNNING, 4.0, True)
    assert any("waiting for capture -> running (captured" in m for m in s.log)
    # Running: the angle limit applies in the upright convention.
    assert s.tick(alpha_measured=theta_for(-14 * DEG), V_command=4.0)["V"] == 4.0
    row = s.tick(alpha_measured=theta_for(-16 * DEG), V_command=4.0)
    assert (row["state"], row["trip_reason"], row["V"]) == (TRIPPED, TRIP_ANGLE, 0.0)
    assert row["alpha"] == pytest.approx(-16 * DEG)


@pytest.mark.parametrize("theta, alpha", [(0.0, math.pi), (2 * math.pi, math.pi), (-0.1, math.pi - 0.1),
                                          (math.pi, 0.0), (3 * math.pi + 0.2, 0.2), (1e-9, -math.pi + 1e-9)])
def test_rig_angle_is_wrapped_into_minus_pi_pi(make, theta, alpha):
    s = make(rig_mode=True, auto_start=False)
    got = s.tick(alpha_measured=theta)["alpha"]
    assert -math.pi < got <= math.pi
    assert got == pytest.approx(alpha, abs=1e-12)
    assert rig_to_upright(theta) == pytest.approx(got, abs=1e-15)  # the Python helper agrees with the FMU


def test_rig_capture_from_either_side_of_the_wrap(make):
    for theta in (math.pi + 1 * DEG, -math.pi + 1 * DEG):  # the encoder may count either way
        s = make(rig_mode=True)
        assert s.tick(alpha_measured=0.0)["state"] == WAITING  # auto_start in rig mode waits for capture
        assert s.tick(alpha_measured=theta, V_command=1.0)["V"] == 1.0


def test_rig_rearm_while_hanging_then_capture_again(make):
    s = make(rig_mode=True, auto_start=False)
    s.tick("start", alpha_measured=math.pi)  # captured at once
    assert s.tick(alpha_measured=math.pi + 20 * DEG)["state"] == TRIPPED
    row = s.tick("rearm", alpha_measured=0.0)  # the pendulum hangs after a trip: re-arm is still allowed
    assert row["state"] == IDLE
    row = s.tick("start", alpha_measured=0.0, V_command=2.0)
    assert (row["state"], row["V"]) == (WAITING, 0.0)
    # Pause and resume go through the capture window again.
    assert s.tick(alpha_measured=math.pi, V_command=2.0)["state"] == RUNNING
    s.tick("pause", alpha_measured=math.pi)
    row = s.tick("start", alpha_measured=math.pi - 5 * DEG, V_command=2.0)
    assert (row["state"], row["V"]) == (WAITING, 0.0)


def test_rig_capture_needs_the_cart_within_the_track(make):
    s = make(rig_mode=True)
    row = s.tick(alpha_measured=math.pi, x_measured=0.45, V_command=1.0)
    assert (row["state"], row["V"]) == (WAITING, 0.0)
    assert s.tick(alpha_measured=math.pi, x_measured=0.3, V_command=1.0)["state"] == RUNNING


# ---------------------------------------------------------------- calibration mode
def test_calibration_start_needs_the_cart_centred(make):
    s = make(calibration_mode=True, auto_start=False, centre_tolerance=0.01)
    row = s.tick("start", x_measured=0.02, V_command=1.0)
    assert (row["state"], row["V"]) == (IDLE, 0.0)
    refused = [m for m in s.log if "start refused" in m]
    assert len(refused) == 1 and "centre" in refused[0] and "0.0200 m" in refused[0]
    s.tick(x_measured=-0.005)  # the key released: the next press is a new command
    row = s.tick("start", x_measured=-0.005, V_command=1.0)
    assert (row["state"], row["V"]) == (RUNNING, 1.0)
    # Pendulum removed: the angle input is ignored; the track limit still trips.
    assert s.tick(alpha_measured=2.0, x_measured=0.2, V_command=1.0)["state"] == RUNNING
    assert s.tick(alpha_measured=math.nan, x_measured=0.2, V_command=1.0)["state"] == RUNNING
    row = s.tick(x_measured=-0.41, V_command=1.0)
    assert (row["state"], row["trip_reason"], row["V"]) == (TRIPPED, TRIP_TRACK, 0.0)
    # After the trip the cart is at the end of the track: re-arm, but start only once centred.
    assert s.tick("rearm", x_measured=-0.39)["state"] == IDLE
    assert s.tick("start", x_measured=-0.39)["state"] == IDLE
    s.tick(x_measured=0.0)
    assert s.tick("start", x_measured=0.0)["state"] == RUNNING


def test_the_seesaw_starts_only_held_level(make):
    """Issue 20, the seesaw's start rule (level_start): hold it level, then start. Tilted (resting on its stop, or
    beyond the capture window), a start is refused with the reason; level, it starts; after a trip the same."""
    s = make(level_start=True, auto_start=False, alpha_max=10 * DEG)
    row = s.tick("start", alpha_measured=-11.5 * DEG, V_command=1.0)
    assert (row["state"], row["V"]) == (IDLE, 0.0)
    refused = [m for m in s.log if "start refused" in m]
    assert len(refused) == 1 and "not level" in refused[0] and "11.5 deg" in refused[0], refused
    s.tick(alpha_measured=1.2 * CAPTURE_WINDOW_DEFAULT)
    assert s.tick("start", alpha_measured=1.2 * CAPTURE_WINDOW_DEFAULT)["state"] == IDLE
    s.tick(alpha_measured=0.5 * CAPTURE_WINDOW_DEFAULT)
    row = s.tick("start", alpha_measured=-0.5 * CAPTURE_WINDOW_DEFAULT, V_command=1.0)
    assert (row["state"], row["V"]) == (RUNNING, 1.0)
    # Running, the tilt may go anywhere within the angle limit (a 5-degree tap); beyond it, the trip.
    assert s.tick(alpha_measured=5 * DEG, V_command=1.0)["state"] == RUNNING
    assert s.tick(alpha_measured=10.5 * DEG)["state"] == TRIPPED
    s.tick(alpha_measured=-11.5 * DEG)
    assert s.tick("start", alpha_measured=-11.5 * DEG)["state"] == TRIPPED  # not level: still tripped
    s.tick(alpha_measured=0.0)
    assert s.tick("start", alpha_measured=0.0)["state"] == RUNNING
    # Without the rule (the pendulum in simulation), a start is a start.
    plain = make(auto_start=False, alpha_max=10 * DEG)
    assert plain.tick("start", alpha_measured=5 * DEG)["state"] == RUNNING


def test_calibration_auto_start_refused_off_centre(make):
    s = make(calibration_mode=True, x_measured=0.05)
    assert s.tick(x_measured=0.05)["state"] == IDLE
    assert any("start refused" in m for m in s.log)


def test_calibration_mode_on_the_rig_needs_no_capture(make):
    s = make(calibration_mode=True, rig_mode=True)
    assert s.tick(alpha_measured=0.0, V_command=1.0)["V"] == 1.0


def test_calibration_iteration_is_announced(make):
    s = make(calibration_mode=True)
    s.tick(iteration=1)
    s.tick(iteration=1)
    s.tick(iteration=2)
    assert [m for m in s.log if "iteration" in m] == ["t=0.000 s: calibration iteration 1", "t=0.002 s: calibration iteration 2"]


# ---------------------------------------------------------------- parameters
@pytest.mark.parametrize("degrees", [9.9, 15.1, 0.0, -12.0, math.nan])
def test_alpha_max_outside_10_to_15_degrees_is_an_error(make, degrees):
    with pytest.raises(FMICallException):
        make(alpha_max=degrees * DEG)
    name = Supervisor.last_name
    errors = [m for status, _, m in MESSAGES[name] if status == 3]
    assert errors and "alpha_max" in errors[0] and "10 to 15 deg" in errors[0]


@pytest.mark.parametrize("alpha_max", [10 * DEG, 12.5 * DEG, 15 * DEG, 0.2618])
def test_alpha_max_within_range_is_accepted(make, alpha_max):
    s = make(alpha_max=alpha_max, capture_window=CAPTURE_WINDOW_DEFAULT)
    assert s.tick(alpha_measured=alpha_max * 0.99, V_command=1.0)["V"] == 1.0
    assert s.tick(alpha_measured=alpha_max * 1.01, V_command=1.0)["trip_reason"] == TRIP_ANGLE


@pytest.mark.parametrize("parameters, word", [
    (dict(x_max=0.0), "x_max"),
    (dict(capture_window=20 * DEG), "capture_window"),
    (dict(capture_window=0.0), "capture_window"),
    (dict(centre_tolerance=0.5), "centre_tolerance"),
    (dict(V_limit=-1.0), "V_limit"),
    (dict(V_limit=math.inf), "V_limit"),
])
def test_other_bad_parameters_are_errors(make, parameters, word):
    with pytest.raises(FMICallException):
        make(**parameters)
    name = Supervisor.last_name
    assert any(word in m for status, _, m in MESSAGES[name] if status == 3)


def test_python_codes_name_every_output_code():
    assert sorted(STATES) == list(range(7)) and sorted(TRIP_REASONS) == list(range(7))
    assert set(COMMANDS.values()) == set(range(5))
