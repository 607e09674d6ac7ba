"""CasADi SX functions as C over SIMD lanes: one instruction stream, several parameter sets at once.

CasADi's own C code evaluates one parameter set per call, one double at a time. The fit replays the same
log for many parameter sets (:mod:`pendulab.calibration._replay`), so here each of an SX function's
instructions becomes one operation on a GCC/Clang vector of :data:`LANES` doubles, one set per lane:
a comparison a lane mask, ``if_else`` a blend, no branches. Each lane does exactly the scalar operations
in CasADi's order (IEEE, no reassociation, no contraction), so the results are those of CasADi's virtual
machine, bit for bit, whatever the lane width or the CPU (``tests/test_fit_reproducible.py``).

The width is the widest the compiler's target has (``-march=native``, :data:`FLAGS`): 8 lanes with
AVX-512, 4 with AVX, 2 otherwise (SSE2, every x86-64).

Examples
--------
>>> import casadi as ca
>>> x, y = ca.SX.sym("x"), ca.SX.sym("y")
>>> f = ca.Function("f", [x, y], [ca.if_else(x < y, x * y, 2.0)])
>>> print(statements(f, [lambda j: "a", lambda j: "b"], [lambda j, e: f"out = {e};"]))
vd w0, w1, w2;
w0 = a;
w1 = b;
w2 = truth(w0 < w1);
w0 = w0 * w1;
w0 = (vd)((vl)w0 & (w2 != 0));
w2 = truth(w2 == 0);
w1 = bc(2.0);
w2 = (vd)((vl)w1 & (w2 != 0));
w0 = w0 + w2;
out = w0;
"""

from __future__ import annotations

import platform
from typing import Callable, Sequence

import casadi as ca

#: Vector types and helpers; ``LANES`` from the compiler's target unless defined before.
PRELUDE = r"""
#include <math.h>
#include <stddef.h>
#ifndef LANES
#if defined(__AVX512F__)
#define LANES 8
#elif defined(__AVX__)
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

#: Compiler flags: the machine's own vector width (the library is cached per machine, see :func:`salt`). Not on
#: Windows, where MinGW's gcc does not align the stack for 32-byte vectors (GCC bug 54412): 2 lanes there.
FLAGS = ("-O2",) if platform.system() == "Windows" else ("-O2", "-march=native")

_OPS = {getattr(ca, k): k[3:] for k in dir(ca) if k.startswith("OP_")}
_ARITHMETIC = {"ADD": "+", "SUB": "-", "MUL": "*", "DIV": "/"}
_COMPARE = {"LT": "<", "LE": "<=", "EQ": "==", "NE": "!="}
#: Taken lane by lane from the C library, as CasADi's virtual machine does.
_LIBM = {"SIN": "sin", "COS": "cos", "TAN": "tan", "FLOOR": "floor", "CEIL": "ceil", "SQRT": "sqrt", "EXP": "exp",
         "LOG": "log", "TANH": "tanh", "ATAN": "atan", "ATAN2": "atan2", "POW": "pow", "CONSTPOW": "pow"}


def lanes(f: ca.Function) -> int | None:
    """How many lanes suit ``f``: 2 where it calls the C library (the lanes wait for one scalar call after another,
    and wider vectors only add their packing: the pendulum's sines run 1.7 times slower in 4 lanes than in 2),
    else None, the target's widest (a cart's step: 5 times faster in 8 lanes than CasADi's scalar C)."""
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


def statements(f: ca.Function, inputs: Sequence[Callable[[int], str]], outputs: Sequence[Callable[[int, str], str]]) -> str:
    """The C statements that evaluate the SX function ``f`` over lanes.

    ``inputs[i](j)`` is the C expression (a ``vd``) of input ``i``'s nonzero ``j``; ``outputs[o](j, e)`` the
    statement that stores the expression ``e`` as output ``o``'s nonzero ``j``. Work variables are CasADi's own
    (``f.sz_w()`` of them, reused as its code generator reuses them).
    """
    lines = [f"vd {', '.join(f'w{i}' for i in range(max(f.sz_w(), 1)))};"]
    for k in range(f.n_instructions()):
        op, a, o = _OPS[f.instruction_id(k)], f.instruction_input(k), f.instruction_output(k)
        if op == "INPUT":
            lines.append(f"w{o[0]} = {inputs[a[0]](a[1])};")
            continue
        if op == "OUTPUT":
            lines.append(outputs[o[0]](o[1], f"w{a[0]}"))
            continue
        r, x = f"w{o[0]}", [f"w{i}" for i in a]
        if op == "CONST":
            value = f.instruction_constant(k)
            lines.append(f"{r} = bc({value!r});" if value == value and abs(value) != float("inf") else f"{r} = bc({'NAN' if value != value else ('-' if value < 0 else '') + 'INFINITY'});")
        elif op in _ARITHMETIC:
            lines.append(f"{r} = {x[0]} {_ARITHMETIC[op]} {x[1]};")
        elif op == "NEG":
            lines.append(f"{r} = -{x[0]};")
        elif op == "TWICE":
            lines.append(f"{r} = {x[0]} + {x[0]};")
        elif op == "SQ":
            lines.append(f"{r} = {x[0]} * {x[0]};")
        elif op in _COMPARE:
            lines.append(f"{r} = truth({x[0]} {_COMPARE[op]} {x[1]});")
        elif op in ("AND", "OR"):
            lines.append(f"{r} = truth(({x[0]} != 0) {'&' if op == 'AND' else '|'} ({x[1]} != 0));")
        elif op == "NOT":
            lines.append(f"{r} = truth({x[0]} == 0);")
        elif op == "IF_ELSE_ZERO":
            lines.append(f"{r} = (vd)((vl){x[1]} & ({x[0]} != 0));")
        elif op == "FABS":
            lines.append(f"{r} = (vd)((vl){x[0]} & ~(vl)bc(-0.0));")
        elif op in ("FMIN", "FMAX"):
            lines.append(f"{r} = pick({x[0]} {'<' if op == 'FMIN' else '>'} {x[1]}, {x[0]}, {x[1]});")
        elif op == "SIGN":
            lines.append(f"{r} = pick({x[0]} < 0, bc(-1.0), pick({x[0]} > 0, bc(1.0), {x[0]}));")
        elif op in _LIBM:
            args = ", ".join(f"{v}[l]" for v in x)
            lines.append(f"{{ vd t_; for (int l = 0; l < LANES; ++l) t_[l] = {_LIBM[op]}({args}); {r} = t_; }}")
        else:
            raise NotImplementedError(f"SX operation {op} has no lane form in pendulab.simd")
    return "\n".join(lines)
