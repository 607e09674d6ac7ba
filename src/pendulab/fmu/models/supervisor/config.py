"""Supervisor FMU: the lab control logic of SPEC §5 (Co-Simulation only).

The supervisor sits between the controller and the plant (or the rig) and owns the motor enable. Its
state machine lives in ``model.c``; this module holds its variable table and the codes a master needs
to drive it and to read its outputs. The C code gets the same codes and names through ``#define``
lines generated from the tables below, so the two can never disagree.

States (output ``state``)::

    idle --start--> running            (rig mode: --> waiting for capture --|alpha| < capture_window--> running)
    running --pause--> paused --start--> running (rig mode: through the capture window again)
    running --limit crossed / non-finite input--> tripped (latched, V = 0)
    swing_up: idle --start--> swinging up --catch window--> running --falls within catch_hold-->
              swinging up (again, up to swing_tries misses, then tripped: catch missed)
              swinging up --swing_time_max / swing_x_limit / non-finite input--> tripped
    tripped --rearm (limits OK)--> idle;  tripped --start (limits OK)--> running (re-armed and started)
    any --end--> ended (final)

Examples
--------
>>> from pendulab.fmu.models.supervisor.config import COMMANDS, STATES, TRIP_REASONS
>>> STATES[2], TRIP_REASONS[1], COMMANDS["start"]
('running', 'angle limit', 1)
>>> spec().identifier
'Supervisor'
"""

from __future__ import annotations

import math
import textwrap

from pendulab.fmu.description import ModelSpec, Variable

# ---------------------------------------------------------------- codes shared with model.c
IDLE, WAITING, RUNNING, PAUSED, TRIPPED, ENDED, SWINGING = range(7)
#: ``state`` output code -> name.
STATES: dict[int, str] = {
    IDLE: "idle",
    WAITING: "waiting for capture",
    RUNNING: "running",
    PAUSED: "paused",
    TRIPPED: "tripped",
    ENDED: "ended",
    SWINGING: "swinging up",
}

NO_TRIP, TRIP_ANGLE, TRIP_TRACK, TRIP_VOLTAGE, TRIP_MEASUREMENT, TRIP_SWING_TIME, TRIP_CATCH = range(7)
#: ``trip_reason`` output code -> name.
TRIP_REASONS: dict[int, str] = {
    NO_TRIP: "none",
    TRIP_ANGLE: "angle limit",
    TRIP_TRACK: "track limit",
    TRIP_VOLTAGE: "non-finite voltage command",
    TRIP_MEASUREMENT: "non-finite measurement",
    TRIP_SWING_TIME: "swing-up timed out",
    TRIP_CATCH: "catch missed",
}

#: Operator command name -> ``command`` input code. The master sets a code for one step, then 0;
#: the supervisor acts when the input changes to a non-zero code (so a held code acts once).
COMMANDS: dict[str, int] = {"none": 0, "start": 1, "pause": 2, "end": 3, "rearm": 4}

#: The lab keys (SPEC §9) -> command names; "r" re-arms after a trip.
KEYS: dict[str, str] = {"s": "start", "p": "pause", "e": "end", "r": "rearm"}

# ---------------------------------------------------------------- parameter defaults and limits
ALPHA_MAX_RANGE_DEG = (10.0, 15.0)
ALPHA_MAX_DEFAULT = math.radians(15.0)
X_MAX_DEFAULT = 0.40
CAPTURE_WINDOW_DEFAULT = math.radians(2.0)
CENTRE_TOLERANCE_DEFAULT = 0.01
V_LIMIT_DEFAULT = 10.0
#: Re-centring (the old lab's "kickback"): engage beyond RECENTRE_X_ON, release inside RECENTRE_X_OFF.
RECENTRE_X_ON = 0.05
RECENTRE_X_OFF = 0.02
RECENTRE_GAIN = 0.2
RECENTRE_R_MAX = 0.005
RECENTRE_SLEW = 0.05
RECENTRE_LEAD = 0.0
#: Swing-up (Quanser's self-erecting pendulum): the catch window and the set point's speed limit.
CATCH_X = 0.20
#: Quanser's window allows 15 deg; the hand-over waits until 6 deg, from where a tip-only loop such as the demo
#: controller holds the pendulum with the smallest cart excursion (from 15 deg it overshoots past the angle limit;
#: from 8 deg it holds, but the cart runs 0.06 m further: measured, issue 21).
CATCH_ALPHA = math.radians(6.0)
CATCH_RATE = math.radians(150.0)
SWING_SPEED_MAX = 0.7
#: Slack (rad) on the alpha_max range so that a rounded 15 deg (0.2618 rad) is accepted.
ALPHA_MAX_SLACK = 1e-6


