#!/usr/bin/env python3
"""Issue 18's must-show figures: the code before the redesign (a commit, 2bb46a2 by default) against this checkout.

1. **Run files**: ``run.mat``, ``run.csv`` and ``metrics.json`` of the demo, the old lab's three PIDs, the LQR
   block example and a ``--delay 2`` run, written by both trees. Each file is byte-identical or not (``run.mat``
   apart from its 116-byte text header, which holds the date it was written). Where not: every column/key the
   old file has is compared bit for bit (CSV fields as text, MATLAB arrays by their bytes, JSON values
   exactly), and the columns/keys/meta fields the new file adds (or lacks) are listed.
2. **Import time**: ``python -X importtime -c "import pendulab; pendulab.simulate"`` (this checkout) against
   ``import pendulab.cosim.pendulum`` (the old tree), interleaved, ``--rounds`` times each, medians: the sum of
   the top-level imports after ``site`` (wall clock, so the machine's load shows) and the CPU time of the
   import statement (``time.process_time`` in the fresh interpreter; hardly depends on the load).
3. **Doctests**: examples run and skipped in every module, each skip with its reason; the docstring-coverage
   test (``tests/test_docstrings.py -k public_name``) run, its summary line printed.
4. **Line counts** of ``cli/``, ``gui/``, ``cosim/``, ``hil/`` (``*.py``) in both trees.

The old tree is ``git archive``'d into a temporary folder and its FMUs are built there from its own sources
(as bench/watchdog_trips.py does); both trees run with the interpreter running this script.

Usage::

    python bench/refactor_identity.py [--before 2bb46a2] [--rounds 11] [--keep DIR]
"""

from __future__ import annotations

import argparse
import doctest
import importlib
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import scipy.io

REPO = Path(__file__).resolve().parents[1]
PYTHON = sys.executable
#: The cases of the issue: name -> the command's arguments (``pendulab simulate ...`` or the LQR example).
CASES = {
    "demo": ["simulate", "--demo"],
    "pid1": ["simulate", "--pid", "600,200,5", "--poke", "220,0.005,1"],
    "pid2": ["simulate", "--pid", "750,6,10", "--poke", "220,0.005,1"],
    "pid3": ["simulate", "--pid", "1200,20,20", "--poke", "220,0.005,1"],
    "delay2": ["simulate", "--demo", "--delay", "2"],
    "lqr": ["example"],
}
FILES = ("run.mat", "run.csv", "metrics.json")
MAT_HEADER = 116  # MATLAB 5 text header: "MATLAB 5.0 MAT-file Platform: ..., Created on: <date>"
PACKAGES = ("cli", "gui", "cosim", "hil")


def environment(src: Path, fmus: Path | None) -> dict[str, str]:
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": str(src)}
    if fmus is not None:
        env["PENDULAB_FMU_DIR"] = str(fmus)
    return env


def write_runs(tree: Path, env: dict[str, str], out: Path) -> None:
    """Every case's run files into ``out/<case>/``, written by the code of ``tree``."""
    for case, argv in CASES.items():
        if argv == ["example"]:
            command = [PYTHON, str(tree / "examples" / "lqr_controller.py"), "--out", str(out / case)]
        else:
            command = [PYTHON, "-m", "pendulab", *argv, "--out", str(out / case)]
        result = subprocess.run(command, env=env, cwd=out, capture_output=True, text=True)
        if result.returncode != 0:
            raise SystemExit(f"{tree.name}: {' '.join(command[1:])} failed:\n{result.stderr[-2000:]}")


# ---------------------------------------------------------------- 1. the run files
def csv_columns(path: Path) -> dict[str, list[str]]:
    """run.csv as column name -> the fields' text (compared as written, no parsing)."""
    lines = path.read_text().splitlines()
    names = lines[0].split(",")
    rows = [line.split(",") for line in lines[1:]]
    return {name: [row[j] for row in rows] for j, name in enumerate(names)}


