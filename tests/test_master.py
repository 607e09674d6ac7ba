"""The co-simulation master (SPEC §7): native plan runner == Python loop, plant == CasADi model,
events at the right step for one step, wiring checks, FMU errors named by component."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from pendulab.control.controller import demo_controller, unstable_example
from pendulab.control.realization import discretize
from pendulab.cosim.master import Event, Master, SimulationError, native_runner
from pendulab.cosim.pendulum import RECORDED, pendulum_system
from pendulab.cosim.system import System
from pendulab.errors import UserError
from pendulab.fmu.models.supervisor.config import COMMANDS, PAUSED, RUNNING, TRIPPED
from pendulab.model.parameters import PlantParameters
from pendulab.model.plant import STATES, PlantModel

H = 1e-3
#: Everything the loop logs, plus inputs (an input can be read back: the value the master set).
PLANT_STATES = [f"plant.{s}" for s in STATES]
LOOP_RECORD = [*RECORDED, "controller.e", "plant.V", "supervisor.command", "supervisor.motor_enable"]


def loop_system(controller=None, **params) -> System:
    """The three-FMU loop with the poke early (0.3 s) so that runs stay short."""
    p = PlantParameters.preset().with_values(poke_start=0.3, **params)
    return pendulum_system(p, discretize(controller or demo_controller(), h=H).to_parameters(), step=H)


def plant_system(plant_fmu: Path, V: float = 0.0, **start: float) -> System:
    """The plant alone, its input held at ``V`` (a start value), from the given initial state."""
    system = System(step=H)
    system.add("plant", plant_fmu, {**PlantParameters.preset().as_dict(), "V": V, **start})
    return system


def run(system: System, stop_time: float, record, native: bool, **kw) -> dict[str, np.ndarray]:
    with Master(system, native=native) as master:
        return master.run(stop_time, list(record), **kw)


def test_the_native_runner_is_available():
    """Without a C compiler the master falls back to the Python loop; on this machine it must not."""
    assert native_runner() is not None


# ---------------------------------------------------------------- native runner == Python loop
@pytest.mark.parametrize(
    "case",
    ["demo with pause and start", "unstable (safety cut)"],
)
def test_native_runner_and_python_loop_give_bit_identical_logs(loop_fmus, case):
    if case.startswith("demo"):
        system = loop_system()
        events = (Event(0.8, "supervisor.command", COMMANDS["pause"]), Event(0.85, "supervisor.command", COMMANDS["start"]))
    else:
        system, events = loop_system(unstable_example()), ()
    native = run(system, 1.5, LOOP_RECORD, True, events=events)
    python = run(system, 1.5, LOOP_RECORD, False, events=events)
    assert native.keys() == python.keys() == {"time", *LOOP_RECORD}
    for name in native:
        assert native[name].shape == (1501,)
        np.testing.assert_array_equal(native[name], python[name], err_msg=name)
    # Not a trivially quiet run: the poke moved the pendulum and the controller acted.
    assert np.ptp(native["plant.alpha"]) > 1e-3 and np.ptp(native["controller.V_command"]) > 0.1
    if case.startswith("unstable"):
        assert native["supervisor.state"][-1] == TRIPPED


def test_stop_when_ends_both_paths_at_the_same_point(loop_fmus):
    system = loop_system(unstable_example())
    tripped = lambda row: row["supervisor.state"] == TRIPPED  # noqa: E731
    logs = [run(system, 3.0, RECORDED, native, stop_when=tripped) for native in (True, False)]
    native, python = logs
    n = len(native["time"])
    assert n < 3001 and n % 100 == 0, "checked every 100 steps, stopped early"
    assert native["supervisor.state"][-1] == TRIPPED and native["supervisor.state"][-101] != TRIPPED
    for name in native:
        np.testing.assert_array_equal(native[name], python[name], err_msg=name)


def test_progress_is_reported_every_simulated_second(loop_fmus):
    for native in (True, False):
        seen: list[float] = []
        run(loop_system(), 2.5, ["plant.x"], native, progress=seen.append)
        assert seen == pytest.approx([1.0, 2.0])


# ---------------------------------------------------------------- plant == CasADi reference
@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
def test_plant_driven_by_a_fixed_input_equals_the_casadi_model(plant_fmu, native):
    params = PlantParameters.preset().with_values(poke_start=0.2)
    system = System(step=H)
    system.add("plant", plant_fmu, {**params.as_dict(), "V": 2.5, "alpha": 0.05})
    n = 600
    log = run(system, n * H, PLANT_STATES, native)
    ours = np.column_stack([log[s] for s in PLANT_STATES])
    reference = PlantModel().simulate(params, np.full(n, 2.5), H, x0=(0.0, 0.0, 0.05, 0.0))
    assert np.ptp(ours[:, 0]) > 1e-3, "the cart moved (the voltage overcame the stiction)"
    np.testing.assert_allclose(ours, reference, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(log["time"], H * np.arange(n + 1), rtol=0, atol=1e-12)


# ---------------------------------------------------------------- events
@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
def test_an_event_acts_at_its_step_for_one_step(plant_fmu, native):
    """V = 5 at t = 0.1 (on the grid) and V = -3 at t = 0.2503 (off the grid: the next point, 0.251)."""
    events = (Event(0.1, "plant.V", 5.0), Event(0.2503, "plant.V", -3.0))
    n = 400
    log = run(plant_system(plant_fmu, V=0.0), n * H, [*PLANT_STATES, "plant.V", "plant.V_applied"], native, events=events)
    V = np.zeros(n)
    V[100], V[251] = 5.0, -3.0
    np.testing.assert_array_equal(log["plant.V"], np.append(V, 0.0))
    np.testing.assert_array_equal(log["plant.V_applied"], np.append(V, 0.0))
    # The plant integrated exactly that input sequence (each value held for one step).
    reference = PlantModel().simulate(PlantParameters.preset(), V, H)
    np.testing.assert_allclose(np.column_stack([log[s] for s in PLANT_STATES]), reference, rtol=1e-9, atol=1e-12)
    assert np.any(reference[:, 1] != 0)


@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
def test_supervisor_pause_and_start_act_at_their_steps(loop_fmus, native):
    events = (Event(0.8, "supervisor.command", COMMANDS["pause"]), Event(0.9, "supervisor.command", COMMANDS["start"]))
    log = run(loop_system(), 1.2, LOOP_RECORD, native, events=events)
    state, command = log["supervisor.state"], log["supervisor.command"]
    k_pause, k_start = 800, 900
    # Each command is set for exactly one communication point, then the input returns to 0.
    expected = np.zeros_like(command)
    expected[k_pause], expected[k_start] = COMMANDS["pause"], COMMANDS["start"]
    np.testing.assert_array_equal(command, expected)
    # The supervisor acts in the step the command arrives: paused from 0.8 s, running again from 0.9 s.
    assert np.all(state[:k_pause] == RUNNING)
    assert np.all(state[k_pause:k_start] == PAUSED)
    assert np.all(state[k_start:] == RUNNING)
    voltage, enable = log["plant.V_applied"], log["supervisor.motor_enable"]
    assert np.all(voltage[k_pause:k_start] == 0) and not np.any(enable[k_pause:k_start])
    assert np.all(enable[:k_pause]) and np.all(enable[k_start:])
    # While running, the plant gets the (clamped) command; the controller keeps computing throughout.
    running = state == RUNNING
    np.testing.assert_array_equal(voltage[running], np.clip(log["controller.V_command"][running], -10, 10))
    assert np.any(log["controller.V_command"][k_pause:k_start] != 0)


@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
def test_events_at_the_same_point_all_apply(loop_fmus, native):
    """Two events at one communication point (one of them off the grid) on two components."""
    # (controller.r is the supervisor's output now: the other event sets the supervisor's free input iteration.)
    events = (Event(0.5, "supervisor.iteration", 7), Event(0.4995, "supervisor.command", COMMANDS["pause"]))
    record = ["controller.r", "controller.e", "plant.alpha_measured", "supervisor.command", "supervisor.state", "supervisor.iteration"]
    log = run(loop_system(), 0.6, record, native, events=events)
    assert np.flatnonzero(log["supervisor.iteration"]).tolist() == [500]
    assert np.flatnonzero(log["supervisor.command"]).tolist() == [500]
    assert log["supervisor.state"][499] == RUNNING and log["supervisor.state"][500] == PAUSED
    # The controller's error is e = r - Lp*alpha_measured (r = 0 from the supervisor: re-centring is off).
    Lp = PlantParameters.preset().Lp
    np.testing.assert_allclose(log["controller.e"], log["controller.r"] - Lp * log["plant.alpha_measured"], rtol=0, atol=1e-15)


def test_an_event_cannot_change_a_fixed_parameter_or_an_output(plant_fmu):
    """FMI 2.0: only inputs (and tunable parameters) may change during a run."""
    for target in ("plant.Beq", "plant.x"):
        with Master(plant_system(plant_fmu)) as master, pytest.raises(UserError, match="an event sets an input"):
            master.run(0.1, ["plant.x"], events=(Event(0.05, target, 1.0),))


# ---------------------------------------------------------------- wiring mistakes
def test_unknown_component_in_a_connection_is_a_user_error(plant_fmu):
    system = plant_system(plant_fmu)
    with pytest.raises(UserError, match="unknown component 'ctrl'"):
        system.connect("plant.alpha_measured", "ctrl.alpha_measured")
    with pytest.raises(UserError, match="component.variable"):
        system.connect("plant", "plant.V")
    with pytest.raises(UserError, match="already in the system"):
        system.add("plant", plant_fmu)


def test_doubly_connected_input_is_a_user_error(loop_fmus):
    system = loop_system()
    with pytest.raises(UserError, match="supervisor.V_command is already connected"):
        system.connect("plant.x", "supervisor.V_command")


@pytest.mark.parametrize(
    "source, target, words",
    [
        ("plant.nonsense", "controller.alpha_measured", "no variable 'nonsense'"),
        ("plant.alpha_measured", "controller.nonsense", "no variable 'nonsense'"),
        ("supervisor.state", "controller.alpha_measured", "joins a Integer to a Real"),
        ("supervisor.motor_enable", "controller.r", "joins a Boolean to a Real"),
        ("plant.x", "controller.V_command", "causality output"),
        ("plant.x", "controller.Lp", "causality parameter"),
        ("plant.V", "controller.r", "causality input"),
    ],
)
def test_bad_wiring_is_a_user_error_before_the_run(loop_fmus, source, target, words):
    system = System(step=H)
    for name, fmu in loop_fmus.items():
        system.add(name, fmu)
    system.connect(source, target)
    with Master(system) as master, pytest.raises(UserError, match=words):
        master.run(0.01, ["plant.x"])


@pytest.mark.parametrize(
    "record, events, words",
    [
        (["plant.nonsense"], (), "no variable 'nonsense'"),
        (["nobody.x"], (), "no component 'nobody'"),
        (["plant.x"], (Event(0.1, "nobody.V", 1.0),), "names no component"),
        (["plant.x"], (Event(0.1, "plant.nonsense", 1.0),), "no variable 'nonsense'"),
    ],
)
def test_bad_records_and_events_are_user_errors(plant_fmu, record, events, words):
    with Master(plant_system(plant_fmu)) as master, pytest.raises(UserError, match=words):
        master.run(0.1, record, events=events)


def test_other_master_mistakes_are_user_errors(plant_fmu, tmp_path):
    with pytest.raises(UserError, match="no components"):
        Master(System())
    missing = System()
    missing.add("plant", tmp_path / "Missing.fmu")
    with pytest.raises(UserError, match="does not exist"):
        Master(missing)
    (tmp_path / "Text.fmu").write_text("not a zip")
    not_zip = System()
    not_zip.add("plant", tmp_path / "Text.fmu")
    with pytest.raises(UserError, match="not an FMU"):
        Master(not_zip)
    with Master(plant_system(plant_fmu)) as master, pytest.raises(UserError, match="at least one step"):
        master.run(0.0004, ["plant.x"])


# ---------------------------------------------------------------- FMU errors
@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
def test_fmu_error_mid_run_names_the_component_and_time(plant_fmu, native):
    """A non-finite voltage reaches the plant at t = 0.3 s: the plant's doStep refuses it."""
    with pytest.raises(SimulationError, match=r"^plant: fmi2DoStep failed at t=0\.3000 s"):
        run(plant_system(plant_fmu), 1.0, ["plant.x"], native, events=(Event(0.3, "plant.V", math.nan),))