def rig_to_upright(theta: float) -> float:
    """The rig encoder's angle (0 hanging down) in the upright convention, wrapped into (-pi, pi].

    The same conversion as the FMU's in rig_mode (``alpha = wrap(theta - pi)``), for a master that
    needs the upright angle outside the supervisor (e.g. to feed the controller on the rig).

    Examples
    --------
    >>> rig_to_upright(math.pi), rig_to_upright(0.0) == math.pi
    (0.0, True)
    """
    a = math.fmod(theta - math.pi, 2 * math.pi)
    if a <= -math.pi:
        a += 2 * math.pi
    elif a > math.pi:
        a -= 2 * math.pi
    return a


def _codes(table: dict[int, str]) -> str:
    return ", ".join(f"{code} {name}" for code, name in table.items())


def _c_names(table: dict[int, str]) -> str:
    return "((const char *[]){" + ", ".join(f'"{table[k]}"' for k in sorted(table)) + "})"


def spec() -> ModelSpec:
    """The Supervisor's variable table (value references follow the table order per base type)."""
    commands = ", ".join(f"{code} {name}" for name, code in COMMANDS.items())
    lo, hi = ALPHA_MAX_RANGE_DEG
    variables = [
        # Real
        Variable("V_command", "Real", "input", start=0.0, unit="V", description="Voltage command from the controller"),
        Variable("alpha_measured", "Real", "input", start=0.0, unit="rad",
                 description="Measured pendulum angle: from upright (simulation), or the rig encoder's theta, 0 hanging down (rig_mode)"),
        Variable("x_measured", "Real", "input", start=0.0, unit="m", description="Measured cart position (0 at track centre)"),
        Variable("V", "Real", "output", unit="V",
                 description="Gated voltage to the amplifier: V_command clamped to +-V_limit while running, else 0"),
        Variable("trip_time", "Real", "output", variability="discrete", unit="s",
                 description="Communication point at which the latched trip was seen (-1: no trip)"),
        Variable("alpha", "Real", "output", unit="rad",
                 description="Pendulum angle from upright in (-pi, pi], as the supervisor checks it"),
        Variable("alpha_max", "Real", "parameter", start=ALPHA_MAX_DEFAULT, unit="rad", initial="exact",
                 min=math.radians(lo) - ALPHA_MAX_SLACK, max=math.radians(hi) + ALPHA_MAX_SLACK,
                 description=f"Angle limit |alpha| (must be {lo:g} to {hi:g} deg; not checked in calibration_mode)"),
        Variable("x_max", "Real", "parameter", start=X_MAX_DEFAULT, unit="m", initial="exact", min=1e-3, max=10.0,
                 description="Track limit |x_measured|"),
        Variable("capture_window", "Real", "parameter", start=CAPTURE_WINDOW_DEFAULT, unit="rad", initial="exact",
                 min=1e-6, max=math.radians(hi) + ALPHA_MAX_SLACK,
                 description="rig_mode: the controller is engaged once |alpha| is below this (0 < capture_window <= alpha_max)"),
        Variable("centre_tolerance", "Real", "parameter", start=CENTRE_TOLERANCE_DEFAULT, unit="m", initial="exact",
                 min=1e-6, max=10.0, description="calibration_mode: start is accepted only while |x_measured| is below this"),
        Variable("V_limit", "Real", "parameter", start=V_LIMIT_DEFAULT, unit="V", initial="exact", min=0.01, max=1000.0,
                 description="Clamp of the gated voltage V"),
        # Integer
        Variable("command", "Integer", "input", start=0,
                 description=f"Operator command ({commands}); acted on when it changes to a non-zero code"),
        Variable("iteration", "Integer", "input", start=0,
                 description="Current calibration iteration, announced when it changes (set by the calibration master)"),
        Variable("state", "Integer", "output", description=f"Supervisor state: {_codes(STATES)}"),
        Variable("trip_reason", "Integer", "output", description=f"Reason of the latched trip: {_codes(TRIP_REASONS)}"),
        # Boolean
        Variable("rig_mode", "Boolean", "parameter", start=False, initial="exact",
                 description="alpha_measured is the rig encoder's theta (0 hanging down): convert to alpha = wrap(theta - pi) and engage only inside the capture window"),
        Variable("auto_start", "Boolean", "parameter", start=True, initial="exact",
                 description="Start at initialization (simulation); false: wait for the start command (lab)"),
        Variable("calibration_mode", "Boolean", "parameter", start=False, initial="exact",
                 description="Pendulum removed: no angle limit, no capture window, start only with the cart centred"),
        Variable("level_start", "Boolean", "parameter", start=False, initial="exact",
                 description="The seesaw's start rule: a start is accepted only while |alpha_measured| (its tilt) is below "
                             "capture_window: hold it level, then start"),
        Variable("motor_enable", "Boolean", "output", description="Amplifier enable: true only while running"),
    ]
    defines = {
        **{f"STATE_{name.split()[0].upper()}": str(code) for code, name in STATES.items()},
        **{f"TRIP_{key}": str(code) for key, code in
           zip(("NONE", "ANGLE", "TRACK", "VOLTAGE", "MEASUREMENT", "SWING_TIME", "CATCH"), TRIP_REASONS)},
        **{f"CMD_{name.upper()}": str(code) for name, code in COMMANDS.items()},
        "N_STATE_CODES": str(len(STATES)),
        "STATE_NAMES": _c_names(STATES),
        "TRIP_NAMES": _c_names(TRIP_REASONS),
    }
    variables += _mode_variables()
    structure, initial_structure = model_structure(variables)
    return ModelSpec(
        identifier="Supervisor",
        description="Lab supervisor: angle and track limits with latched trips, start / pause / end / re-arm, "
        "upright capture for the rig, calibration mode, cart re-centring through the reference r, energy-based "
        "swing-up with a catch window; gates the voltage and owns the motor enable",
        variables=variables,
        defines=defines,
        dependencies=structure,
        initial_dependencies=initial_structure,
        constraints=CONSTRAINTS,
        documentation=documentation(),
    )


