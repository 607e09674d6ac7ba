"""Model structure from symbolic equations: which known each unknown depends on, and how.

The FMUs' ``<ModelStructure>`` (FMI 2.0 ``dependencies``/``dependenciesKind``, FMI 3.0 ``<Output
dependencies>``) is read off the CasADi expressions of their equations: the structure of the Jacobian of the
unknowns with respect to the knowns, never a hand-written list.

Examples
--------
>>> import casadi as ca
>>> u, k, p = ca.SX.sym("u"), ca.SX.sym("k"), ca.SX.sym("p")
>>> dependencies({"y": 2 * u + p * k, "z": ca.sin(u)}, {"u": u, "k": k}, parameters=[p])
{'y': {'u': 'constant', 'k': 'fixed'}, 'z': {'u': 'dependent'}}
"""

from __future__ import annotations

from typing import Mapping, Sequence

import casadi as ca


def dependencies(unknowns: Mapping[str, ca.SX], knowns: Mapping[str, ca.SX], *, parameters: Sequence[ca.SX] = (),
                 smooth: bool = True) -> dict[str, dict[str, str]]:
    """unknown -> {known: FMI ``dependenciesKind``}, from the Jacobian of ``unknowns`` w.r.t. ``knowns``.

    A structurally non-zero entry is a dependency. Its kind: ``constant`` where the entry is a non-zero
    number (the unknown is the known times a constant, plus the rest); ``fixed`` where the entry depends on
    ``parameters`` only and the equations are ``smooth`` (no switches: a floor or comparison has a zero
    derivative that would look constant); ``dependent`` otherwise.

    Parameters
    ----------
    unknowns, knowns : mapping of name -> scalar SX
    parameters : sequence of SX
        The fixed parameters' symbols (for the ``fixed`` kind).
    smooth : bool
        Whether the equations are free of switches (if_else, floor, fmin, ...).
    """
    names = list(knowns)
    x = ca.vertcat(*[knowns[n] for n in names])
    others = ca.vertcat(*parameters) if parameters else ca.SX(0, 1)
    table: dict[str, dict[str, str]] = {}
    for unknown, expression in unknowns.items():
        jacobian = ca.jacobian(expression, x)
        structure = ca.jacobian_sparsity(expression, x)
        row: dict[str, str] = {}
        for j, name in enumerate(names):
            if not structure.has_nz(0, j):
                continue
            entry = jacobian[0, j]
            if entry.is_constant() and float(ca.evalf(entry)) != 0:
                row[name] = "constant"
            elif smooth and not ca.depends_on(entry, x) and (others.numel() == 0 or ca.depends_on(entry, others)):
                row[name] = "fixed"
            else:
                row[name] = "dependent"
        table[unknown] = row
    return table


def merge(*tables: Mapping[str, Mapping[str, str]]) -> dict[str, dict[str, str]]:
    """The union of dependency tables; a known whose kind differs between them is ``dependent``."""
    merged: dict[str, dict[str, str]] = {}
    for table in tables:
        for unknown, row in table.items():
            into = merged.setdefault(unknown, {})
            for known, kind in row.items():
                into[known] = kind if into.get(known, kind) == kind else "dependent"
    return merged


def state_space_structure(state: ca.SX, inputs: Mapping[str, ca.SX], parameters: Mapping[str, ca.SX],
                          state_names: Sequence[str], outputs: Mapping[str, ca.SX],
                          laws: Sequence[ca.SX] = ()) -> tuple[dict[str, dict[str, str]], dict[str, dict[str, str]]]:
    """The model structure of an FMU whose states are outputs (the plant, the seesaw): its ``dependencies``
    at communication points and its ``initial_dependencies``.

    Parameters
    ----------
    state : SX (n,)
        The states' symbols, named ``state_names``; each state is an output of its own.
    inputs, parameters : mapping of name -> SX
    outputs : mapping of name -> SX
        The other outputs as expressions of states, inputs and parameters (switches and all).
    laws : sequence of SX (n,)
        Right-hand sides (each law the FMU may use: Co-Simulation's, Model Exchange's); their structures are
        merged into the derivatives ``der(<state>)``.
    """
    knowns = {**{s: state[k] for k, s in enumerate(state_names)}, **inputs}
    unknowns = {**{s: state[k] for k, s in enumerate(state_names)}, **outputs}
    initial_unknowns = dict(outputs)
    tables, initial = [dependencies(unknowns, knowns, parameters=list(parameters.values()), smooth=False)], []
    for law in laws or [None]:
        derivatives = {} if law is None else {f"der({s})": law[k] for k, s in enumerate(state_names)}
        tables.append(dependencies(derivatives, knowns, parameters=list(parameters.values()), smooth=False))
        initial.append(dependencies({**initial_unknowns, **derivatives}, {**knowns, **parameters}, smooth=False))
    return merge(*tables), merge(*initial)
