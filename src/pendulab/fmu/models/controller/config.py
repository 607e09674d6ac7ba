"""Controller FMU: a generic discrete LTI block whose matrices are parameters.

A new controller is a new set of parameter values, never a new binary: the student's G(s) is
discretized in Python (:mod:`pendulab.control.realization`) and its matrices set as start values.
The block forms the error itself, ``e = r - Lp * alpha_measured``, and outputs ``V_command = C x + D e``;
each step ``x <- A x + B e``. The reference ``r`` (an input, 0 unless the supervisor re-centres the cart) and
``engaged`` (false: held in reset while the supervisor swings the pendulum up) come from the supervisor.
"""

from __future__ import annotations

from pendulab.fmu.description import ModelSpec, Variable

#: Largest controller order the FMU holds.
MAX_ORDER = 16


def spec() -> ModelSpec:
    n = MAX_ORDER
    variables = [
        Variable("alpha_measured", "Real", "input", start=0.0, unit="rad", description="Measured pendulum angle from upright"),
        Variable("r", "Real", "input", start=0.0, unit="m", description="Tip position reference (0 in the lab)"),
        Variable("x_measured", "Real", "input", start=0.0, unit="m",
                 description="Measured cart position: the second input of a state feedback (unused by a transfer function G(s))"),
        Variable("V_command", "Real", "output", unit="V", description="Voltage command, C x + D e", initial="calculated"),
        Variable("e", "Real", "output", unit="m", description="Tip position error r - Lp*alpha_measured", initial="calculated"),
        Variable("Lp", "Real", "parameter", start=0.6413, unit="m", description="Pendulum length: the tip position is Lp*alpha", initial="exact"),
        Variable("h", "Real", "parameter", start=1e-3, unit="s", description="Sample period the matrices were discretized for", initial="exact"),
        Variable("D", "Real", "parameter", start=0.0, unit="V/m", description="Feedthrough", initial="exact"),
    ]
    variables += [
        Variable(f"A[{i},{j}]", "Real", "parameter", start=0.0, description=f"State matrix entry ({i},{j})", initial="exact")
        for i in range(1, n + 1)
        for j in range(1, n + 1)
    ]
    variables += [Variable(f"B[{i}]", "Real", "parameter", start=0.0, description=f"Input matrix entry {i}", initial="exact") for i in range(1, n + 1)]
    variables += [Variable(f"C[{i}]", "Real", "parameter", start=0.0, unit="V", description=f"Output matrix entry {i}", initial="exact") for i in range(1, n + 1)]
    # The second input, x_measured (state feedback: the seesaw's cart position); zero for a SISO G(s).
    variables.append(Variable("D_x", "Real", "parameter", start=0.0, unit="V/m", description="Feedthrough of x_measured", initial="exact"))
    variables += [Variable(f"B_x[{i}]", "Real", "parameter", start=0.0, description=f"Input matrix entry {i} of x_measured", initial="exact") for i in range(1, n + 1)]
    variables.append(Variable("integral_limit", "Real", "parameter", start=0.0,
                              description="Limit of the integral state (state feedback's integral; Quanser's seesaw: 10 deg)", initial="exact"))
    variables.append(Variable("n", "Integer", "parameter", start=0, description=f"Controller order (0..{n})", initial="exact"))
    variables += [
        Variable("engaged", "Boolean", "input", start=True,
                 description="The controller runs; false holds it in reset (state 0), so it starts fresh when engaged again"),
        Variable("wrap_angle", "Boolean", "parameter", start=False, initial="exact",
                 description="Wrap alpha_measured into (-pi, pi] (a pendulum that may turn over, as in a swing-up)"),
    ]
    variables.append(Variable("integral_index", "Integer", "parameter", start=0,
                              description="1-based index of the state held within +/-integral_limit (0: none)", initial="exact"))
    return ModelSpec(
        identifier="Controller",
        description="Student controller: discrete linear time-invariant block x+ = A x + B e, V = C x + D e, e = r - Lp*alpha",
        variables=variables,
        defines={"MAX_ORDER": str(n)},
        # doStep refuses any step other than h: the matrices hold for that sample period only.
        variable_step=False,
    )
