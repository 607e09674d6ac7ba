"""Issue 25: model descriptions other FMI tools can trust.

* every output and derivative declares its dependencies; they are checked against the CasADi model's
  Jacobian structure and against a finite-difference probe of the built FMUs;
* the model descriptions validate against the official FMI 2.0 and 3.0 schemas (shipped in fmpy)
  (``fmpy validate`` of every FMU: test_fmu_capabilities);
* the wired loop plant -> controller -> supervisor -> plant has no algebraic loop by these declarations;
* every variable with a range refuses a value outside it, with a log line naming it (FMI 2.0 and 3.0);
* units carry their SI base units, angles display in degrees, the documentation is inside the FMU.
"""

from __future__ import annotations

import math
import zipfile
from ctypes import c_double
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from fmi_harness import Slave
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Model
from fmpy.fmi3 import FMU3Slave

from pendulab.cosim.pendulum import CONNECTIONS
from pendulab.fmu.build import model_spec
from pendulab.fmu.description import model_description_xml
from pendulab.fmu.units import UNITS
from pendulab.model.parameters import PlantParameters
from pendulab.model.plant import OUTPUTS, STATES, PlantModel

lxml_etree = pytest.importorskip("lxml.etree")
SCHEMAS = Path(__import__("fmpy").__file__).parent / "schema"


@pytest.fixture(scope="module")
def fmus(plant_fmu, plant3_fmu, controller_fmu, supervisor_fmu, seesaw_fmu, seesaw3_fmu) -> dict[str, Path]:
    return {"Plant": plant_fmu, "Plant3": plant3_fmu, "Controller": controller_fmu, "Supervisor": supervisor_fmu,
            "Seesaw": seesaw_fmu, "Seesaw3": seesaw3_fmu}


