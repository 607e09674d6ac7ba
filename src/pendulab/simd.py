"""CasADi SX functions as C over SIMD lanes: one instruction stream, several parameter sets at once.

CasADi's own C code evaluates one parameter set per call, one double at a time. The fit replays the same
log for many parameter sets (:mod:`pendulab.calibration._replay`), so here each of an SX function's
instructions becomes one operation on a GCC/Clang vector of :data:`LANES` doubles, one set per lane:
a comparison a lane mask, ``if_else`` a blend, no branches. Each lane does exactly the scalar operations
in CasADi's order (IEEE, no reassociation, no contraction), so the results are those of CasADi's virtual
machine, bit for bit, whatever the lane width or the CPU (``tests/test_fit_reproducible.py``).

The width: 4 lanes where the compiler's target has AVX (``-march=native``, :data:`FLAGS`; 8 lanes of
AVX-512 were slower than 4 groups of 4 interleaved), 2 otherwise (SSE2, every x86-64), and
:func:`lanes` says where 2 suit better anyway.

Examples
--------
>>> import casadi as ca
>>> x, y = ca.SX.sym("x"), ca.SX.sym("y")
>>> f = ca.Function("f", [x, y], [ca.if_else(x < y, x * y, 2.0)])
>>> print(statements(f, [lambda j, g: "a", lambda j, g: "b"], [lambda j, e, g: f"out = {e};"]))
vd w0_0, w0_1, w0_2;
w0_0 = a;
w0_1 = b;
w0_2 = (vd)(w0_0 < w0_1);
w0_0 = w0_0 * w0_1;
w0_0 = (vd)((vl)w0_0 & (vl)w0_2);
w0_2 = (vd)~(vl)w0_2;
w0_1 = bc(2.0);
w0_2 = (vd)((vl)w0_1 & (vl)w0_2);
w0_0 = w0_0 + w0_2;
out = w0_0;
"""

from __future__ import annotations

import math
import platform
from typing import Callable, Sequence

import casadi as ca

#: Vector types and helpers; ``LANES`` from the compiler's target unless defined before.
PRELUDE = r"""
#include <math.h>
#include <stddef.h>
#ifndef LANES
#if defined(__AVX__)
#define LANES 4
#else
#define LANES 2
#endif
#endif
typedef double vd __attribute__((vector_size(8 * LANES)));
typedef long long vl __attribute__((vector_size(8 * LANES)));
static inline vd bc(double x) { vd r; for (int l = 0; l < LANES; ++l) r[l] = x; return r; }
static inline vd truth(vl mask) { return (vd)(mask & (vl)bc(1.0)); }
static inline vd pick(vl mask, vd a, vd b) { return (vd)((mask & (vl)a) | (~mask & (vl)b)); }
"""

#: Compiler flags: the machine's own instruction set (the library is cached per machine, see :func:`salt`). On
#: Windows without AVX, whose 32-byte vectors MinGW's gcc does not align on the stack (GCC bug 54412): 2 lanes of
#: SSE4 there (1.6 times faster than SSE2's, measured; AVX's 4 lanes are 2.4 times faster again).
WINDOWS_FLAGS = ("-O2", "-march=native", "-mno-avx")
FLAGS = WINDOWS_FLAGS if platform.system() == "Windows" else ("-O2", "-march=native")

_OPS = {getattr(ca, k): k[3:] for k in dir(ca) if k.startswith("OP_")}
_ARITHMETIC = {"ADD": "+", "SUB": "-", "MUL": "*", "DIV": "/"}
_COMPARE = {"LT": "<", "LE": "<=", "EQ": "==", "NE": "!="}
#: Taken lane by lane from the C library, as CasADi's virtual machine does.
_LIBM = {"SIN": "sin", "COS": "cos", "TAN": "tan", "FLOOR": "floor", "CEIL": "ceil", "SQRT": "sqrt", "EXP": "exp",
         "LOG": "log", "TANH": "tanh", "ATAN": "atan", "ATAN2": "atan2", "POW": "pow", "CONSTPOW": "pow"}


def lanes(f: ca.Function) -> int | None:
    """How many lanes suit ``f``: 2 where it calls the C library (the lanes wait for one scalar call after another,
    and wider vectors only add their packing: the pendulum's step runs 2.6 times slower in 4 lanes than in 2),
    else None: the target's (:data:`PRELUDE`)."""
    return 2 if any(_OPS[f.instruction_id(k)] in _LIBM for k in range(f.n_instructions())) else None


def salt() -> str:
    """What a library built with ``-march=native`` depends on besides its source: the machine's CPU."""
    flags = ""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as info:
            flags = next((line for line in info if line.startswith("flags")), "")
    except OSError:
        pass
    return f"{platform.machine()} {platform.processor()} {flags.strip()}"


