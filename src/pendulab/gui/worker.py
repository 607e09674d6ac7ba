"""One simulation of the GUI, in its own process: runs from two tabs share no FMU instance and no state."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any


def run_simulation(spec: Any, meta: Any, folder: str, queue: Any) -> None:
    """Simulate ``spec`` (a RunSpec), write ``run.mat``, ``run.csv``, ``metrics.json`` (``meta`` added) into ``folder``; report on ``queue``.

    Messages: ``("progress", t)``, then ``("done", None)`` or ``("error", message)``.
    """
    from pendulab.errors import UserError

    try:
        from pendulab.cosim.master import SimulationError
        from pendulab.simulation import simulate

        last = [0.0]

        def progress(t: float) -> None:
            now = time.monotonic()
            if now - last[0] > 0.1:  # a few reports a second are enough for a progress bar
                last[0] = now
                queue.put(("progress", float(t)))

        try:
            result = simulate(spec, progress=progress, meta=meta)
        except SimulationError as exc:
            raise UserError(f"the simulation failed: {exc}; check the controller, the poke and the parameters") from None
        result.write(Path(folder))
        queue.put(("done", None))
    except UserError as exc:
        queue.put(("error", str(exc)))
    except Exception as exc:  # noqa: BLE001 - the page shows it; the server keeps running
        queue.put(("error", f"the simulation stopped with an internal error ({type(exc).__name__}: {exc}); please report it"))