@pytest.fixture(scope="module")
def unzipped(fmus, tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("unzipped")
    return {name: Path(extract(str(path), unzipdir=str(root / name))) for name, path in fmus.items()}


def declared(description, kind: str = "outputs") -> dict[str, dict[str, str]]:
    """unknown -> {known: dependenciesKind} as fmpy reads them (None: the attribute is missing)."""
    table = {}
    for unknown in getattr(description, kind):
        if unknown.dependencies is None:
            table[unknown.variable.name] = None
        else:
            kinds = unknown.dependenciesKind or ["dependent"] * len(unknown.dependencies)
            table[unknown.variable.name] = {v.name: k for v, k in zip(unknown.dependencies, kinds)}
    return table


# ---------------------------------------------------------------- dependencies: CasADi
def casadi_structure(model) -> dict[str, set[str]]:
    """What a cart model's outputs and derivatives depend on by the Jacobian structure of its CasADi functions
    (derivatives: Co-Simulation's law and Model Exchange's law with frozen switches together)."""
    ode, outputs_function, _, ode_regime, _, _ = model.functions
    states = [f"x{k}" for k in range(ode.size1_in(0))]
    state, V, t = ca.SX.sym("state", len(states)), ca.SX.sym("V"), ca.SX.sym("t")
    p, regime = ca.SX.sym("p", ode.size1_in(2)), ca.SX.sym("regime", ode_regime.size1_in(4))
    knowns = ca.vertcat(state, V)
    rows = {}
    outputs = ca.jacobian_sparsity(outputs_function(state, V, p, t), knowns)
    for i in range(outputs.size1()):
        rows[f"y{i}"] = {j for j in range(knowns.numel()) if outputs.has_nz(i, j)}
    for law in (ode(state, V, p, t), ode_regime(state, V, p, t, regime)):
        structure = ca.jacobian_sparsity(law, knowns)
        for i in range(len(states)):
            rows.setdefault(f"d{i}", set()).update(j for j in range(knowns.numel()) if structure.has_nz(i, j))
    return rows


def cart_model(name: str):
    """The CasADi model, state names and output names of a cart FMU (Plant/Plant3, Seesaw/Seesaw3)."""
    from pendulab.model import seesaw

    if name.startswith("Plant"):
        return PlantModel(), STATES, OUTPUTS
    return seesaw.SeesawModel(), seesaw.STATES, seesaw.OUTPUTS


@pytest.mark.parametrize("name", ["Plant", "Plant3", "Seesaw", "Seesaw3"])
def test_cart_model_dependencies_are_the_casadi_jacobian_structure(fmus, name):
    description = read_model_description(str(fmus[name]))
    model, states, output_names = cart_model(name)
    knowns = [*states, "V"]
    table = casadi_structure(model)
    expected = {s: {s} for s in states}
    expected.update({name: {knowns[j] for j in table[f"y{i}"]} for i, name in enumerate(output_names)})
    expected.update({f"der({s})": {knowns[j] for j in table[f"d{i}"]} for i, s in enumerate(states)})
    outputs, derivatives = declared(description), declared(description, "derivatives")
    assert set(outputs) == {*states, *output_names} and set(derivatives) == {f"der({s})" for s in states}
    for unknown, row in {**outputs, **derivatives}.items():
        assert row is not None and set(row) == expected[unknown], unknown
    # The measured outputs depend on states only: nothing feeds the voltage through to them.
    angle = states[2]
    assert outputs[f"{angle}_measured"] == {angle: "dependent"} and outputs["x_measured"] == {"x": "dependent"}
    assert outputs["x"] == {"x": "constant"}
    assert f"{angle}dot" in derivatives[f"der({angle})"]
    if angle == "alpha":  # the pendulum's angle has no stop; the seesaw's rate is zeroed at its tilt stops
        assert derivatives["der(alpha)"] == {"alphadot": "constant"}
    assert "V" in derivatives["der(xdot)"]
    # At initialization the encoder steps count too.
    initial = declared(description, "initialUnknowns")
    step = {"alpha": "q_alpha", "theta": "q_theta"}[angle]
    assert set(initial[f"{angle}_measured"]) == {angle, step} and set(initial["V_applied"]) == {"V", "V_max"}


def test_controller_feeds_its_inputs_through_d(fmus):
    description = read_model_description(str(fmus["Controller"]))
    outputs = declared(description)
    # V_command = C x + D (r - Lp alpha_measured) + D_x x_measured: through the parameters, linearly, but for the
    # angle, which the block may wrap into (-pi, pi] (wrap_angle).
    assert outputs == {"V_command": {"alpha_measured": "dependent", "r": "fixed", "x_measured": "fixed"},
                       "e": {"alpha_measured": "dependent", "r": "constant"}}
    initial = declared(description, "initialUnknowns")
    # The state starts at zero: no C, A, B; engaged acts on the state only.
    assert set(initial["V_command"]) == {"alpha_measured", "r", "x_measured", "Lp", "D", "D_x"}
    assert all(v.variability == "discrete" for v in description.modelVariables if v.causality == "output")


# ---------------------------------------------------------------- dependencies: finite differences on the FMUs
def probe(unzipdir: Path, description, start: dict, perturbed: dict, unknowns: list[str]) -> dict[str, set[str]]:
    """Which unknowns change when each known is moved from its ``start`` value to ``perturbed[known]`` (each
    set before initialization of a fresh Co-Simulation instance; read right after it)."""
    def run(values: dict) -> np.ndarray:
        with Slave(unzipdir, name="probe", initialize=False, description=description) as probe:
            probe.fmu.setupExperiment(startTime=0.0)
            probe.set(values)
            probe.fmu.enterInitializationMode()
            probe.fmu.exitInitializationMode()
            out = np.array([float(value) for value in probe.get(unknowns)])
            probe.terminate()
            return out

    base = run(start)
    seen: dict[str, set[str]] = {u: set() for u in unknowns}
    for known, value in perturbed.items():
        moved = run({**start, known: value})
        for u, a, b in zip(unknowns, base, moved):
            if not (a == b or (math.isnan(a) and math.isnan(b))):
                seen[u].add(known)
    return seen


#: Plant states and voltage at which every switch of the law is met once: sticking, slipping, free, at a stop.
PLANT_POINTS = [
    {"x": 0.1, "xdot": 0.001, "alpha": 0.05, "alphadot": 0.1, "V": 0.5},   # stick: F_friction = -F_motor
    {"x": -0.2, "xdot": 0.02, "alpha": -0.1, "alphadot": 0.3, "V": 0.5},   # slip: F_friction = -B xdot
    {"x": 0.0, "xdot": 0.3, "alpha": 0.2, "alphadot": -0.5, "V": 3.0},     # free
    {"x": 0.407, "xdot": 0.0, "alpha": 0.1, "alphadot": 0.2, "V": 8.0},    # held at the upper stop
]
PLANT_STEPS = {"x": -1e-3, "xdot": 1e-3, "alpha": 0.01, "alphadot": 0.01, "V": 0.1}


def test_plant_dependencies_hold_for_the_built_fmu_by_finite_differences(unzipped):
    description = read_model_description(str(unzipped["Plant"] / "modelDescription.xml"))
    declared_table = {**declared(description), **declared(description, "derivatives")}
    unknowns = list(declared_table)
    union: dict[str, set[str]] = {u: set() for u in unknowns}
    for point in PLANT_POINTS:
        seen = probe(unzipped["Plant"], description, point, {k: point[k] + d for k, d in PLANT_STEPS.items()}, unknowns)
        for u in unknowns:
            assert seen[u] <= set(declared_table[u]), f"{u} changed with {seen[u] - set(declared_table[u])}, not declared"
            union[u] |= seen[u]
    # Every declared dependency of an output is seen at one of the points.
    for u in (*STATES, *OUTPUTS):
        assert union[u] == set(declared_table[u]), u
    # Derivatives: der(x) depends on x, alpha, alphadot and V only through the stop's hold, which the FMU's
    # own event handling never leaves half-way (declared from the law's structure, not seen here).
    assert union["der(xdot)"] == set(declared_table["der(xdot)"]) and union["der(alpha)"] == {"alphadot"}


def test_plant_derivatives_by_finite_differences_in_model_exchange(unzipped):
    """Model Exchange: states set directly in continuous-time mode, derivatives read (switches frozen)."""
    description = read_model_description(str(unzipped["Plant"] / "modelDescription.xml"))
    table = declared(description, "derivatives")
    fmu = FMU2Model(guid=description.guid, unzipDirectory=str(unzipped["Plant"]), modelIdentifier="Plant", instanceName="me")
    fmu.instantiate()
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.setReal([description.modelVariables[8].valueReference], [3.0])  # V
        fmu.exitInitializationMode()
        fmu.newDiscreteStates()
        fmu.enterContinuousTimeMode()
        base_state = np.array([0.0, 0.3, 0.2, -0.5])

        def derivatives(state):
            fmu.setContinuousStates((c_double * 4)(*state), 4)
            dx = (c_double * 4)()
            fmu.getDerivatives(dx, 4)
            return np.array(dx)

        base = derivatives(base_state)
        for j, known in enumerate(STATES):
            moved = base_state.copy()
            moved[j] += 0.01
            changed = derivatives(moved) != base
            for i, s in enumerate(STATES):
                if changed[i]:
                    assert known in table[f"der({s})"], (s, known)
        fmu.terminate()
    finally:
        fmu.freeInstance()


def test_controller_dependencies_by_finite_differences(unzipped):
    description = read_model_description(str(unzipped["Controller"] / "modelDescription.xml"))
    table = declared(description)
    start = {"n": 1, "A[1,1]": 0.5, "B[1]": 1.0, "C[1]": 2.0, "D": 3.0, "D_x": -4.0, "alpha_measured": 0.1, "r": 0.05,
             "x_measured": 0.02}
    moves = {"alpha_measured": 0.2, "r": 0.1, "x_measured": 0.03, "engaged": False}
    seen = probe(unzipped["Controller"], description, start, moves, ["V_command", "e"])
    assert seen == {u: set(row) for u, row in table.items()}
    # With D = D_x = 0 (a strictly proper controller) the command does not feed the inputs through at that instant.
    seen = probe(unzipped["Controller"], description, {**start, "D": 0.0, "D_x": 0.0}, moves, ["V_command"])
    assert seen["V_command"] == set()


def test_supervisor_dependencies_by_finite_differences(unzipped):
    description = read_model_description(str(unzipped["Supervisor"] / "modelDescription.xml"))
    table = declared(description)
    unknowns = list(table)
    start = {"alpha_measured": 0.01, "x_measured": 0.1, "V_command": 2.0}
    union: dict[str, set[str]] = {u: set() for u in unknowns}
    for moves in ({"alpha_measured": 0.02, "x_measured": 0.2, "V_command": 3.0, "command": 2, "iteration": 4},
                  {"alpha_measured": 1.0, "x_measured": 0.5, "V_command": math.nan, "command": 3}):
        seen = probe(unzipped["Supervisor"], description, start, moves, unknowns)
        for u in unknowns:
            assert seen[u] <= set(table[u]), (u, seen[u])
            union[u] |= seen[u]
    assert union["V"] == set(table["V"]) and union["alpha"] == {"alpha_measured"} == set(table["alpha"])
    assert union["state"] == set(table["state"])


# ---------------------------------------------------------------- algebraic loops
def feedthrough_graph(fmus: dict[str, Path], *, ignore_declarations: bool = False) -> dict[str, set[str]]:
    """Edges ``a -> b`` of the wired loop: each connection, and inside each component each input to every
    output that depends on it directly (every input where the dependencies are missing or ignored)."""
    components = {"plant": fmus["Plant"], "controller": fmus["Controller"], "supervisor": fmus["Supervisor"]}
    edges: dict[str, set[str]] = {}
    for name, path in components.items():
        description = read_model_description(str(path))
        inputs = [v.name for v in description.modelVariables if v.causality == "input"]
        for output, row in declared(description).items():
            for known in (inputs if row is None or ignore_declarations else [k for k in row if k in inputs]):
                edges.setdefault(f"{name}.{known}", set()).add(f"{name}.{output}")
    for source, target in CONNECTIONS:
        edges.setdefault(source, set()).add(target)
    return edges


def find_cycle(edges: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        state[node] = 2
        path.pop()
        return None

    for node in sorted(edges):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def test_the_wired_loop_has_no_algebraic_loop(fmus):
    assert find_cycle(feedthrough_graph(fmus)) is None
    # Without the declarations (every output fed through from every input, as before) a tool finds one.
    cycle = find_cycle(feedthrough_graph(fmus, ignore_declarations=True))
    assert cycle and "plant.V" in cycle and "plant.alpha_measured" in cycle


# ---------------------------------------------------------------- the schemas
ALL = ["Plant", "Plant3", "Controller", "Supervisor", "Seesaw", "Seesaw3"]


@pytest.mark.parametrize("name", ALL)
def test_model_description_validates_against_the_official_schema(fmus, name):
    xml = zipfile.ZipFile(fmus[name]).read("modelDescription.xml")
    version = lxml_etree.fromstring(xml).get("fmiVersion")[0]
    schema = lxml_etree.XMLSchema(lxml_etree.parse(str(SCHEMAS / f"fmi{version}" / f"fmi{version}ModelDescription.xsd")))
    assert schema.validate(lxml_etree.fromstring(xml)), schema.error_log


def test_the_schema_check_catches_a_broken_description():
    """The check above can fail: an unknown dependencies kind is a schema error."""
    text = model_description_xml(model_spec("Controller"), ["model.c"]).replace('dependenciesKind="', 'dependenciesKind="linear ', 1)
    schema = lxml_etree.XMLSchema(lxml_etree.parse(str(SCHEMAS / "fmi2" / "fmi2ModelDescription.xsd")))
    assert not schema.validate(lxml_etree.fromstring(text.encode()))


# ---------------------------------------------------------------- units, metadata, documentation
@pytest.mark.parametrize("name", ALL)
def test_units_carry_base_units_and_angles_display_in_degrees(fmus, name):
    description = read_model_description(str(fmus[name]))
    units = {u.name: u for u in description.unitDefinitions}
    def exponents(unit) -> dict[str, int]:
        assert unit.baseUnit is not None, unit.name
        values = {k: getattr(unit.baseUnit, k) for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad")}
        return {k: v for k, v in values.items() if v}

    for unit in units.values():
        assert exponents(unit) == UNITS[unit.name]
    assert {v.unit for v in description.modelVariables if v.unit} <= set(units)
    for v in description.modelVariables:
        if v.unit == "rad":
            assert v.displayUnit == "deg", v.name
    if "rad" in units:
        (deg,) = units["rad"].displayUnits
        assert deg.name == "deg" and deg.factor == pytest.approx(180 / math.pi)
    if "N.s/m" in units and "kg/s" in units:  # the same dimension, and now a tool can tell
        assert exponents(units["N.s/m"]) == exponents(units["kg/s"]) == {"kg": 1, "s": -1}
    assert description.author and description.version == __import__("pendulab").__version__
    assert description.license == "MIT" and description.copyright and description.generationDateAndTime


@pytest.mark.parametrize("name", ALL)
def test_documentation_is_inside_the_fmu(fmus, name):
    html = zipfile.ZipFile(fmus[name]).read("documentation/index.html").decode()
    description = read_model_description(str(fmus[name]))
    for v in description.modelVariables:
        if v.name != "time" and not v.name.startswith(("A[", "event_indicator")):
            assert f"<code>{v.name}</code>" in html, v.name
    words = {"Plant": ["Friction law", "stick", "Poke", "End stops", "xddot"], "Controller": ["V_command = C x + D e"],
             "Supervisor": ["angle limit", "non-finite measurement", "waiting for capture", "rearm"]}
    for word in words.get(name.rstrip("3"), []):
        assert word in html, word


def test_generation_time_honours_source_date_epoch(monkeypatch):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    text = model_description_xml(model_spec("Controller"), ["model.c"])
    assert 'generationDateAndTime="2023-11-14T22:13:20Z"' in text and "Copyright (c) 2023" in text
    assert text == model_description_xml(model_spec("Controller"), ["model.c"])


# ---------------------------------------------------------------- ranges enforced by the FMUs
def out_of_range(v) -> float:
    """A value just beyond the variable's range (above its max, or below its min if it has no max)."""
    if v.max is not None:
        return float(v.max) + 1.0 + abs(float(v.max))
    return float(v.min) - 1.0 - abs(float(v.min))


def ranged(description) -> list:
    return [v for v in description.modelVariables if v.min is not None or v.max is not None]


@pytest.mark.parametrize("name", ["Plant", "Controller", "Supervisor", "Seesaw"])
def test_every_range_is_enforced_fmi2(unzipped, name, capsys):
    description = read_model_description(str(unzipped[name] / "modelDescription.xml"))
    variables = ranged(description)
    # Every parameter has a range (a Boolean has none in FMI), and every default lies inside it.
    parameters = {v.name for v in description.modelVariables if v.causality == "parameter" and v.type != "Boolean"}
    assert parameters <= {v.name for v in variables}
    for v in variables:
        if v.start is not None:
            assert float(v.min) <= float(v.start) <= float(v.max), v.name
    with Slave(unzipped[name], name=name, initialize=False, description=description) as fmu:
        for v in variables:
            value = out_of_range(v)
            with pytest.raises(FMICallException):
                fmu.set({v.name: value})
            printed = capsys.readouterr().out
            assert f"{v.name} = {value:g} is outside its range" in printed, (v.name, printed)
        fmu.initialize()  # nothing refused was set: the defaults initialize
        fmu.terminate()


def test_every_range_is_enforced_fmi3(unzipped):
    description = read_model_description(str(unzipped["Plant3"] / "modelDescription.xml"))
    messages: list[str] = []
    fmu = FMU3Slave(guid=description.guid, unzipDirectory=str(unzipped["Plant3"]), modelIdentifier="Plant3", instanceName="p3")
    fmu.instantiate(logMessage=lambda env, status, category, message: messages.append(message.decode()))
    try:
        variables = ranged(description)
        assert {v.name for v in description.modelVariables if v.causality == "parameter"} <= {v.name for v in variables}
        for v in variables:
            value = out_of_range(v)
            with pytest.raises(Exception):
                fmu.setFloat64([v.valueReference], [value])
            assert f"fmi3SetFloat64: {v.name} = {value:g} is outside its range" in messages[-1], messages[-1:]
        fmu.enterInitializationMode()
        fmu.setFloat64([next(v.valueReference for v in variables if v.name == "x")], [1.0])  # beyond the stop
        with pytest.raises(Exception):
            fmu.exitInitializationMode()
        assert "abs(x) <= track_half_length is violated (x = 1, track_half_length = 0.407)" in messages[-1]
    finally:
        fmu.freeInstance()


def test_the_issue_examples_are_refused_through_simulate_fmu(fmus, capsys):
    from fmpy import simulate_fmu

    for start, words in (({"V_max": -5.0}, "V_max = -5 is outside its range 0.01 to 1000 V"),
                         ({"Lp": 0.0}, "lp <= Lp is violated"), ({"x": 1.0}, "abs(x) <= track_half_length")):
        with pytest.raises(Exception):
            simulate_fmu(str(fmus["Plant"]), start_values=start, stop_time=0.01, fmi_type="CoSimulation")
        assert words in capsys.readouterr().out
    # The Python parameter table says the same before any FMU is involved.
    with pytest.raises(Exception, match=r"V_max=-5\.0 \(negative\) is outside its range 0\.01 to 1000 V"):
        PlantParameters.preset(V_max=-5.0)


def test_documentation_renders_in_chromium(unzipped, tmp_path):
    """The unzipped FMU's documentation/index.html in headless Chromium: a page with text and tables, not blank."""
    import shutil
    import subprocess

    import matplotlib.image

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if not chromium:
        pytest.skip("needs chromium (apt-get install chromium)")
    png = tmp_path / "plant.png"
    page = (unzipped["Plant"] / "documentation" / "index.html").resolve()
    result = subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                             "--no-first-run", f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1200,2400",
                             f"--screenshot={png}", page.as_uri()], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and png.is_file(), result.stderr
    pixels = matplotlib.image.imread(str(png))[..., :3]
    assert pixels.shape[:2] == (2400, 1200)
    dark = (pixels.mean(axis=2) < 0.5).mean()
    assert 0.01 < dark < 0.3  # text on a white page (measured 3.5 %), neither blank nor a black error screen
