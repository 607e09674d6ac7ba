"""A co-simulation system as data: components (FMUs with start values) and connections by name.

Examples
--------
>>> system = System(step=1e-3)
>>> plant = system.add("plant", "fmus/Plant.fmu")
>>> controller = system.add("controller", "fmus/Controller.fmu")
>>> connection = system.connect("plant.alpha_measured", "controller.alpha_measured")
>>> [str(c) for c in system.connections]
['plant.alpha_measured -> controller.alpha_measured']
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pendulab.errors import UserError


@dataclass
class ComponentSpec:
    """One FMU instance in a system."""

    name: str
    fmu: Path
    start_values: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Connection:
    """``source_component.source_variable -> target_component.target_variable``."""

    source: str
    source_variable: str
    target: str
    target_variable: str
    #: Transport delay in communication steps: the target gets the value the source had ``delay``
    #: steps earlier (the start value of the source before that), as on the rig (SPEC §9).
    delay: int = 0

    def __str__(self) -> str:
        arrow = f" -[{self.delay} step delay]-> " if self.delay else " -> "
        return f"{self.source}.{self.source_variable}{arrow}{self.target}.{self.target_variable}"


@dataclass
class System:
    """Components evaluated in the order they were added, at a fixed macro step.

    Within each communication point the components are evaluated in order (Gauss-Seidel): each
    gets its inputs from the outputs already computed at that point, so a chain
    plant -> controller -> supervisor -> plant adds no delay beyond the one step of the plant.
    """

    step: float = 1e-3
    components: dict[str, ComponentSpec] = field(default_factory=dict)
    connections: list[Connection] = field(default_factory=list)

    def add(self, name: str, fmu: str | Path, start_values: dict[str, Any] | None = None) -> ComponentSpec:
        if name in self.components:
            raise UserError(f"component {name!r} is already in the system; give each component its own name")
        component = ComponentSpec(name, Path(fmu), dict(start_values or {}))
        self.components[name] = component
        return component

    def connect(self, source: str, target: str, *, delay: int = 0) -> Connection:
        """Connect ``"component.variable"`` to ``"component.variable"`` (output to input).

        ``delay`` (steps, >= 0) makes the connection a transport delay of that many control periods.
        """
        (src, src_var), (dst, dst_var) = (self._split(source), self._split(target))
        if isinstance(delay, bool) or not isinstance(delay, int) or delay < 0:
            raise UserError(f"delay {delay!r} of connection {source} -> {target} must be a whole number of steps >= 0")
        connection = Connection(src, src_var, dst, dst_var, delay)
        if any(c.target == dst and c.target_variable == dst_var for c in self.connections):
            raise UserError(f"input {target} is already connected; an input takes one connection")
        self.connections.append(connection)
        return connection

    def _split(self, path: str) -> tuple[str, str]:
        component, _, variable = path.partition(".")
        if not variable:
            raise UserError(f"connection end {path!r} must be 'component.variable'")
        if component not in self.components:
            raise UserError(f"unknown component {component!r} in {path!r}; add it to the system first")
        return component, variable
