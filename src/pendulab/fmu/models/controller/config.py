"""Controller FMU: a generic discrete LTI block whose matrices are parameters.

A new controller is a new set of parameter values, never a new binary: the student's G(s) is
discretized in Python (:mod:`pendulab.control.realization`) and its matrices set as start values.
The block forms the error itself, ``e = r - Lp * alpha_measured``, and outputs ``V_command = C x + D e``;
each step ``x <- A x + B e``. The reference ``r`` (an input, 0 unless the supervisor re-centres the cart) and
``engaged`` (false: held in reset while the supervisor swings the pendulum up) come from the supervisor.
"""

from __future__ import annotations

import casadi as ca

from pendulab.fmu.description import ModelSpec, Variable
from pendulab.fmu.structure import dependencies

#: Largest controller order the FMU holds.
MAX_ORDER = 16
#: Inputs the block may wrap into (-pi, pi] (the wrap_angle parameter) before it uses them.
WRAPPED = ("alpha_measured",)
#: The matrices' entries may take any finite value: the range only keeps NaN and infinities out.
_ANY = {"min": -1e15, "max": 1e15}


def output_equations(names: list[str]) -> tuple[dict[str, ca.SX], dict[str, ca.SX], list[ca.SX], ca.SX]:
    """The outputs as symbolic expressions of the variables ``names`` (the same equations as model.c):
    ``e = r - Lp alpha_measured``, ``V_command = C x + D e + D_x x_measured`` with the block's internal state ``x``.

    Returns the outputs, every variable's symbol by name, the parameters' symbols and ``x``.
    """
    symbols = {name: ca.SX.sym(name) for name in names}
    x = ca.SX.sym("x", MAX_ORDER)
    e = symbols["r"] - symbols["Lp"] * symbols["alpha_measured"]
    C = ca.vertcat(*[symbols[f"C[{i}]"] for i in range(1, MAX_ORDER + 1)])
    outputs = {"V_command": ca.dot(C, x) + symbols["D"] * e + symbols["D_x"] * symbols["x_measured"], "e": e}
    return outputs, symbols, [symbols[n] for n in names if n not in ("alpha_measured", "r", "x_measured")], x


def model_structure(variables: list[Variable]) -> tuple[dict[str, dict[str, str]], dict[str, dict[str, str]]]:
    """Dependencies of the outputs on the inputs (through D and Lp, so ``fixed``), and at initialization, where
    the block's state is zero (so V_command = D e: on the inputs, D and Lp)."""
    outputs, symbols, parameters, x = output_equations([v.name for v in variables if v.type == "Real"])
    # engaged (Boolean) acts on the state in the step only, never on the outputs of the instant.
    inputs = {v.name: symbols[v.name] for v in variables if v.causality == "input" and v.name in symbols}
    exact = {v.name: symbols[v.name] for v in variables if v.initial == "exact" and v.name in symbols}
    at_start = {name: ca.substitute(y, x, ca.DM.zeros(MAX_ORDER)) for name, y in outputs.items()}
    structure = dependencies(outputs, inputs, parameters=parameters)
    # With wrap_angle the angle is wrapped into (-pi, pi] first: linear between the jumps only.
    for row in structure.values():
        row.update({k: "dependent" for k in row if k in WRAPPED})
    return structure, dependencies(at_start, {**inputs, **exact}, parameters=parameters)


