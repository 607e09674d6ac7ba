"""Sweeps: one table from every engine, workers killed mid-sweep, --resume, crashes and hangs of a run.

The sweep here is small (16 runs of 1.5 s: two controller gains, one that balances and one that is
cut, over 8 rigs with drawn friction and delay) so that the tests stay cheap; ``bench/sweep.py``
measures the rates.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from pendulab.cli.main import main
from pendulab.sweep import sweep
from pendulab.sweep.spec import parse_sweep_spec, runs_of

SPEC = """
[run]
stop_time = 1.5
poke = [220, 0.005, 0.5]

[controller]
demo = true

[grid]
"kernel.gain" = [20000, 40000]

[uncertainty]
samples = 8
seed = 3
F1 = { uniform = [1.0, 2.0] }
delay = { choice = [0, 1, 3] }

[sweep]
batch = 2
save_every = 0
"""
#: Columns that differ from one execution to the next by nature: who ran a run, and how long it took.
EXECUTION = ["time_s", "worker"]


def table_of(out: Path):
    return pq.read_table(out / "results.parquet")


def same_results(a, b) -> bool:
    return a.drop(EXECUTION).equals(b.drop(EXECUTION))


@pytest.fixture(scope="module")
def spec_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("spec") / "sweep.toml"
    path.write_text(SPEC)
    return path


@pytest.fixture(scope="module")
def reference(spec_file, tmp_path_factory, loop_fmus):
    """The sweep on one local worker process."""
    out = tmp_path_factory.mktemp("ref") / "one"
    result = sweep(spec_file, out, workers=1, plots=False)
    return table_of(out), result


def test_a_reset_instance_runs_as_a_fresh_one(loop_fmus):
    import numpy as np

    import pendulab
    from pendulab.analysis.metrics import METRIC_KEYS
    from pendulab.simulation import Simulator
    from pendulab.sweep.runner import BatchRunner

    spec = parse_sweep_spec(SPEC)
    runs = list(runs_of(spec))
    assert runs[3][3]["delay"] != runs[12][3]["delay"]
    # A later run with run 12's wiring (its delay) on another rig: the master reuses its plan and log buffers.
    later = next(r for r in runs if r[3]["delay"] == runs[12][3]["delay"] and r[3]["F1"] != runs[12][3]["F1"])
    with Simulator() as sim:
        pendulab.simulate(spec.run_spec(runs[3][3]), simulator=sim)  # another controller gain, rig and delay first
        again = pendulab.simulate(spec.run_spec(runs[12][3]), simulator=sim)
        reused = pendulab.simulate(spec.run_spec(later[3]), simulator=sim)
    fresh = pendulab.simulate(spec.run_spec(runs[12][3]))
    assert all(np.array_equal(again.columns[k], fresh.columns[k]) for k in fresh.columns)
    fresh_later = pendulab.simulate(spec.run_spec(later[3]))
    assert all(np.array_equal(reused.columns[k], fresh_later.columns[k]) for k in fresh_later.columns)
    assert not np.array_equal(reused.columns["x"], again.columns["x"])  # another rig, not the last run's buffers
    with BatchRunner() as runner:
        runner.run(spec, *runs[3])
        row = runner.run(spec, *runs[12])
    # The row holds the metrics of SPEC §7 (metrics.json's verdict and reasons are not columns of a sweep).
    assert {k: row[k] for k in METRIC_KEYS} == {k: fresh.metrics[k] for k in METRIC_KEYS}
    assert row["status"] == fresh.metrics["verdict"]["outcome"]


#: A controller at an edge (the demo's kernel gain 80 000, 1.5 s runs): cut at the track limit as it stands, and
#: balanced once any one of these [run] keys changes. Each case: the key's TOML, and the RunSpec section it means.
EDGE_RUN = {"stop_time": "1.5", "poke": "[220, 0.005, 0.5]"}
EDGE_CASES = [
    ("delay", "4", {"timing": ("Timing", {"stop_time": 1.5, "delay": 4})}),
    ("pendulum", '"short"', {"plant": ("Plant", {"pendulum": "short"})}),
    ("cart", '"ip02-weight"', {"plant": ("Plant", {"cart": "ip02-weight"})}),
    ("poke", "[100, 0.005, 0.5]", {"poke": ("Poke", {"magnitude": 100.0, "duration": 0.005, "start": 0.5})}),
    ("supervisor", "{ x_max = 0.5 }", {"supervisor": ("Supervisor", {"x_max": 0.5})}),
]


def test_every_run_key_reaches_the_runs_as_simulate_sees_it(loop_fmus):
    """A sweep's row is what pendulab.simulate gives the same run (spec written out by hand), for [run] keys
    that change the outcome; the rows come from one set of reset FMU instances, in turn."""
    import pendulab
    from pendulab.analysis.metrics import METRIC_KEYS
    from pendulab.control import Controller, demo_controller
    from pendulab.sweep.runner import BatchRunner

    tables = demo_controller().to_dict()
    tables["kernel"]["gain"] = 80000.0
    controller = Controller.from_dict(tables)
    base = {"poke": pendulab.Poke(220.0, 0.005, 0.5), "timing": pendulab.Timing(stop_time=1.5)}
    with BatchRunner() as runner:
        def row_of(run: dict[str, str]) -> dict:
            text = "[run]\n" + "".join(f"{k} = {v}\n" for k, v in run.items()) + "[controller]\ndemo = true\n[grid]\n\"kernel.gain\" = [80000]\n"
            spec = parse_sweep_spec(text)
            return runner.run(spec, *next(runs_of(spec)))

        nominal = pendulab.simulate(pendulab.RunSpec(controller, **base)).metrics
        assert nominal["verdict"]["outcome"] == "cut" and nominal["safety_cut_reason"] == "track limit"
        assert row_of(EDGE_RUN)["status"] == "cut"
        for key, value, sections in EDGE_CASES:
            spec = pendulab.RunSpec(controller, **{**base, **{name: getattr(pendulab, kind)(**fields) for name, (kind, fields) in sections.items()}})
            expected = pendulab.simulate(spec).metrics
            row = row_of({**EDGE_RUN, key: value})
            assert expected["verdict"]["outcome"] == "balanced", key  # the key changes the outcome ...
            assert row["status"] == "balanced", key  # ... in the sweep too, with the same numbers
            assert {k: row[k] for k in METRIC_KEYS} == {k: expected[k] for k in METRIC_KEYS}, key


def test_one_worker_two_workers_and_a_dask_local_cluster_give_one_table(spec_file, reference, tmp_path):
    table, result = reference
    statuses = table.column("status").to_pylist()
    assert table.column("run_id").to_pylist() == list(range(16))
    # Balanced, or not: cut at the track or fallen past the angle limit (the outcome of analysis.verdict).
    assert "balanced" in statuses and set(statuses) - {"balanced"} and set(statuses) <= {"balanced", "cut", "fell"}
    assert sum(result.counts.get(k, 0) for k in ("balanced", "cut", "fell")) == 16
    # the supervisor's reason for each cut, as metrics.json gives it
    reasons = table.column("safety_cut_reason").to_pylist()
    assert all((r is None) == (s == "balanced") for r, s in zip(reasons, statuses))
    assert all(r == "angle limit" for r, s in zip(reasons, statuses) if s == "fell")
    # the varied inputs are columns: the gain per point, the same 8 rigs for both points
    assert table.column("kernel.gain").to_pylist() == [20000.0] * 8 + [40000.0] * 8
    assert table.column("F1").to_pylist()[:8] == table.column("F1").to_pylist()[8:]
    two = sweep(spec_file, tmp_path / "two", workers=2, plots=False)
    assert same_results(table_of(tmp_path / "two"), table)
    assert len(set(table_of(tmp_path / "two").column("worker").to_pylist())) == 2
    pytest.importorskip("distributed")
    dask = sweep(spec_file, tmp_path / "dask", scheduler="local:2", plots=False)
    assert same_results(table_of(tmp_path / "dask"), table)
    assert "Dask" in dask.engine and two.counts == result.counts == dask.counts


def _start(command: list[str], **kwargs) -> subprocess.Popen:
    return subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, **kwargs)


def test_a_dask_worker_killed_mid_sweep_loses_nothing(spec_file, reference, tmp_path):
    pytest.importorskip("distributed")
    dask = str(Path(sys.executable).with_name("dask"))
    address_file = tmp_path / "scheduler.json"
    processes = [_start([dask, "scheduler", "--scheduler-file", str(address_file), "--port", "0", "--no-dashboard"])]
    try:
        deadline = time.monotonic() + 60
        while not address_file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        address = json.loads(address_file.read_text())["address"]
        workers = [_start([dask, "worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard"]) for _ in range(2)]
        processes += workers
        from dask.distributed import Client

        with Client(address) as client:
            client.wait_for_workers(2, timeout=60)
        killed = []

        def kill_one(progress) -> None:
            if not killed:
                workers[0].send_signal(signal.SIGKILL)
                workers[0].wait()
                killed.append(progress.done)

        result = sweep(spec_file, tmp_path / "out", scheduler=address, plots=False, progress=kill_one)
        assert killed and killed[0] < 16  # killed mid-sweep
        table = table_of(tmp_path / "out")
        ids = table.column("run_id").to_pylist()
        assert ids == list(range(16)) and len(set(ids)) == 16
        assert same_results(table, reference[0])
        assert result.counts == reference[1].counts
    finally:
        for p in processes:
            if p.poll() is None:
                p.send_signal(signal.SIGKILL)
                p.wait()


def test_resume_after_the_sweep_is_killed_runs_the_rest_once(spec_file, reference, tmp_path):
    out = tmp_path / "out"
    # The sweep is held at run 10 (it hangs there), so that it is killed with runs 0-9 journalled.
    env = {**os.environ, "PENDULAB_SWEEP_FAULTS": "10:hang"}
    command = [sys.executable, "-m", "pendulab", "sweep", str(spec_file), "--out", str(out), "--workers", "1"]
    process = _start(command, env=env)
    journal = out / "journal.jsonl"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if journal.exists() and len(journal.read_text().splitlines()) >= 1 + 5:
            break
        time.sleep(0.05)
    time.sleep(0.3)
    process.send_signal(signal.SIGKILL)
    process.wait()
    lines = [json.loads(x) for x in journal.read_text().splitlines()[1:]]
    saved = sorted(i for e in lines for i in pq.read_table(out / e["part"]).column("run_id").to_pylist())
    assert saved == list(range(10)) and not (out / "results.parquet").exists()
    assert main(["sweep", str(spec_file), "--out", str(out), "--no-plots"]) == 2  # not without --resume
    assert main(["sweep", str(spec_file), "--out", str(out), "--resume", "--workers", "1", "--no-plots"]) == 0
    table = table_of(out)
    assert table.column("run_id").to_pylist() == list(range(16))
    assert same_results(table, reference[0])
    # The runs saved before the kill were not run again: the resumed session ran exactly the other six.
    workers = table.column("worker").to_pylist()
    assert len(set(workers[:10])) == 1 and set(workers[:10]).isdisjoint(workers[10:])


def test_a_run_that_crashes_or_hangs_its_worker_costs_only_that_run(reference, monkeypatch):
    from pendulab.sweep.sandbox import Sandbox

    spec = parse_sweep_spec(SPEC.replace("[sweep]", "[sweep]\ntimeout = 6"))  # a loaded machine's slowest run: ~1 s
    monkeypatch.setenv("PENDULAB_SWEEP_FAULTS", "2:crash,4:hang")
    sandbox = Sandbox(grace=1.0)
    try:
        rows = sandbox.run_batch(spec, list(runs_of(spec, range(7))))
    finally:
        sandbox.close()
    assert [r["run_id"] for r in rows] == list(range(7))
    assert rows[2]["status"] == "error" and "crashed its worker process" in rows[2]["message"]
    assert rows[4]["status"] == "timeout" and "killed" in rows[4]["message"]
    expected = reference[0].drop(EXECUTION).to_pylist()
    for k in (0, 1, 3, 5, 6):
        assert {c: v for c, v in rows[k].items() if c not in EXECUTION} == expected[k]
    assert len({rows[k]["worker"] for k in (0, 3, 5)}) == 3  # a new worker process after the crash and after the hang


def test_run_errors_and_time_budgets_are_statuses(loop_fmus):
    from pendulab.sweep.runner import BatchRunner

    spec = parse_sweep_spec(SPEC.replace("[sweep]", "[sweep]\ntimeout = 1e-6"))
    broken = parse_sweep_spec(SPEC.replace("poke = [220,", "poke = [1e12,"))
    normal = parse_sweep_spec(SPEC)
    with BatchRunner() as runner:
        late = runner.run(spec, *next(runs_of(spec)))
        failed = runner.run(broken, *next(runs_of(broken)))
        fine = runner.run(normal, *next(runs_of(normal)))
    assert late["status"] == "timeout" and late["stable"] is None
    assert failed["status"] == "error" and "fmi2DoStep failed" in failed["message"]
    assert fine["status"] in ("balanced", "cut", "fell")  # the runner goes on after a failed run


def test_the_cli_writes_results_and_plots(spec_file, reference, tmp_path, capsys):
    out = tmp_path / "cli"
    assert main(["sweep", str(spec_file), "--out", str(out), "--workers", "1"]) == 0
    captured = capsys.readouterr()
    assert "16 runs on 1 local worker process" in captured.out and "balanced" in captured.out
    assert "16/16 runs" in captured.err and "runs/s" in captured.err and "left" in captured.err
    assert same_results(table_of(out), reference[0])
    for name in ("stability_map.png", "metrics.png"):
        assert (out / "plots" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not (out / "parts").exists() and (out / "journal.jsonl").exists()
    assert main(["sweep", str(spec_file), "--out", str(out)]) == 2
    assert "holds an earlier run" in capsys.readouterr().err
    (out / "results.parquet").write_bytes(b"not a table")
    assert main(["sweep", str(spec_file), "--out", str(out), "--overwrite", "--no-plots", "--workers", "1"]) == 0
    assert same_results(table_of(out), reference[0]) and not (out / "plots").exists()


def test_robust_says_in_one_line_how_often_it_balances_and_saves_the_worst_rig(tmp_path, capsys, loop_fmus):
    import math
    import re

    out = tmp_path / "robust"
    args = ["simulate", "--demo", "--poke", "220,0.005,0.5", "--stop-time", "2.5", "--robust", "12", "--out", str(out)]
    assert main(args) == 0
    lines = capsys.readouterr().out.splitlines()
    line = next(x for x in lines if x.startswith("balances on"))
    share, low, high, n = (int(v) for v in re.fullmatch(r"balances on (\d+) % \(95 % CI (\d+)–(\d+) %\) of (\d+) plausible rigs", line).groups())
    table = pq.read_table(out / "robust" / "results.parquet")
    statuses = table.column("status").to_pylist()
    k = statuses.count("balanced")
    assert n == 12 and share == round(100 * k / 12)
    # The Wilson score interval, written out: (p + z^2/2n -/+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n)
    z, p = 1.959963984540054, k / n
    centre, half = p + z * z / (2 * n), z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    assert (low, high) == (round(100 * (centre - half) / (1 + z * z / n)), round(100 * (centre + half) / (1 + z * z / n)))
    assert 0 < k < 12, statuses  # a controller that balances only sometimes under the lab's hard poke
    # The worst rig's run is saved and is one that did not balance.
    worst = json.loads((out / "worst" / "metrics.json").read_text())
    assert worst["stable"] is False and worst["safety_cut_time_s"] is not None
    cuts = [t for t, s in zip(table.column("safety_cut_time_s").to_pylist(), statuses) if s != "balanced"]
    assert worst["safety_cut_time_s"] == pytest.approx(min(cuts), abs=1e-9)
    assert (out / "run.mat").exists() and (out / "worst" / "run.mat").exists()
