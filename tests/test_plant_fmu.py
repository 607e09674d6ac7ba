"""Plant.fmu runs: Co-Simulation equals the CasADi model, Model Exchange agrees with Co-Simulation,
and independent FMI engines give fmpy's trajectory (issue 2, must-shows 3 and 4; SPEC §6)."""

from __future__ import annotations

import math
from ctypes import c_double
from pathlib import Path
from typing import Mapping, Sequence

import fmi_harness
import numpy as np
import pytest
from fmi_harness import VARARGS_AS_FIXED, Slave, capturing_callbacks, value_references
from fmpy import simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Model

from pendulab.model.parameters import PlantParameters
from pendulab.model.plant import OUTPUTS, STATES, PlantModel

ALL_OUTPUTS = (*STATES, *OUTPUTS)


def run_cs(
    unzipdir: Path,
    voltages: Sequence[float],
    step: float | Sequence[float] = 1e-3,
    start: Mapping[str, float] | None = None,
    outputs: Sequence[str] = STATES,
) -> np.ndarray:
    """Co-simulate with fmpy: V held over each step; rows are ``outputs`` at t = 0, t1, ..., tn."""
    return fmi_harness.run_cs(unzipdir, outputs, {"V": voltages}, step=step, start=start)


def reference(params: PlantParameters, voltages: Sequence[float], step: float = 1e-3, x0: Sequence[float] = (0, 0, 0, 0)) -> np.ndarray:
    return PlantModel().simulate(params, np.asarray(voltages, dtype=float), step, x0)


def saturating_voltage(n: int, step: float = 1e-3) -> np.ndarray:
    """A chirp-like command that swings well past the +-10 V saturation."""
    t = np.arange(n) * step
    return 14.0 * np.sin(2 * np.pi * (0.5 + 1.5 * t) * t)


# ---------------------------------------------------------------- Co-Simulation == CasADi model
def test_co_simulation_equals_the_casadi_model(plant_unzipdir: Path) -> None:
    """Friction on, poke at 1 s, V saturating, the pendulum falling over and swinging through: 2.5 s."""
    n = 2500
    V = saturating_voltage(n)
    params = PlantParameters.preset("long")
    fmu = run_cs(plant_unzipdir, V, start={"alpha": 0.05})
    ref = reference(params, V, x0=(0, 0, 0.05, 0))
    assert np.max(np.abs(fmu[:, 2])) > math.pi, "the pendulum swung over: a demanding trajectory"
    np.testing.assert_allclose(fmu, ref, rtol=1e-9, atol=1e-9)


def test_co_simulation_outputs_equal_the_casadi_outputs(plant_unzipdir: Path) -> None:
    """alpha_measured, x_measured, V_applied and F_friction after each step, from the same CasADi function."""
    n = 1500
    V = 0.3 * saturating_voltage(n) + 1.0  # reaches the sticking and slipping regions
    params = PlantParameters.preset("long", q_alpha=2 * math.pi / 4096)
    start = {"alpha": math.pi + 0.2, "q_alpha": params.q_alpha}
    fmu = run_cs(plant_unzipdir, V, start=start, outputs=ALL_OUTPUTS)
    states = reference(params, V, x0=(0, 0, math.pi + 0.2, 0))
    np.testing.assert_allclose(fmu[:, :4], states, rtol=1e-9, atol=1e-9)
    outputs = PlantModel().outputs
    p = params.as_vector()
    for k in range(1, n + 1):
        expected = np.asarray(outputs(states[k], V[k - 1], p, k * 1e-3)).ravel()
        np.testing.assert_allclose(fmu[k, 4:], expected, rtol=1e-9, atol=1e-12, err_msg=f"step {k}")
    friction = fmu[:, ALL_OUTPUTS.index("F_friction")]
    assert np.any(friction == 0) and np.any(friction != 0), "both friction regimes visited"


