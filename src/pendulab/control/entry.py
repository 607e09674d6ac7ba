"""The controller as a user types it: kernel and compensator text, a PID, a controller file or the demo.

One function, :func:`controller_from_options`, holds the rules (one source, a kernel needs a gain,
compensators need a kernel) and messages that the command line and the GUI show.

Examples
--------
>>> from pendulab.control.entry import controller_from_options
>>> print(controller_from_options(zeros="-3,-6", poles="-30,-0.1", gain="80"))
80 (s + 3)(s + 6) / ((s + 30)(s + 0.1))
>>> controller_from_options(pid="40,5,4").order
2
>>> controller_from_options() is None
True
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from pendulab.errors import UserError


def controller_from_options(
    *,
    zeros: str | None = None,
    poles: str | None = None,
    gain: str | None = None,
    compensators: Sequence[str] = (),
    pid: str | None = None,
    file: str | os.PathLike[str] | None = None,
    demo: bool = False,
    pendulum: str = "long",
) -> Any:
    """The controller the options describe, or ``None`` when none was given.

    Parameters
    ----------
    zeros, poles : str, optional
        The kernel's zeros and poles as text (``"-3,-6"``, ``"-2+1j,-2-1j"``; ``""`` for none).
    gain : str, optional
        The kernel's gain (needed with ``zeros``/``poles``).
    compensators : sequence of str
        Compensators ``"ZEROS;POLES[;GAIN]"``, after the kernel (or the file's or the demo's factors).
    pid : str, optional
        ``"KP,KI,KD"``: :meth:`Controller.pid`.
    file : path, optional
        A controller file (TOML or JSON).
    demo : bool
        The demo controller for ``pendulum``.
    pendulum : str
        The pendulum the demo controller is for.

    Returns
    -------
    Controller or None

    Raises
    ------
    UserError
        Two sources given, a kernel without gain, compensators without a kernel, or a bad value.
    """
    from pendulab import control as ctl

    kernel = zeros is not None or poles is not None or gain is not None
    sources = [name for name, present in (("--zeros/--poles/--gain", kernel), ("--pid", pid is not None),
                                          ("--controller", file is not None), ("--demo", demo)) if present]
    if len(sources) > 1:
        raise UserError(f"give one controller, not {' and '.join(sources)}")
    if compensators and not (kernel or file or demo or pid is not None):
        raise UserError("--compensator needs a kernel: give --zeros, --poles and --gain (or --pid, --controller FILE, --demo)")
    if demo:
        base = ctl.demo_controller(pendulum)
    elif file:
        base = ctl.load_controller_file(file)
    elif pid is not None:
        try:
            kp, ki, kd = (float(p) for p in pid.split(","))
        except ValueError:
            raise UserError(f"--pid {pid!r} must be three numbers KP,KI,KD, e.g. --pid 300,100,100") from None
        # The PID is the kernel; compensators go in series (a PID alone cannot balance: see README).
        base = ctl.Controller.pid(kp, ki, kd)
    elif kernel:
        if gain is None:
            raise UserError("the kernel needs a gain: add --gain K")
        # Kernel and numbered compensators, so that an error names the factor it is about.
        return ctl.parse_controller(zeros or "", poles or "", gain, list(compensators))
    else:
        return None
    if compensators:
        first = len(base.factors)
        extra = [ctl.parse_compensator(c, f"compensator {first + i}") for i, c in enumerate(compensators)]
        base = ctl.Controller([*base.factors, *extra])
    return base
