"""Plot a pendulab run yourself and find the first peak by hand.

For students who prefer to read the numbers themselves instead of trusting metrics.json.
It needs only numpy, scipy and matplotlib (no pendulab), so you can copy it anywhere.

Usage::

    python examples/plot_run.py runs/xyz/run.mat

It prints the first peak of the pendulum angle after the poke and when it happens, draws the
angle and the cart position, and saves the picture as ``my_plot.png`` next to ``run.mat``.
(MATLAB users: ``load run.mat`` gives the same column vectors t, x, alpha, ... and a struct meta.)
"""

import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import scipy.io

if len(sys.argv) != 2:
    sys.exit("usage: python plot_run.py path/to/run.mat")
mat_path = Path(sys.argv[1])
if not mat_path.is_file():
    sys.exit(f"error: {mat_path} does not exist; give the run.mat of a run")

# --- 1. Load the file --------------------------------------------------------------------------
# squeeze_me turns the (n, 1) column vectors into plain 1-D arrays; struct_as_record=False lets us
# write meta.parameters.poke_start instead of meta['parameters'][0, 0]['poke_start'][0, 0].
run = scipy.io.loadmat(mat_path, squeeze_me=True, struct_as_record=False)
t = run["t"]  # time (s)
alpha = run["alpha"]  # pendulum angle from upright (rad), positive = leaning toward -x
x = run["x"]  # cart position (m)
# On the real rig only the encoder angle exists; use it if there is no true angle:
# alpha = run["alpha_measured"]

# When did the poke start? It is one of the plant parameters stored in the meta struct.
try:
    poke_start = float(run["meta"].parameters.poke_start)
except (KeyError, AttributeError):
    poke_start = 1.0  # the default poke start
    print("no poke start in the file; assuming 1.0 s")

# --- 2. Find the first peak by hand ------------------------------------------------------------
# Look only after the poke, and measure the angle from where it was just before the poke.
after = t >= poke_start
initial = alpha[t < poke_start][-1] if np.any(t < poke_start) else alpha[0]
deviation = np.abs(alpha[after] - initial)
t_after = t[after]

# A peak is where the deviation stops growing: its slope changes from + to -.
# (np.diff(...) > 0 is True while it grows; the first True -> False change is the first peak.)
growing = np.diff(deviation) > 0
turns = np.flatnonzero(growing[:-1] & ~growing[1:]) + 1
if turns.size == 0:
    print("no peak found after the poke (flat, or still growing at the end of the run)")
    peak_index = None
else:
    peak_index = turns[0]
    peak_time = t_after[peak_index]
    peak_angle = alpha[after][peak_index]
    print(f"poke at t = {poke_start:.3f} s")
    print(f"first peak: alpha = {np.degrees(peak_angle):+.3f} deg at t = {peak_time:.4f} s")
    print(f"peak time (poke start to first peak): {peak_time - poke_start:.4f} s")

# --- 3. Plot ------------------------------------------------------------------------------------
fig, (ax_angle, ax_cart) = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
ax_angle.plot(t, np.degrees(alpha), label="alpha")
ax_angle.axvline(poke_start, color="red", linestyle="--", label="poke")
if peak_index is not None:
    ax_angle.plot(peak_time, np.degrees(peak_angle), "ko", label="first peak")
ax_angle.set_ylabel("angle (deg)")
ax_angle.legend()
ax_angle.grid(True)

ax_cart.plot(t, 100 * x, color="purple")
ax_cart.axvline(poke_start, color="red", linestyle="--")
ax_cart.set_ylabel("cart position (cm)")
ax_cart.set_xlabel("time (s)")
ax_cart.grid(True)

out = mat_path.with_name("my_plot.png")
fig.savefig(out, dpi=100)
print(f"plot saved to {out}")
# Show a window when there is a screen (MPLBACKEND=Agg, as in the tests, has none).
if plt.get_backend().lower() != "agg":
    plt.show()