#: Ranges of the re-centring and swing-up parameters (the FMU refuses a value set outside them).
MODE_RANGES: dict[str, tuple[float, float]] = {
    "recentre_x_on": (0.0, 10.0), "recentre_x_off": (0.0, 10.0), "recentre_gain": (-100.0, 100.0),
    "recentre_r_max": (0.0, 1.0), "recentre_slew": (1e-6, 10.0), "recentre_lead": (0.0, 10.0), "pendulum_frequency": (1e-3, 1e3),
    "swing_energy_gain": (0.0, 1e4), "swing_energy_target": (-2.0, 2.0), "swing_accel_max": (0.0, 100.0),
    "swing_speed_max": (1e-6, 10.0), "swing_travel": (1e-6, 10.0), "swing_centring": (0.0, 100.0),
    "swing_kp": (0.0, 1e4), "swing_kd": (0.0, 1e3), "swing_kff": (0.0, 1e3), "swing_V_limit": (1e-3, 1e3),
    "swing_x_limit": (1e-3, 10.0), "swing_time_max": (1e-3, 1e6), "catch_x": (1e-6, 10.0),
    "catch_alpha": (1e-6, math.pi), "catch_rate": (1e-6, 1e3), "catch_hold": (0.0, 1e3), "rate_filter": (0.0, 10.0),
}