def spec() -> ModelSpec:
    n = MAX_ORDER
    variables = [
        Variable("alpha_measured", "Real", "input", start=0.0, unit="rad", description="Measured pendulum angle from upright"),
        Variable("r", "Real", "input", start=0.0, unit="m", description="Tip position reference (0 in the lab)"),
        Variable("x_measured", "Real", "input", start=0.0, unit="m",
                 description="Measured cart position: the second input of a state feedback (unused by a transfer function G(s))"),
        # Sampled: the outputs change only at communication points.
        Variable("V_command", "Real", "output", variability="discrete", unit="V", description="Voltage command, C x + D e",
                 initial="calculated"),
        Variable("e", "Real", "output", variability="discrete", unit="m", description="Tip position error r - Lp*alpha_measured",
                 initial="calculated"),
        Variable("Lp", "Real", "parameter", start=0.6413, unit="m",
                 description="Pendulum length: the tip position is Lp*alpha (another loop may use it as a gain: the seesaw's is -1)",
                 initial="exact", min=-10.0, max=10.0),
        Variable("h", "Real", "parameter", start=1e-3, unit="s", description="Sample period the matrices were discretized for",
                 initial="exact", min=1e-6, max=10.0),
        Variable("D", "Real", "parameter", start=0.0, unit="V/m", description="Feedthrough", initial="exact", **_ANY),
    ]
    variables += [
        Variable(f"A[{i},{j}]", "Real", "parameter", start=0.0, description=f"State matrix entry ({i},{j})", initial="exact", **_ANY)
        for i in range(1, n + 1)
        for j in range(1, n + 1)
    ]
    variables += [Variable(f"B[{i}]", "Real", "parameter", start=0.0, description=f"Input matrix entry {i}", initial="exact", **_ANY) for i in range(1, n + 1)]
    variables += [Variable(f"C[{i}]", "Real", "parameter", start=0.0, unit="V", description=f"Output matrix entry {i}", initial="exact", **_ANY) for i in range(1, n + 1)]
    # The second input, x_measured (state feedback: the seesaw's cart position); zero for a SISO G(s).
    variables.append(Variable("D_x", "Real", "parameter", start=0.0, unit="V/m", description="Feedthrough of x_measured", initial="exact", **_ANY))
    variables += [Variable(f"B_x[{i}]", "Real", "parameter", start=0.0, description=f"Input matrix entry {i} of x_measured", initial="exact", **_ANY) for i in range(1, n + 1)]
    variables.append(Variable("integral_limit", "Real", "parameter", start=0.0,
                              description="Limit of the integral state (state feedback's integral; Quanser's seesaw: 10 deg)", initial="exact",
                              min=0.0, max=1e15))
    variables.append(Variable("n", "Integer", "parameter", start=0, description=f"Controller order (0..{n})", initial="exact",
                              min=0, max=n))
    variables += [
        Variable("engaged", "Boolean", "input", start=True,
                 description="The controller runs; false holds it in reset (state 0), so it starts fresh when engaged again"),
        Variable("wrap_angle", "Boolean", "parameter", start=False, initial="exact",
                 description="Wrap alpha_measured into (-pi, pi] (a pendulum that may turn over, as in a swing-up)"),
    ]
    variables.append(Variable("integral_index", "Integer", "parameter", start=0,
                              description="1-based index of the state held within +/-integral_limit (0: none)", initial="exact",
                              min=0, max=n))
    structure, initial_structure = model_structure(variables)
    return ModelSpec(
        identifier="Controller",
        description="Student controller: discrete linear time-invariant block x+ = A x + B e, V = C x + D e, e = r - Lp*alpha",
        variables=variables,
        defines={"MAX_ORDER": str(n)},
        # doStep refuses any step other than h: the matrices hold for that sample period only.
        variable_step=False,
        dependencies=structure,
        initial_dependencies=initial_structure,
        constraints=(("integral_index <= n", "the integral is one of the block's states: set integral_index <= n"),),
        documentation=DOCUMENTATION,
    )


DOCUMENTATION = f"""
<h2>Equations</h2>
<p>A discrete linear time-invariant block of order <code>n</code> (0 to {MAX_ORDER}), sampled every <code>h</code>
seconds (the FMU refuses any other communication step):</p>
<pre>
e         = r - Lp alpha_measured          (the tip position error)
V_command = C x + D e + D_x x_measured
x        <- A x + B e + B_x x_measured     (at the end of each step; the integral_index-th state held
                                           within +-integral_limit; x = 0 while engaged is false)
</pre>
<p>A new controller is a new set of parameters, never a new binary: pendulab discretizes the student's G(s)
(Tustin or zero-order hold) and sets <code>A[i,j]</code>, <code>B[i]</code>, <code>C[i]</code>, <code>D</code> and
<code>n</code> as start values. Where D is not zero, V_command depends on the inputs directly (declared in the
model structure as <code>fixed</code>: through the parameters D and Lp).</p>
"""