def mat_contents(path: Path) -> tuple[dict[str, np.ndarray], dict[str, object]]:
    data = scipy.io.loadmat(path, squeeze_me=False, struct_as_record=False)
    columns = {k: v for k, v in data.items() if not k.startswith("__") and k != "meta"}

    def plain(value: object) -> object:
        if hasattr(value, "_fieldnames"):
            return {f: plain(getattr(value, f)) for f in value._fieldnames}
        if isinstance(value, np.ndarray) and value.dtype == object:
            return [plain(v) for v in value.ravel()]
        if isinstance(value, np.ndarray):
            return (value.dtype.str, value.shape, value.tobytes())
        return value

    meta = plain(data["meta"][0, 0]) if "meta" in data else {}
    return columns, meta  # type: ignore[return-value]


def compare_keys(old: dict, new: dict) -> tuple[list[str], list[str], list[str]]:
    """(changed, added, removed) keys: changed = a key of both whose values differ (exactly)."""
    changed = [k for k in old if k in new and old[k] != new[k]]
    return changed, [k for k in new if k not in old], [k for k in old if k not in new]


def compare_case(before: Path, after: Path) -> list[str]:
    lines = []
    for name in FILES:
        a, b = (before / name).read_bytes(), (after / name).read_bytes()
        same = a[MAT_HEADER:] == b[MAT_HEADER:] if name == "run.mat" else a == b
        if same:
            lines.append(f"  {name:12s} byte-identical ({len(a)} bytes)" + (" apart from the header's date" if name == "run.mat" else ""))
            continue
        if name == "run.csv":
            old, new = csv_columns(before / name), csv_columns(after / name)
            what = "column"
        elif name == "metrics.json":
            old, new = json.loads(a), json.loads(b)
            what = "key"
        else:
            (old, old_meta), (new, new_meta) = mat_contents(before / name), mat_contents(after / name)
            old = {k: (v.dtype.str, v.shape, v.tobytes()) for k, v in old.items()}
            new = {k: (v.dtype.str, v.shape, v.tobytes()) for k, v in new.items()}
            what = "variable"
        changed, added, removed = compare_keys(old, new)
        verdict = "every old " + what + " bit-identical" if not changed else f"CHANGED {what}s: {changed}"
        if changed and name == "metrics.json":
            verdict += " (" + ", ".join(f"{k} {old[k]!r} -> {new[k]!r}" for k in changed) + ")"
        lines.append(f"  {name:12s} differs ({len(a)} / {len(b)} bytes): {verdict}; added {added}; missing {removed}")
        if name == "run.mat":
            changed, added, removed = compare_keys(old_meta, new_meta)
            lines.append(f"  {'':12s} meta struct: changed fields {changed}; added {added}; missing {removed}")
    return lines


# ---------------------------------------------------------------- 2. import time
def import_cost(statement: str, env: dict[str, str]) -> tuple[float, float]:
    """(sum of -X importtime's top-level entries after site, CPU time of the statement), in ms."""
    code = f"import time; c = time.process_time(); {statement}; print(time.process_time() - c)"
    result = subprocess.run([PYTHON, "-X", "importtime", "-c", code], capture_output=True, text=True, env=env, check=True)
    total, after_site = 0, False
    for line in result.stderr.splitlines():
        match = re.match(r"import time:\s+(\d+) \|\s+(\d+) \| (\s*)(\S+)", line)
        if match and not match.group(3):
            if after_site:
                total += int(match.group(2))
            after_site = after_site or match.group(4) == "site"
    return total / 1000, float(result.stdout) * 1000


# ---------------------------------------------------------------- 3. doctests
def doctest_count(src: Path) -> tuple[int, list[str]]:
    """Examples run, and the skipped ones with their reason (the '# skipped: ...' line or the comment)."""
    finder = doctest.DocTestFinder()
    run, skipped = 0, []
    for path in sorted((src / "pendulab").rglob("*.py")):
        parts = path.relative_to(src).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        if name == "pendulab.__main__":
            continue
        for test in finder.find(importlib.import_module(name)):
            lines = test.docstring.splitlines() if test.docstring else []
            for example in test.examples:
                if not example.options.get(doctest.SKIP):
                    run += 1
                    continue
                here = example.lineno
                said = [ln.split("#", 1)[1].strip() for ln in lines[max(0, here - 4) : here] if "# skipped:" in ln]
                own = example.source.split("# doctest")[0]
                reason = said[-1] if said else (own.split("#", 1)[1].strip() if "#" in own else "NO REASON")
                skipped.append(f"{name}: {example.source.strip().splitlines()[0][:60]!r} -- {reason}")
    return run, skipped


