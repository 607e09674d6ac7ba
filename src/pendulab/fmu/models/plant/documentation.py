"""The plant's sections of its FMU's ``documentation/index.html``: the equations the CasADi model
(:func:`pendulab.model.plant.plant_equations`) implements, the friction law, the end stops, the amplifier, the
encoders and the poke. Parameter names, defaults and units come from :class:`PlantParameters`; the regimes and
event indicators from :mod:`pendulab.model.plant`.
"""

from __future__ import annotations

from html import escape

from pendulab.model.parameters import FRICTION_NAMES, PlantParameters
from pendulab.model.plant import EVENT_INDICATORS, MAX_SUBSTEP, REGIME


def _value(name: str) -> str:
    """``F1 = 1.5 N`` from the parameter table (default and unit)."""
    field = PlantParameters.__dataclass_fields__[name]
    unit = field.metadata["unit"]
    return f"<code>{name}</code> = {field.default:g}{'' if unit == '1' else ' ' + escape(unit)}"


def documentation() -> str:
    """HTML sections (no page frame: :func:`pendulab.fmu.description.documentation_html` adds it)."""
    friction = ", ".join(_value(n) for n in FRICTION_NAMES)
    return f"""
<h2>Equations</h2>
<p>States <code>x</code> (cart position, m), <code>xdot</code>, <code>alpha</code> (pendulum angle from upright,
counter-clockwise positive, rad), <code>alphadot</code>; input <code>V</code> (volts). With the lumped cart mass
<i>M<sub>c</sub></i> = M_cart + &eta;<sub>g</sub> K<sub>g</sub><sup>2</sup> J<sub>m</sub> / r<sub>mp</sub><sup>2</sup>
and <i>J</i> = I<sub>p</sub> + M<sub>p</sub> l<sub>p</sub><sup>2</sup>:</p>
<pre>
V_applied = min(max(V, -V_max), V_max)
I         = (V_applied - Km Kg xdot / r_mp) / Rm           (clamped to +-I_max if I_max > 0)
F_motor   = force_gain eta_g Kg eta_m Kt I / r_mp
F         = F_motor + F_friction
cart      = F - Beq xdot - Mp lp sin(alpha) alphadot^2
torque    = Mp g lp sin(alpha) - Bp alphadot
D         = (Mc + Mp) Ip + Mc Mp lp^2 + Mp^2 lp^2 sin(alpha)^2
xddot     = (J cart + Mp lp cos(alpha) torque) / D
alphaddot = (Mp lp cos(alpha) cart + (Mc + Mp) torque) / D + poke(t)
</pre>
<p>Without a pendulum (<code>Mp</code> = <code>Ip</code> = <code>lp</code> = 0) the cart alone obeys
M<sub>c</sub> xddot = F - Beq xdot. Co-Simulation integrates with classical RK4 sub-steps of at most
{MAX_SUBSTEP * 1e3:g} ms inside each communication step. Model Exchange freezes the switches below as a discrete
state ({", ".join(f"<code>{r}</code>" for r in REGIME)}) that changes only at events, located by
{len(EVENT_INDICATORS)} event indicators ({", ".join(f"<code>{e}</code>" for e in EVENT_INDICATORS)}).</p>

<h2>Friction law (stick-slip)</h2>
<p>The friction vector [F1, v1, F2, v2, B] ({friction}):</p>
<ul>
<li><b>stick</b> while |xdot| &lt; v1 and |F_motor| &lt; F1: F_friction = -F_motor (the cart holds);</li>
<li><b>slip</b> else while |xdot| &lt; v2 and |F_motor| &lt; F2: F_friction = -B xdot (strong viscous drag);</li>
<li><b>free</b> otherwise: F_friction = 0 (only the viscous Beq xdot acts).</li>
</ul>
<p>F1 = F2 = 0 switches stick-slip off. In Model Exchange the cart may also slide on the surfaces |xdot| = v1 or
v2, or |F_motor| = F1 or F2 (through the back-EMF a speed too), where both sides push it there (the Filippov
solution that a fixed step approximates by chattering).</p>

<h2>End stops</h2>
<p>The cart stops dead at &plusmn;{_value("track_half_length")}: at a stop and pushed into it, it is held
(xdot = 0) and the pendulum swings about a fixed pivot. The start position must lie between the stops.</p>

<h2>Amplifier and encoders</h2>
<p>The amplifier saturates the voltage at &plusmn;{_value("V_max")} and, if {_value("I_max")} is positive,
limits the current. The outputs <code>alpha_measured</code> and <code>x_measured</code> are the angle and the
position rounded half away from zero to the encoder steps {_value("q_alpha")} and {_value("q_x")}
(0 switches quantization off).</p>

<h2>Poke</h2>
<p>A rectangular pulse of angular acceleration, {_value("poke_magnitude")} for {_value("poke_duration")} from
{_value("poke_start")}, is added to alphaddot (as a finger flicking the pendulum). Co-Simulation averages it over
each RK4 sub-step, so its impulse is exact wherever its edges fall; Model Exchange reports its edges as time
events.</p>
"""