def _mode_variables() -> list[Variable]:
    """Re-centring and swing-up (SPEC §5): their outputs and parameters."""

    def real(name: str, start: float, unit: str, description: str) -> Variable:
        low, high = MODE_RANGES[name]
        return Variable(name, "Real", "parameter", start=start, unit=unit, initial="exact", description=description,
                        min=low, max=high)

    return [
        Variable("r", "Real", "output", variability="discrete", unit="m",
                 description="Tip reference for the controller (e = r - Lp*alpha): 0 unless re-centring acts; sampled (set by each step, held until the next)"),
        Variable("swing_voltage", "Real", "output", unit="V",
                 description="The swing-up's voltage (applied as V while swinging up)"),
        Variable("energy", "Real", "output", unit="1",
                 description="Pendulum energy over Mp*g*lp: 0 at rest upright, -2 at rest hanging"),
        real("recentre_x_on", RECENTRE_X_ON, "m", "Re-centring engages when |x_measured| exceeds this"),
        real("recentre_x_off", RECENTRE_X_OFF, "m", "Re-centring lets go (r slews back to 0) when |x_measured| is below this"),
        real("recentre_gain", RECENTRE_GAIN, "m/m", "Re-centring's outer loop: r = recentre_gain * x_measured while engaged"),
        real("recentre_r_max", RECENTRE_R_MAX, "m", "Largest |r| re-centring applies"),
        real("recentre_slew", RECENTRE_SLEW, "m/s", "Largest rate of change of r"),
        real("recentre_lead", RECENTRE_LEAD, "s", "Re-centring acts on the cart position predicted this far ahead from its speed, x + lead * dx/dt (0: the measured position)"),
        real("pendulum_frequency", math.sqrt(0.230 * 9.81 * 0.3302 / (7.884e-3 + 0.230 * 0.3302**2)), "rad/s",
             "Small-swing frequency of the hanging pendulum, sqrt(Mp*g*lp/(Ip+Mp*lp^2)): scales the energy"),
        real("swing_energy_gain", 60.0, "m/s2", "Swing-up law: cart acceleration per unit of missing energy (Astrom-Furuta)"),
        real("swing_energy_target", 0.02, "1", "Energy the swing-up aims at, over Mp*g*lp (0 would only creep up to upright; a little more passes through the catch window)"),
        real("swing_accel_max", 3.0, "m/s2", "Largest cart acceleration the swing-up asks for"),
        real("swing_speed_max", SWING_SPEED_MAX, "m/s", "Largest speed of the cart's set point while swinging up"),
        real("swing_travel", 0.20, "m", "The cart's set point stays within +-swing_travel while swinging up"),
        real("swing_centring", 0.7, "rad/s", "Spring that pulls the set point back to the centre while swinging up"),
        real("swing_kp", 60.0, "V/m", "Cart servo while swinging up: voltage per metre of set point error"),
        real("swing_kd", 8.0, "V.s/m", "Cart servo while swinging up: voltage per m/s of set point speed error"),
        real("swing_kff", 7.0, "V.s/m", "Cart servo while swinging up: voltage per m/s of set point speed (back-EMF and drag)"),
        real("swing_V_limit", 6.0, "V", "Clamp of the voltage while swinging up"),
        real("swing_x_limit", 0.33, "m", "Track limit while swinging up: beyond it the swing trips"),
        real("swing_time_max", 30.0, "s", "Longest time from the start of a swing-up to a held catch: then it trips"),
        real("catch_x", CATCH_X, "m", "Catch window: |x_measured| below this"),
        real("catch_alpha", CATCH_ALPHA, "rad", "Catch window: |alpha| below this"),
        real("catch_rate", CATCH_RATE, "rad/s", "Catch window: |dalpha/dt| below this"),
        real("catch_hold", 1.0, "s", "A fall past alpha_max within this time of a catch is a missed catch: swing again"),
        real("rate_filter", 0.01, "s", "Time constant of the speed estimates (filtered differences of the measurements)"),
        Variable("swing_tries", "Integer", "parameter", start=3, initial="exact", min=1, max=1000,
                 description="Missed catches after which the swing-up stops (trip: catch missed)"),
        Variable("misses", "Integer", "output", description="Missed catches so far"),
        Variable("recentre", "Boolean", "parameter", start=False, initial="exact",
                 description="Re-centring: a slow outer loop on the cart position acts through r (off: r = 0)"),
        Variable("swing_up", "Boolean", "parameter", start=False, initial="exact",
                 description="Start swings the pendulum up from hanging and hands over inside the catch window"),
        Variable("recentring", "Boolean", "output", description="Re-centring is engaged (r follows the cart)"),
        Variable("controller_engaged", "Boolean", "output",
                 description="The controller runs (false while swinging up: held in reset, engaged fresh at the catch)"),
    ]