@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
def test_controller_refuses_a_step_other_than_its_period(loop_fmus, native):
    p = PlantParameters.preset()
    system = pendulum_system(p, discretize(demo_controller(), h=2e-3).to_parameters(), step=H)
    system.components["controller"].start_values["h"] = 2e-3
    with pytest.raises(SimulationError, match=r"^controller: fmi2DoStep failed at t=0\.0000 s"):
        run(system, 0.1, ["plant.x"], native)


def test_bad_start_values_fail_initialization_naming_the_component(loop_fmus):
    system = loop_system()
    system.components["supervisor"].start_values["alpha_max"] = 1.0  # 57 deg: outside 10..15 deg
    with Master(system) as master, pytest.raises(SimulationError, match="^supervisor: initialization failed"):
        master.run(0.1, ["plant.x"])


def test_master_frees_its_instances_and_folders(plant_fmu):
    master = Master(plant_system(plant_fmu))
    folders = [c.folder for c in master.instances.values()]
    assert folders and all(Path(d).is_dir() for d in folders)
    # Only what a run needs is unpacked: no sources, no other platform's binary.
    unpacked = {p.relative_to(folders[0]).parts[0] for p in Path(folders[0]).rglob("*")}
    assert "sources" not in unpacked and {"binaries", "modelDescription.xml"} <= unpacked
    assert len(list(Path(folders[0], "binaries").iterdir())) == 1
    with master:
        master.run(0.01, ["plant.x"])
    assert not master.instances and not any(Path(d).exists() for d in folders)