def statements(
    f: ca.Function, inputs: Sequence[Callable[[int, int], str]], outputs: Sequence[Callable[[int, str, int], str]], ways: int = 1
) -> str:
    """The C statements that evaluate the SX function ``f`` over lanes, ``ways`` groups of lanes interleaved.

    ``inputs[i](j, g)`` is the C expression (a ``vd``) of input ``i``'s nonzero ``j`` for group ``g``;
    ``outputs[o](j, e, g)`` the statement that stores the expression ``e`` as output ``o``'s nonzero ``j``.
    Work variables are CasADi's own (``f.sz_w()`` of them per group, reused as its code generator reuses them).
    Each instruction is written once per group, side by side: a step's operations form long chains (each waits
    for the last), and independent groups' chains fill the CPU's pipelines (4 groups of 4 lanes replay a cart's
    step 3 times faster than one).
    """
    lines = [f"vd {', '.join(f'w{g}_{i}' for g in range(ways) for i in range(max(f.sz_w(), 1)))};"]
    masks: set[int] = set()  # the work variables that hold a truth value as a lane mask (see _statement)
    for k in range(f.n_instructions()):
        lines += [_statement(f, k, g, inputs, outputs, masks) for g in range(ways)]
        op, o = _OPS[f.instruction_id(k)], f.instruction_output(k)
        if op != "OUTPUT":
            (masks.add if op in _LOGIC else masks.discard)(o[0])
    return "\n".join(lines)


#: Operations whose result is a truth value: kept as a lane mask (all bits set for true), as their consumers
#: (``AND``, ``OR``, ``NOT``, ``IF_ELSE_ZERO``) take it, and made 0 or 1 only where it is a number (the
#: plant's step: 40 % fewer vector operations than 0/1 doubles compared to zero at every use).
_LOGIC = {*_COMPARE, "AND", "OR", "NOT"}


def _statement(f: ca.Function, k: int, g: int, inputs, outputs, masks: set[int]) -> str:
    """Instruction ``k`` of ``f`` for group ``g`` (see :func:`statements`); ``masks``: the work variables that
    hold a lane mask before it."""
    op, a, o = _OPS[f.instruction_id(k)], f.instruction_input(k), f.instruction_output(k)
    if op == "INPUT":
        return f"w{g}_{o[0]} = {inputs[a[0]](a[1], g)};"
    x = [f"truth((vl)w{g}_{i})" if i in masks else f"w{g}_{i}" for i in a]  # each operand as a number
    mask = [f"(vl)w{g}_{i}" if i in masks else f"(w{g}_{i} != 0)" for i in a]  # ... and as a truth (nonzero)
    if op == "OUTPUT":
        return outputs[o[0]](o[1], x[0], g)
    r = f"w{g}_{o[0]}"
    if op == "CONST":
        value = f.instruction_constant(k)
        literal = repr(value) if math.isfinite(value) else "NAN" if math.isnan(value) else ("-" if value < 0 else "") + "INFINITY"
        return f"{r} = bc({literal});"
    if op in _ARITHMETIC:
        return f"{r} = {x[0]} {_ARITHMETIC[op]} {x[1]};"
    if op == "NEG":
        return f"{r} = -{x[0]};"
    if op == "TWICE":
        return f"{r} = {x[0]} + {x[0]};"
    if op == "SQ":
        return f"{r} = {x[0]} * {x[0]};"
    if op in _COMPARE:
        return f"{r} = (vd)({x[0]} {_COMPARE[op]} {x[1]});"
    if op in ("AND", "OR"):
        return f"{r} = (vd)({mask[0]} {'&' if op == 'AND' else '|'} {mask[1]});"
    if op == "NOT":
        return f"{r} = (vd)~{mask[0]};"
    if op == "IF_ELSE_ZERO":
        return f"{r} = (vd)((vl){x[1]} & {mask[0]});"
    if op == "FABS":
        return f"{r} = (vd)((vl){x[0]} & ~(vl)bc(-0.0));"
    if op in ("FMIN", "FMAX"):  # as the virtual machine's: a NaN loses, and of two equal (+0 and -0) the first
        return f"{r} = pick(({x[0]} {'<=' if op == 'FMIN' else '>='} {x[1]}) | ({x[1]} != {x[1]}), {x[0]}, {x[1]});"
    if op == "SIGN":
        return f"{r} = pick({x[0]} < 0, bc(-1.0), pick({x[0]} > 0, bc(1.0), {x[0]}));"
    if op in _LIBM:
        args = ", ".join(f"{v}[l]" for v in x)
        return f"{{ vd t_; for (int l = 0; l < LANES; ++l) t_[l] = {_LIBM[op]}({args}); {r} = t_; }}"
    raise NotImplementedError(f"SX operation {op} has no lane form in pendulab.simd")
