"""Custom Python blocks (pythonfmu): the base class, the build and its patches, the LQR worked example."""

from __future__ import annotations

import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from pendulab.blocks import Block, Var, block_error, build_block, fix_model_description
from pendulab.blocks.loop import block_controller_system
from pendulab.blocks.lqr import (
    GAIN_NAMES,
    LQRController,
    build_lqr_controller,
    design_lqr,
)
from pendulab.cosim.master import Master, SimulationError
from pendulab.cosim.system import System
from pendulab.errors import UserError
from pendulab.model.linear import linearize
from pendulab.model.parameters import PlantParameters
from pendulab.simulation import simulate
from pendulab.spec import ControllerSpec, Poke, RunSpec, Timing

GAIN_SOURCE = '''
from pendulab.blocks import Block, Var

class Gain(Block):
    """y = k u, with a step counter."""
    feedthrough = {feedthrough}
    inputs = {{"u": Var(0.0, "rad", "Input")}}
    outputs = {{"y": Var(0.0, "rad", "k times u"), "steps": Var(0, description="Samples taken")}}
    parameters = {{"k": Var(2.0, None, "Gain")}}

    def step(self, t, h):
        self.y = self.k * self.u
        self.steps += 1
'''


def write_gain(folder: Path, feedthrough: bool = True) -> Path:
    path = folder / ("gain.py" if feedthrough else "gain_delayed.py")
    path.write_text(GAIN_SOURCE.format(feedthrough=feedthrough))
    return path


# ---------------------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def long_params() -> PlantParameters:
    return PlantParameters.preset(pendulum="long")


@pytest.fixture(scope="module")
def lqr_fmu(tmp_path_factory: pytest.TempPathFactory, long_params: PlantParameters) -> Path:
    return build_lqr_controller(tmp_path_factory.mktemp("lqr"), long_params)


@pytest.fixture(scope="module")
def lqr_run(lqr_fmu: Path, long_params: PlantParameters):
    """The default poke (50 rad/s^2 for 5 ms at 1 s), 5 s, long pendulum, Plant + LQR + Supervisor."""
    spec = RunSpec.for_parameters(ControllerSpec(fmu=str(lqr_fmu)), long_params, timing=Timing(stop_time=5.0))
    return simulate(spec, record=["plant.alphadot", "controller.xdot_estimate", "controller.alphadot_estimate"])


@pytest.fixture(scope="module")
def gain_fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[bool, Path]:
    folder = tmp_path_factory.mktemp("gain")
    return {ft: build_block(write_gain(folder, ft), folder / f"Gain_{ft}.fmu", start_values={"k": 2.5}) for ft in (True, False)}


# ---------------------------------------------------------------------------------------- the build
def test_lqr_fmu_passes_fmpy_validate(lqr_fmu: Path) -> None:
    assert validate_fmu(str(lqr_fmu)) == []


def test_lqr_fmu_declares_units_gains_and_initial_unknowns(lqr_fmu: Path, long_params: PlantParameters) -> None:
    md = read_model_description(str(lqr_fmu))
    variables = {v.name: v for v in md.modelVariables}
    for name, (_, var) in LQRController.variables().items():
        assert variables[name].unit == (var.unit if var.type == "Real" else None)
    assert {u.name for u in md.unitDefinitions} == set(LQRController.units().values())
    outputs = {v.name for v in md.modelVariables if v.causality == "output"}
    assert {u.variable.name for u in md.outputs} == outputs == {u.variable.name for u in md.initialUnknowns}
    # The design is baked into the start values.
    design = design_lqr(long_params)
    for name, k in zip(GAIN_NAMES, design.K):
        assert float(variables[name].start) == pytest.approx(k, rel=1e-12)
    assert float(variables["Lp_design"].start) == long_params.Lp