@pytest.mark.parametrize(
    "step",
    [1e-3, 2.5e-4, 1.23e-3, 5e-5],
    ids=["1ms-10-substeps", "0.25ms-3-substeps", "1.23ms-13-substeps", "0.05ms-1-substep"],
)
def test_sub_steps_follow_the_model_rule(plant_unzipdir: Path, step: float) -> None:
    """Equal RK4 sub-steps of at most 0.1 ms, the same rule as PlantModel.simulate, for any step size."""
    n = int(round(0.3 / step))
    V = np.full(n, 4.0)
    params = PlantParameters.preset("short", "ip01")
    start = {"alpha": math.pi - 0.4, "Mp": params.Mp, "Lp": params.Lp, "lp": params.lp, "Ip": params.Ip,
             "M_cart": params.M_cart, "Beq": params.Beq, "V": 4.0}
    fmu = run_cs(plant_unzipdir, V, step=step, start=start)
    ref = reference(params, V, step, x0=(0, 0, math.pi - 0.4, 0))
    np.testing.assert_allclose(fmu, ref, rtol=1e-9, atol=1e-12)


def test_variable_communication_steps(plant_unzipdir: Path) -> None:
    """Mixed step sizes in one run: each step splits itself into <= 0.1 ms RK4 sub-steps."""
    steps = [1e-3, 3e-4, 2e-3, 1e-4, 7e-4] * 40
    V = np.linspace(-3, 3, len(steps))
    fmu = run_cs(plant_unzipdir, V, step=steps, start={"alpha": math.pi + 0.1})
    p = PlantParameters.preset("long")
    state, t = np.array([0, 0, math.pi + 0.1, 0]), 0.0
    for k, (v, h) in enumerate(zip(V, steps)):
        state = PlantModel().simulate(p, [v], h, state)[-1] if t < 0.99 else state  # the poke (1 s) is after the run
        t += h
    assert t < 0.99
    np.testing.assert_allclose(fmu[-1], state, rtol=1e-9, atol=1e-12)


def test_parameters_are_used(plant_unzipdir: Path) -> None:
    """Changing a parameter in the FMU changes the trajectory exactly as in the model (current limit, Beq)."""
    V = np.full(400, 8.0)
    params = PlantParameters.preset("long", I_max=1.0, Beq=6.0, F1=0.0, F2=0.0)
    fmu = run_cs(plant_unzipdir, V, start={"alpha": math.pi, "I_max": 1.0, "Beq": 6.0, "F1": 0.0, "F2": 0.0})
    ref = reference(params, V, x0=(0, 0, math.pi, 0))
    np.testing.assert_allclose(fmu, ref, rtol=1e-9, atol=1e-12)
    unlimited = reference(params.with_values(I_max=0.0), V, x0=(0, 0, math.pi, 0))
    assert abs(unlimited[-1, 1] - fmu[-1, 1]) > 0.01, "the current limit matters here"


# ---------------------------------------------------------------- Model Exchange
# Friction off, no poke, no end stop within reach: a smooth right-hand side.
SMOOTH = {"F1": 0.0, "F2": 0.0, "poke_magnitude": 0.0, "track_half_length": 1e4}


def model_exchange(plant_fmu: Path, start: Mapping[str, float], stop: float, rtol: float = 1e-8) -> np.ndarray:
    """fmpy's CVode run, sampled every 1 ms (event rows and off-grid samples dropped)."""
    result = simulate_fmu(
        str(plant_fmu), fmi_type="ModelExchange", solver="CVode", relative_tolerance=rtol, output_interval=1e-3,
        stop_time=stop, start_values=dict(start), output=list(STATES),
    )
    k = result["time"] / 1e-3
    on_grid = np.abs(k - np.round(k)) < 1e-6
    index = np.round(k[on_grid]).astype(int)
    rows = np.full((int(round(stop / 1e-3)) + 1, 4), np.nan)
    rows[index] = np.column_stack([result[s] for s in STATES])[on_grid]  # last row wins at an event time
    assert not np.isnan(rows).any()
    return rows