#: Conditions between the parameters, checked by the FMU on leaving initialization (their ranges when set).
CONSTRAINTS = (
    ("capture_window <= alpha_max", "the controller is engaged inside the angle limit: set capture_window <= alpha_max"),
    ("centre_tolerance < x_max", "a centred cart is inside the track limit: set centre_tolerance < x_max"),
    ("catch_alpha <= alpha_max", "the catch window lies inside the angle limit: set catch_alpha <= alpha_max"),
    ("recentre_x_off < recentre_x_on", "re-centring lets go closer to the centre than it engages: set recentre_x_off < recentre_x_on"),
    ("recentre_x_on < x_max", "re-centring engages inside the track limit: set recentre_x_on < x_max"),
)
#: Outputs that depend on fewer inputs than all (model.c: alpha is the measured angle, converted in rig_mode;
#: the reference r is sampled, held from the last step).
FEEDTHROUGH: dict[str, tuple[str, ...]] = {"alpha": ("alpha_measured",), "r": ()}
#: Inputs that no output depends on (the iteration is only announced in the log).
NO_FEEDTHROUGH = ("iteration",)


def model_structure(variables: list[Variable]) -> tuple[dict[str, dict[str, str]], dict[str, dict[str, str]]]:
    """The outputs' dependencies: the state machine (model.c) runs on the current inputs in every output
    update, so every output but those of :data:`FEEDTHROUGH` may change with every input but those of
    :data:`NO_FEEDTHROUGH` (a trip, a command). At initialization the parameters are knowns too."""
    inputs = [v.name for v in variables if v.causality == "input" and v.name not in NO_FEEDTHROUGH]
    parameters = [v.name for v in variables if v.causality == "parameter"]
    structure = {v.name: {k: "dependent" for k in FEEDTHROUGH.get(v.name, inputs)}
                 for v in variables if v.causality == "output"}
    initial = {name: {**row, **{p: "dependent" for p in parameters}} for name, row in structure.items()}
    return structure, initial


def documentation() -> str:
    """The supervisor's sections of documentation/index.html, from the code tables above."""
    rows = "".join(f"<tr><td>{code}</td><td>{name}</td></tr>" for code, name in STATES.items())
    trips = "".join(f"<tr><td>{code}</td><td>{name}</td></tr>" for code, name in TRIP_REASONS.items())
    commands = "".join(f"<tr><td>{code}</td><td>{name}</td><td>{''.join(k for k, c in KEYS.items() if c == name)}</td></tr>"
                       for name, code in COMMANDS.items())
    return f"""
<h2>State machine</h2>
<pre>{textwrap.dedent(__doc__.split("States (output ``state``)::")[1].split("Examples")[0]).strip()}</pre>
<h3>States (output <code>state</code>)</h3>
<table><tr><th>code</th><th>state</th></tr>{rows}</table>
<h3>Trip reasons (output <code>trip_reason</code>)</h3>
<p>A trip latches: the voltage V is 0 and motor_enable false until a re-arm (or start) with every limit
satisfied. <code>trip_time</code> is the communication point at which the trip was seen (-1: none).</p>
<table><tr><th>code</th><th>reason</th></tr>{trips}</table>
<h3>Commands (input <code>command</code>)</h3>
<p>Acted on when the input changes to a non-zero code, so a held code acts once.</p>
<table><tr><th>code</th><th>command</th><th>lab key</th></tr>{commands}</table>
"""