def line_count(folder: Path) -> int:
    return sum(len(p.read_text(encoding="utf-8").splitlines()) for p in folder.rglob("*.py"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default="2bb46a2", help="commit of the code before the redesign")
    parser.add_argument("--rounds", type=int, default=11, help="import-time measurements per statement")
    parser.add_argument("--keep", type=Path, help="also copy both trees' run files here")
    args = parser.parse_args()
    print(f"before = {args.before}; after = this checkout ({REPO}); load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")

    with tempfile.TemporaryDirectory(prefix="pendulab-before-") as tmp:
        old_tree = Path(tmp) / "tree"
        old_tree.mkdir()
        archive = subprocess.run(["git", "-C", str(REPO), "archive", args.before], capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(old_tree)], input=archive, check=True)
        envs = {"before": environment(old_tree / "src", Path(tmp) / "fmus"), "after": environment(REPO / "src", None)}
        (Path(tmp) / "fmus").mkdir()
        outs = {}
        for name, tree in (("before", old_tree), ("after", REPO)):
            found = subprocess.run([PYTHON, "-c", "import pendulab; print(pendulab.__file__)"], env=envs[name], capture_output=True, text=True,
                                   check=True).stdout.strip()
            if not Path(found).is_relative_to(tree):
                raise SystemExit(f"{name}: 'import pendulab' finds {found}, not the tree in {tree}")
            subprocess.run([PYTHON, "-c", "from pendulab.fmu.build import ensure_fmu\n"
                            "for n in ('Plant', 'Controller', 'Supervisor'): ensure_fmu(n)"], env=envs[name], check=True)
            outs[name] = Path(tmp) / f"runs-{name}"
            outs[name].mkdir()
            write_runs(tree, envs[name], outs[name])
        if args.keep:
            subprocess.run(["cp", "-r", str(outs["before"]), str(outs["after"]), str(args.keep)], check=True)

        print("\n1. Run files, before -> after")
        for case in CASES:
            print(f"{case} ({' '.join(CASES[case])}):")
            print("\n".join(compare_case(outs["before"] / case, outs["after"] / case)))

        print(f"\n2. Import time, {args.rounds} rounds interleaved, median (min) in ms")
        statements = {"before: import pendulab.cosim.pendulum": ("import pendulab.cosim.pendulum", envs["before"]),
                      "after:  import pendulab; pendulab.simulate": ("import pendulab; pendulab.simulate", envs["after"]),
                      "after:  import pendulab": ("import pendulab", envs["after"])}
        costs: dict[str, list[tuple[float, float]]] = {k: [] for k in statements}
        for _ in range(args.rounds):
            for key, (statement, env) in statements.items():
                costs[key].append(import_cost(statement, env))
        for key, values in costs.items():
            wall, cpu = [v[0] for v in values], [v[1] for v in values]
            print(f"  {key:45s} -X importtime {statistics.median(wall):6.1f} ({min(wall):.1f});  CPU {statistics.median(cpu):6.1f} ({min(cpu):.1f})")

        print("\n3. Doctests (this checkout)")
        run, skipped = doctest_count(REPO / "src")
        print(f"  {run} examples run, {len(skipped)} skipped:")
        print("\n".join(f"    {s}" for s in skipped))
        coverage = subprocess.run([PYTHON, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(REPO / "tests" / "test_docstrings.py"), "-k", "public_name"],
                                  capture_output=True, text=True, cwd=REPO)
        print(f"  docstring coverage (tests/test_docstrings.py -k public_name): {coverage.stdout.strip().splitlines()[-1]}")

        print("\n4. Line counts (*.py)")
        for package in PACKAGES:
            print(f"  {package + '/':7s} {line_count(old_tree / 'src' / 'pendulab' / package):5d} -> {line_count(REPO / 'src' / 'pendulab' / package):5d}")


if __name__ == "__main__":
    main()