@pytest.mark.parametrize(
    "start, V",
    [({"alpha": math.pi + 0.3}, 2.0), ({"alpha": 0.3, "Bp": 0.01}, -6.0), ({"alpha": math.pi, "xdot": 0.2, "I_max": 3.0}, 9.0)],
    ids=["hanging-swing", "falling-from-upright", "current-limited"],
)
def test_model_exchange_cvode_matches_co_simulation(plant_fmu: Path, plant_unzipdir: Path, start: dict, V: float) -> None:
    stop = 3.0
    start = {**SMOOTH, **start, "V": V}
    me = model_exchange(plant_fmu, start, stop)
    cs = run_cs(plant_unzipdir, np.full(int(round(stop / 1e-3)), V), start=start)
    np.testing.assert_allclose(me, cs, rtol=0, atol=1e-4)


@pytest.mark.parametrize("poke_start", [1.0, 1.00037])  # edges on and inside a sub-step
def test_model_exchange_matches_co_simulation_with_a_poke(plant_fmu: Path, plant_unzipdir: Path, poke_start: float) -> None:
    # The RK4 sub-steps use the poke averaged over each sub-step, so the impulse is exact in CS too.
    start = {"F1": 0.0, "F2": 0.0, "alpha": math.pi + 0.3, "V": 2.0, "poke_start": poke_start}
    me = model_exchange(plant_fmu, start, 2.0)
    cs = run_cs(plant_unzipdir, np.full(2000, 2.0), start=start)
    np.testing.assert_allclose(me, cs, rtol=0, atol=1e-4)


def test_model_exchange_reports_the_poke_as_time_events(plant_fmu: Path) -> None:
    """CVode stops at the poke's edges: without them it would step across a 5 ms pulse unaware."""
    result = simulate_fmu(
        str(plant_fmu), fmi_type="ModelExchange", solver="CVode", output_interval=0.1, stop_time=2.0,
        start_values={"poke_start": 1.23456, "poke_duration": 0.004, "F1": 0.0, "F2": 0.0}, output=["alpha"],
    )
    times = result["time"]
    assert np.any(np.isclose(times, 1.23456, atol=1e-12)) and np.any(np.isclose(times, 1.23856, atol=1e-12))
    # The poke pushes the upright pendulum (positive alpha) and nothing else does.
    assert np.all(result["alpha"][times < 1.23456] == 0) and result["alpha"][-1] > 0


def test_model_exchange_derivatives_equal_the_casadi_ode(plant_unzipdir: Path) -> None:
    guid, vr = value_references(plant_unzipdir)
    fmu = FMU2Model(guid=guid, modelIdentifier="Plant", unzipDirectory=str(plant_unzipdir), instanceName="plant")
    fmu.instantiate()
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.enterContinuousTimeMode()
        ode = PlantModel().ode
        p = PlantParameters().as_vector()
        rng = np.random.default_rng(2)
        for _ in range(50):
            state = rng.normal(size=4) * [0.1, 0.3, 2.0, 3.0]  # inside the end stops
            t, V = float(rng.uniform(0, 2)), float(rng.uniform(-15, 15))
            fmu.setTime(t)
            fmu.setReal([vr["V"]], [V])
            fmu.setContinuousStates((c_double * 4)(*state), 4)
            # The switches are a discrete state that changes only at events (issue 12): an event here
            # lets the FMU pick the regime the law gives at this state.
            fmu.enterEventMode()
            fmu.newDiscreteStates()
            fmu.enterContinuousTimeMode()
            derivatives = (c_double * 4)()
            fmu.getDerivatives(derivatives, 4)
            got = np.array(derivatives)
            np.testing.assert_allclose(got, np.asarray(ode(state, V, p, t)).ravel(), rtol=1e-12, atol=1e-12)
            assert fmu.getReal([vr[f"der({s})"] for s in STATES]) == pytest.approx(list(got), rel=1e-12, abs=1e-12)
    finally:
        fmu.terminate()
        fmu.freeInstance()