def test_pythonfmu_output_fails_validate_until_patched(tmp_path: Path) -> None:
    """What pythonfmu 0.7 writes for a plain slave is rejected by fmpy; fix_model_description repairs it."""
    from pythonfmu import FmuBuilder

    script = tmp_path / "plain_slave.py"
    script.write_text(textwrap.dedent('''
        from pythonfmu import Fmi2Slave, Fmi2Causality, Integer, Real

        class PlainSlave(Fmi2Slave):
            def __init__(self, **kwargs):
                super().__init__(**kwargs)
                self.u, self.y, self.k, self.n = 0.0, 0.0, 2.0, 0
                self.register_variable(Real("u", causality=Fmi2Causality.input))
                self.register_variable(Real("y", causality=Fmi2Causality.output))
                self.register_variable(Integer("n", causality=Fmi2Causality.output))
                self.register_variable(Real("k", causality=Fmi2Causality.parameter))

            def do_step(self, t, h):
                self.y = self.k * self.u
                return True
    '''))
    raw = Path(FmuBuilder.build_FMU(script, dest=tmp_path / "raw"))
    assert validate_fmu(str(raw)) != []
    fixed = tmp_path / "fixed.fmu"
    with zipfile.ZipFile(raw) as zin, zipfile.ZipFile(fixed, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = fix_model_description(data, units={"u": "V", "y": "V"})
            zout.writestr(item.filename, data)
    assert validate_fmu(str(fixed)) == []
    md = read_model_description(str(fixed))
    assert {v.name: v.unit for v in md.modelVariables if v.type == "Real"} == {"u": "V", "y": "V", "k": None}


# ---------------------------------------------------------------------------------------- the LQR design
def test_lqr_gains_solve_the_riccati_equation(long_params: PlantParameters) -> None:
    design = design_lqr(long_params)
    plant = linearize(long_params).ss
    P = scipy.linalg.solve_continuous_are(plant.A, plant.B, design.Q, np.array([[design.R]]))
    np.testing.assert_allclose(design.K, (plant.B.T @ P).ravel() / design.R, rtol=1e-8)
    poles = np.linalg.eigvals(plant.A - plant.B @ design.K[None, :])
    assert np.all(poles.real < 0)
    np.testing.assert_allclose(np.sort_complex(poles), np.sort_complex(design.closed_loop_poles), rtol=1e-8)


def test_lqr_design_rejects_bad_weights() -> None:
    with pytest.raises(UserError, match="weights"):
        design_lqr(q=(1.0, -1.0, 1.0, 0.0))


# ---------------------------------------------------------------------------------------- the LQR in the loop
def test_lqr_balances_the_long_pendulum_through_the_poke(lqr_run, long_params: PlantParameters) -> None:
    from pendulab.fmu.models.supervisor.config import RUNNING

    c = lqr_run.columns
    assert c["t"][-1] == pytest.approx(5.0)
    poke = c["t"] >= long_params.poke_start
    assert np.degrees(np.abs(c["alpha"][poke]).max()) > 0.5  # the poke did push
    assert np.degrees(np.abs(c["alpha"]).max()) < 4.0
    assert lqr_run.metrics["safety_cut_time_s"] is None
    assert np.all(c["supervisor_state"] == RUNNING)
    assert lqr_run.metrics["stable"] is True
    # The worked example is a working design: balanced with no warning (issue 24).
    assert lqr_run.verdict.clean, lqr_run.verdict.lines()
    assert np.all(np.isfinite(c["voltage_command"]))


def test_lqr_recentres_the_cart(lqr_run) -> None:
    x, t = lqr_run.columns["x"], lqr_run.columns["t"]
    excursion = np.abs(x).max()
    assert excursion > 0.01  # the poke moved the cart a measurable distance ...
    tail = t >= t[-1] - 0.5
    assert np.abs(x[tail]).max() < 0.2 * excursion  # ... and the position feedback brought it back
    assert abs(x[-1]) < 0.01


def test_lqr_velocity_estimates_follow_the_plant(lqr_run) -> None:
    c = lqr_run.columns
    busy = (c["t"] > 1.0) & (c["t"] < 2.0)
    for estimate, truth in (("controller.alphadot_estimate", "plant.alphadot"), ("controller.xdot_estimate", "xdot")):
        est, true = c[estimate][busy], c[truth][busy]
        assert np.corrcoef(est, true)[0, 1] > 0.9
        assert np.sqrt(np.mean((est - true) ** 2)) < 0.5 * np.abs(true).max()


def test_lqr_without_gains_fails_initialization_with_its_reason(tmp_path: Path) -> None:
    fmu = build_block(LQRController, tmp_path)  # class defaults: all gains zero
    with pytest.raises(SimulationError, match="no gains"):
        simulate(RunSpec(ControllerSpec(fmu=str(fmu)), poke=Poke(start=0.05), timing=Timing(stop_time=0.1)))


# ---------------------------------------------------------------------------------------- a user's block
@pytest.mark.parametrize("feedthrough", [True, False])
def test_user_gain_block_builds_validates_and_runs(gain_fmus: dict[bool, Path], plant_fmu: Path, feedthrough: bool) -> None:
    fmu = gain_fmus[feedthrough]
    assert validate_fmu(str(fmu)) == []
    system = System(step=1e-3)
    system.add("plant", plant_fmu, {"poke_start": 0.05})
    system.add("gain", fmu)
    system.connect("plant.alpha_measured", "gain.u")
    with Master(system) as master:
        log = master.run(0.6, ["plant.alpha_measured", "gain.y", "gain.steps"])
    u, y = log["plant.alpha_measured"], log["gain.y"]
    assert np.ptp(u) > 0.01  # the unstable pendulum falls after the poke: a moving input
    if feedthrough:  # sampled at the same point: y responds with no delay
        np.testing.assert_allclose(y, 2.5 * u)
        np.testing.assert_array_equal(log["gain.steps"], np.arange(1, len(u) + 1))
    else:  # computed in fmi2DoStep: one step later
        np.testing.assert_allclose(y[1:], 2.5 * u[:-1])
        np.testing.assert_array_equal(log["gain.steps"], np.arange(len(u)))


def test_user_block_is_not_a_loop_controller(gain_fmus: dict[bool, Path]) -> None:
    with pytest.raises(UserError, match="lacks the input 'alpha_measured', the output 'V_command', the parameter 'Lp'"):
        block_controller_system(gain_fmus[True])


def test_block_samples_once_per_point_and_again_after_a_late_input() -> None:
    class Counter(Block):
        """Counts its samples."""

        inputs = {"u": Var(0.0)}
        outputs = {"y": Var(0.0), "steps": Var(0)}

        def step(self, t: float, h: float) -> None:
            self.y = self.u
            self.steps += 1

    block = Counter(instance_name="counter")
    refs = {v.name: vr for vr, v in block.vars.items()}
    block.setup_experiment(0.0)
    block.exit_initialization_mode()
    block.set_real([refs["u"]], [1.0])
    assert block.get_real([refs["y"]]) == [1.0]
    assert block.get_real([refs["y"]]) == [1.0] and block.steps == 1  # read twice, sampled once
    block.set_real([refs["u"]], [3.0])  # a master changes the input after reading: sample again
    assert block.get_real([refs["y"]]) == [3.0] and block.steps == 1
    block.do_step(0.0, 1e-3)
    assert block.steps == 1
    block.do_step(1e-3, 1e-3)  # no read at this point: sampled in the step
    assert block.steps == 2 and block.y == 3.0


def test_block_that_raises_stops_cleanly_with_its_reason() -> None:
    class Fragile(Block):
        """Fails after the first sample."""

        inputs = {"u": Var(0.0)}
        outputs = {"y": Var(0.0)}

        def step(self, t: float, h: float) -> None:
            if t > 0:
                raise ZeroDivisionError("u / 0")
            self.y = self.u

    block = Fragile(instance_name="fragile-test")
    y = next(vr for vr, v in block.vars.items() if v.name == "y")
    block.setup_experiment(0.0)
    block.exit_initialization_mode()
    assert block.do_step(0.0, 0.1) is True
    assert block.get_real([y]) == [0.0]  # the exception stays inside the block ...
    assert block.do_step(0.1, 0.1) is False  # ... and the step reports the failure
    assert block_error("fragile-test") == "Fragile (step at t = 0.1 s): ZeroDivisionError: u / 0"


def test_block_raising_in_the_master_ends_the_run_with_its_reason(tmp_path: Path) -> None:
    source = tmp_path / "boom.py"
    source.write_text(textwrap.dedent('''
        from pendulab.blocks import Block, Var

        class Boom(Block):
            """Fails at 0.2 s."""
            inputs = {"alpha_measured": Var(0.0, "rad")}
            outputs = {"V_command": Var(0.0, "V")}
            parameters = {"Lp": Var(0.6, "m")}

            def step(self, t, h):
                if t >= 0.2:
                    raise RuntimeError("boom")
    '''))
    with pytest.raises(SimulationError, match=r"Boom \(step at t = 0\.2 s\): RuntimeError: boom"):
        simulate(RunSpec(ControllerSpec(fmu=str(build_block(source, tmp_path))), poke=Poke(start=0.1), timing=Timing(stop_time=0.5)))


# ---------------------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    "source, start_values, message",
    [
        ("missing.py", None, "cannot read"),
        ("gain.txt", None, "must be a Python file"),
        ("empty.py", None, "defines no block class"),
        ("two.py", None, "several block classes"),
        ("broken.py", None, "does not import"),
        ("gain.py", {"gain": 1.0}, "no parameter or input 'gain'"),
        ("gain.py", {"y": 1.0}, "no parameter or input 'y'"),
        ("gain.py", {"k": "fast"}, "not a Real"),
    ],
)
def test_build_block_rejects_bad_input_cleanly(tmp_path: Path, source: str, start_values, message: str) -> None:
    write_gain(tmp_path)
    (tmp_path / "gain.txt").write_text("")
    (tmp_path / "empty.py").write_text("x = 1\n")
    (tmp_path / "two.py").write_text(GAIN_SOURCE.format(feedthrough=True) + GAIN_SOURCE.format(feedthrough=True).replace("class Gain", "class Gain2"))
    (tmp_path / "broken.py").write_text("import no_such_module_here\n")
    out = tmp_path / "out"
    with pytest.raises(UserError, match=message) as info:
        build_block(tmp_path / source, out, start_values=start_values)
    assert "\n" not in str(info.value)
    assert not out.exists() or list(out.iterdir()) == []


def test_build_block_reports_an_unusable_output_folder(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("")
    with pytest.raises(UserError, match="cannot create the output folder"):
        build_block(write_gain(tmp_path), tmp_path / "file" / "sub")


@pytest.mark.parametrize(
    "tables, message",
    [
        ({"inputs": {"vars": Var(0.0)}}, "clashes"),
        ({"outputs": {"step": Var(0.0)}}, "clashes"),
        ({"parameters": {"K": Var(3, "V/m")}}, "integer start"),
        ({"inputs": {"u": 1.0}}, "must be declared as Var"),
        ({"inputs": {"u": Var(0.0)}, "outputs": {"u": Var(0.0)}}, "also declared"),
        ({"inputs": {"_u": Var(0.0)}}, "not a valid name"),
    ],
)
def test_block_declarations_are_checked(tables: dict, message: str) -> None:
    with pytest.raises(UserError, match=message):
        type("Bad", (Block,), {**tables, "step": lambda self, t, h: None})