# ---------------------------------------------------------------- bad parameters inside the FMU
@pytest.mark.parametrize(
    "name, value, words",
    [("M_cart", -0.5, "M_cart = -0.5 is outside its range 0.01 to 100 kg"), ("Rm", 0.0, "Rm = 0 is outside"),
     ("Beq", math.nan, "Beq = nan is outside"), ("g", math.inf, "g = inf is outside"), ("Mp", -1.0, "Mp = -1 is outside")],
)
def test_fmu_refuses_a_parameter_out_of_its_range(plant_unzipdir: Path, name: str, value: float, words: str) -> None:
    messages: list[str] = []
    with Slave(plant_unzipdir, callbacks=capturing_callbacks(messages), initialize=False) as plant:
        plant.fmu.setupExperiment(startTime=0.0)
        plant.fmu.enterInitializationMode()
        with pytest.raises(FMICallException):
            plant.set({name: value})
        plant.fmu.exitInitializationMode()  # the refused value was not set: the defaults initialize
        if VARARGS_AS_FIXED:
            assert len(messages) == 1 and words in messages[0], messages


@pytest.mark.parametrize(
    "values, words",
    [({"Lp": 0.0}, "lp <= Lp is violated (lp = 0.3302, Lp = 0)"),
     ({"Ip": 0.0, "lp": 0.0}, "the pendulum has mass but no inertia"),
     ({"x": 1.0}, "abs(x) <= track_half_length is violated (x = 1, track_half_length = 0.407)")],
)
def test_fmu_refuses_parameters_that_contradict_each_other(plant_unzipdir: Path, values: dict, words: str) -> None:
    """Each value within its range, but not together (or the cart starting beyond its end stop)."""
    messages: list[str] = []
    with Slave(plant_unzipdir, callbacks=capturing_callbacks(messages), initialize=False) as plant:
        plant.fmu.setupExperiment(startTime=0.0)
        plant.fmu.enterInitializationMode()
        plant.set(values)
        with pytest.raises(FMICallException):
            plant.fmu.exitInitializationMode()
        if VARARGS_AS_FIXED:
            assert len(messages) == 1 and words in messages[0], messages


def test_non_finite_input_is_an_error_not_a_saturated_voltage(plant_unzipdir: Path) -> None:
    """fmin/fmax would read NaN as -V_max; the FMU refuses a non-finite V instead."""
    with pytest.raises(FMICallException):
        run_cs(plant_unzipdir, [1.0, math.nan, 1.0])


# ---------------------------------------------------------------- independent FMI engines
def test_ecos_gives_the_fmpy_trajectory(plant_fmu: Path, plant_unzipdir: Path) -> None:
    """Ecos (ecospy) runs the same Plant.fmu: friction on, saturating V, 2 s with the poke."""
    pytest.importorskip("ecospy")
    n = 2000
    V = saturating_voltage(n)
    start = {"alpha": math.pi + 0.2, "Beq": 3.0}
    ecos = fmi_harness.ecos_run(plant_fmu, ALL_OUTPUTS, V, start)
    fmpy_run = run_cs(plant_unzipdir, V, start=start, outputs=ALL_OUTPUTS)
    assert np.ptp(ecos[:, 2]) > 0.3, "a real swing, not a resting state"
    np.testing.assert_allclose(ecos, fmpy_run, rtol=1e-9, atol=1e-12)


def test_libcosim_gives_the_fmpy_trajectory(plant_fmu: Path, plant_unzipdir: Path) -> None:
    """libcosim (libcosimpy, DNV's Open Simulation Platform) as a second independent engine."""
    pytest.importorskip("libcosimpy")
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.ERROR)
    _, vr = value_references(plant_unzipdir)
    n, V = 1500, 2.0
    execution = CosimExecution.from_step_size(step_size=1_000_000)  # nanoseconds
    index = execution.add_local_slave(local_slave=CosimLocalSlave(fmu_path=str(plant_fmu), instance_name="plant"))
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer=observer)
    execution.real_initial_value(index, vr["alpha"], math.pi + 0.2)
    execution.real_initial_value(index, vr["V"], V)
    rows = []
    for _ in range(n):
        assert execution.step()
        rows.append(observer.last_real_values(index, [vr[s] for s in STATES]))
    cosim = np.array(rows)
    fmpy_run = run_cs(plant_unzipdir, np.full(n, V), start={"alpha": math.pi + 0.2, "V": V})[1:]
    # libcosim counts time in integer nanoseconds, so step sizes may differ from 1e-3 in the last bit.
    np.testing.assert_allclose(cosim, fmpy_run, rtol=1e-9, atol=1e-12)
