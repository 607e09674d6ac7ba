"""The bad-input corpus of every command, in process (``pendulab.cli.main.main``): each case gives one line on
stderr naming the problem, exit status 2, no traceback; no file of an earlier run changes, and nothing that
looks like a result is left behind.

The inputs live in one folder made once (an earlier run, an earlier calibration, damaged logs and runs);
each case runs in a fresh working folder, so a command's default outputs (``runs/``, ``calibration/``)
would show up there.
"""

from __future__ import annotations

import hashlib
import sys

import numpy as np
import pytest
import scipy.io

from pendulab.cli.main import main

RO = "/sys/pendulab-corpus"  # not writable, even for root (Linux sysfs)


def _inputs(root):
    """The materials the cases refer to as {name}."""
    from pendulab.analysis.results import COLUMNS, write_results

    root.mkdir()
    run = root / "earlier_run"
    t = np.arange(0, 3, 0.001)
    cols = {name: np.zeros_like(t) for name in COLUMNS} | {"t": t}
    cols["alpha"] = cols["alpha_measured"] = 0.01 * np.exp(-np.clip(t - 1, 0, None)) * np.sin(8 * np.clip(t - 1, 0, None))
    write_results(run, cols, {"pendulum": "long", "parameters": {"poke_start": 1.0}}, {"stable": True})
    (run / "rig_log.csv").write_text("t,x\n0,0\n")
    (run / "timing.json").write_text("{}")
    nan_run = root / "nan_run"
    cols_nan = dict(cols)
    cols_nan["alpha"] = cols["alpha"].copy()
    cols_nan["alpha"][1500:] = np.nan
    write_results(nan_run, cols_nan, {"pendulum": "long", "source": "rig"}, {})
    cut = root / "cut_run"
    from pendulab.analysis.verdict import cut_before_poke

    write_results(cut, cols, {"pendulum": "long", "source": "rig"}, cut_before_poke(0.920, "the rig's watchdog tripped")[0])
    (root / "earlier.json").write_text('{"friction": [1, 0.005, 3, 0.05, 20]}\n')
    (root / "earlier.csv").write_text("t,V,x\n0,0,0\n")
    (root / "earlier.png").write_bytes(b"\x89PNG earlier")
    (root / "earlier.toml").write_text("# earlier\n")
    (root / "a_file").write_text("not a folder")
    (root / "empty.csv").write_text("")
    (root / "noheader.csv").write_text("0,0,0\n0.001,0,0\n")
    (root / "cut.csv").write_text("t,V,x\n0,0,0\n0.001,0.5,0.0001\n0.002,0.5,0.00")
    (root / "nan.csv").write_text("t,V,x\n0,0,0\n0.001,nan,0\n0.002,0,0\n")
    (root / "novolt.csv").write_text("t,x\n0,0\n0.001,0\n")
    (root / "text.csv").write_text("t,V,x\n0,zero,0\n")
    (root / "short_row.csv").write_text("t,V,x\n0,0,0\n0.001,0\n")
    (root / "backwards.csv").write_text("t,V,x\n0,0,0\n0.002,0,0\n0.001,0,0\n")
    (root / "flat.csv").write_text("t,V,x\n" + "".join(f"{k * 0.001},1.0,0\n" for k in range(3000)))
    (root / "bad.json").write_text("{")
    (root / "neg.json").write_text('{"friction": [-1, 0.005, 3, 0.05, 20]}\n')
    scipy.io.savemat(root / "empty.mat", {"measuredData": np.zeros((0, 0))})
    (root / "bad.toml").write_text("[kernel\n")
    (root / "ctrl.txt").write_text("zeros = []\n")
    old = root / "old_lab_short"
    old.mkdir()
    tt = np.arange(0, 20, 0.01)
    scipy.io.savemat(old / "angle.mat", {"a": np.column_stack([tt, 0 * tt])})
    scipy.io.savemat(old / "position.mat", {"p": np.column_stack([tt, 0.01 * np.sin(tt)])})
    scipy.io.savemat(old / "voltage.mat", {"v": np.column_stack([tt[:50], 0 * tt[:50]])})
    (root / "sweep.toml").write_text('[run]\nstop_time = 2\n\n[controller.pid]\nkp = [600, 750]\nki = 6\nkd = 5\n')
    (root / "sweep_bad_key.toml").write_text('[run]\nstop_time = 2\nwobble = 3\n\n[controller.pid]\nkp = 600\nki = 6\nkd = 5\n')
    (root / "sweep_bad_toml.toml").write_text('[run\n')
    (root / "sweep_low_high.toml").write_text('[run]\nstop_time = 2\n\n[controller]\ndemo = true\n\n[uncertainty]\nsamples = 2\n'
                                              'F1 = { uniform = [2.0, 1.0] }\n')
    (root / "earlier_sweep").mkdir()
    (root / "earlier_sweep" / "run.csv").write_text("earlier")
    (root / "empty_dir").mkdir()
    (root / "earlier_cmp").mkdir()
    (root / "earlier_cmp" / "comparison.txt").write_text("earlier comparison")
    return root


# (command line with {name} for the inputs and {new} for a fresh name in the working folder, fragment of the line)
CASES = [
    # ---------------------------------------------------------------- simulate
    ("simulate --demo --stop-time 0", "--stop-time"),
    ("simulate --demo --stop-time -1", "--stop-time"),
    ("simulate --demo --stop-time nan", "--stop-time"),
    ("simulate --demo --stop-time inf", "--stop-time"),
    ("simulate --demo --stop-time abc", "--stop-time"),
    ("simulate --demo --stop-time 1e9", "steps"),
    ("simulate --demo --step 0", "--step"),
    ("simulate --demo --step 1", "--step"),
    ("simulate --demo --step nan", "--step"),
    ("simulate --demo --delay -1", "--delay"),
    ("simulate --demo --delay 99", "timing.json"),
    ("simulate --demo --delay x", "--delay"),
    ("simulate --demo --poke 1,2", "--poke"),
    ("simulate --demo --poke a,b,c", "--poke"),
    ("simulate --demo --poke nan,0.005,1", "--poke"),
    ("simulate --demo --poke 50,-1,1", "--poke"),
    ("simulate --demo --poke 50,0.005,10", "poke starts"),
    ("simulate --demo --pendulum medium", "pendulum"),
    ("simulate --demo --cart ip99", "cart"),
    ("simulate --demo --calibration {new}.json", "calibration"),
    ("simulate --demo --calibration {bad.json}", "bad.json"),
    ("simulate --demo --calibration {neg.json}", "F1"),
    ("simulate --demo --calibration {empty.mat}", "empty"),
    ("simulate --zeros -3 --poles -30", "gain"),
    ("simulate --zeros -3 --poles -30 --gain abc", "gain"),
    ("simulate --pid 1,2", "--pid"),
    ("simulate --pid a,b,c", "--pid"),
    ("simulate --controller {new}.toml", "controller"),
    ("simulate --controller {bad.toml}", "bad.toml"),
    ("simulate --controller {ctrl.txt}", "toml"),
    ("simulate --demo --pid 1,2,3", "one controller"),
    ("simulate --compensator -2;-20", "kernel"),
    ("simulate --demo --method euler", "method"),
    ("simulate --demo --out {a_file}", "is a file"),
    ("simulate --demo --out {earlier_run}", "earlier run"),
    ("simulate --demo --out " + RO, "cannot write"),
    ("simulate --demo --ssp Plant9", "ssp"),
    ("simulate --demo --frobnicate", "unrecognized"),
    ("simulate", "no controller given"),
    ("simulate --zeros 0 --poles -5 --gain 10", "zero"),
    # ---------------------------------------------------------------- tf / lqr
    ("tf --pendulum none", "no angle"),
    ("tf --pendulum medium", "pendulum"),
    ("tf --output theta", "output"),
    ("tf --root-locus {new}.png", "controller"),
    ("tf --demo --root-locus {earlier.png}", "exists"),
    ("tf --demo --root-locus {new}.jpg", ".png"),
    ("tf --demo --root-locus " + RO + "/rl.png", "cannot write"),
    ("tf --plant seesaw --demo", "seesaw"),
    ("tf --calibration {bad.json}", "bad.json"),
    ("tf --zeros x --poles -1 --gain 1", "zeros"),
    ("lqr --r 0", "--r"),
    ("lqr --r -1", "--r"),
    ("lqr --q 1,2", "--q"),
    ("lqr --q a,b,c,d", "--q"),
    ("lqr --out {new}.json", ".toml"),
    ("lqr --out {earlier.toml}", "exists"),
    ("lqr --out " + RO + "/k.toml", "cannot write"),
    ("lqr --plant cart", "plant"),
    # ---------------------------------------------------------------- calibrate
    ("calibrate", "give the rig"),
    ("calibrate --virtual --port loop://", "give the rig"),
    ("calibrate --port loop:// --friction 1,0.005,2,0.05,20", "--friction"),
    ("calibrate --port loop:// --baud -1", "--baud -1"),
    ("calibrate --port loop:// --baud 0", "--baud 0"),
    ("calibrate --port loop:// --delay 0", "--delay"),
    ("calibrate --port loop:// --delay 99", "--delay"),
    ("calibrate --port loop:// --max-delay 0", "--max-delay"),
    ("calibrate --port {new}/ttyNONE", "cannot open port"),
    ("calibrate --virtual --iterations 0", "--iterations"),
    ("calibrate --virtual --iterations abc", "--iterations"),
    ("calibrate --virtual --iterations 1.5", "--iterations"),
    ("calibrate --virtual --friction 1,2", "--friction"),
    ("calibrate --virtual --friction -1,0.005,2,0.05,20", "F1"),
    ("calibrate --virtual --friction nan,0.005,2,0.05,20", "--friction"),
    ("calibrate --virtual --friction 3,0.005,2,0.05,20", "F2"),
    ("calibrate --virtual --friction a,b,c,d,e", "--friction"),
    ("calibrate --virtual --pendulum medium", "pendulum"),
    ("calibrate --virtual --cart ip99", "cart"),
    ("calibrate --virtual --x0 nan", "--x0"),
    ("calibrate --virtual --x0 inf", "--x0"),
    ("calibrate --virtual --x0 5", "--x0"),
    ("calibrate --virtual --x0 -0.5", "--x0"),
    ("calibrate --virtual --out {earlier.json}", "exists"),
    ("calibrate --virtual --out {empty_dir}", "directory"),
    ("calibrate --virtual --out {new}.txt", ".json"),
    ("calibrate --virtual --out " + RO + "/c.json", "cannot write"),
    ("calibrate --virtual --out {a_file}/c.json", "not a folder"),
    ("calibrate --virtual --out {new}.json --log {earlier.csv}", "exists"),
    ("calibrate --virtual --out {new}.json --log {new}.txt", ".csv"),
    ("calibrate --virtual --out {new}.json --log " + RO + "/l.csv", "cannot write"),
    ("calibrate --port loop:// --out {new}.json --log {earlier.csv}", "exists"),
    ("calibrate --virtual --backend nope", "backend"),
    # ---------------------------------------------------------------- fit
    ("fit", "LOG"),
    ("fit {new}.csv", "does not exist"),
    ("fit {empty.csv}", "empty"),
    ("fit {noheader.csv}", "header"),
    ("fit {cut.csv}", "line 4"),
    ("fit {nan.csv}", "not finite"),
    ("fit {novolt.csv}", "no column V"),
    ("fit {text.csv}", "line 2"),
    ("fit {short_row.csv}", "line 3"),
    ("fit {backwards.csv}", "not increasing"),
    ("fit {flat.csv}", "never moves"),
    ("fit {old_lab_short}", "cut short"),
    ("fit {empty_dir}", "no .mat"),
    ("fit {earlier.csv} --fit F1,Q", "'Q'"),
    ("fit {earlier.csv} --interval 0", "--interval"),
    ("fit {earlier.csv} --interval 5", "--interval"),
    ("fit {earlier.csv} --interval nan", "--interval"),
    ("fit {earlier.csv} --voltage-lag 1.5", "--voltage-lag"),
    ("fit {flat.csv} --voltage-lag 100000", "voltage lag 100000: give a whole number of samples"),
    ("fit {earlier.csv} --out {earlier.json}", "exists"),
    ("fit {earlier.csv} --out {new}.txt", ".json"),
    ("fit {earlier.csv} --out " + RO + "/f.json", "cannot write"),
    ("fit {earlier.csv} --plot {new}.jpg", ".png"),
    ("fit {earlier.csv} --plot {earlier.png}", "exists"),
    ("fit {earlier.csv} --plot " + RO + "/f.png", "cannot write"),
    ("fit {earlier.csv} --calibration {new}.json", "calibration"),
    ("fit {earlier.csv} --calibration {bad.json}", "bad.json"),
    ("fit {earlier.csv} --pendulum medium", "pendulum"),
    ("fit {earlier.csv} --scale-for medium", "scale-for"),
    ("fit {earlier.csv} --start never", "start"),
    ("fit {earlier.csv}", "has 1 sample"),
    # ---------------------------------------------------------------- lab
    ("lab --demo", "--port"),
    ("lab --port loop:// --demo --delay 0", "--delay 0"),
    ("lab --port loop:// --demo --delay 99", "--delay"),
    ("lab --port loop:// --demo --max-delay 0", "--max-delay"),
    ("lab --port loop:// --demo --max-delay 20", "--max-delay"),
    ("lab --port loop:// --demo --stop-time -1", "--stop-time"),
    ("lab --port loop:// --demo --stop-time nan", "--stop-time"),
    ("lab --port loop:// --demo --poke a,b,c", "--poke"),
    ("lab --port loop:// --demo --baud -1", "--baud -1"),
    ("lab --port loop:// --demo --baud 0", "--baud 0"),
    ("lab --port loop:// --demo --method euler", "method"),
    ("lab --port loop:// --demo --pendulum medium", "pendulum"),
    ("lab --port loop:// --demo --calibration {bad.json}", "bad.json"),
    ("lab --port loop:// --demo --out {a_file}", "is a file"),
    ("lab --port loop:// --demo --out {earlier_run}", "earlier run"),
    ("lab --port loop:// --demo --out " + RO + "/lab", "cannot write"),
    ("lab --port loop:// --pid 1,2", "--pid"),
    ("lab --port loop://", "no controller given"),
    ("lab --port loop:// --zeros 0 --poles -5 --gain 10", "zero"),
    ("lab --port {new}/ttyNONE --demo", "cannot open port"),
    ("lab --port loop:// --demo --pid 1,2,3", "one controller"),
    # ---------------------------------------------------------------- rig-emulator (options are checked before the rig is built)
    ("rig-emulator --tcp 99999", "--tcp 99999"),
    ("rig-emulator --tcp -1", "--tcp -1"),
    ("rig-emulator --tcp abc", "--tcp"),
    ("rig-emulator --byte-error-rate 2", "--byte-error-rate"),
    ("rig-emulator --byte-error-rate -0.1", "--byte-error-rate"),
    ("rig-emulator --byte-error-rate nan", "--byte-error-rate"),
    ("rig-emulator --latency -1", "--latency"),
    ("rig-emulator --latency nan", "--latency"),
    ("rig-emulator --jitter -1", "--jitter"),
    ("rig-emulator --restart-after -1", "--restart-after"),
    ("rig-emulator --stall-after inf", "--stall-after"),
    ("rig-emulator --stall-for nan", "--stall-for"),
    ("rig-emulator --close-after -2", "--close-after"),
    ("rig-emulator --fault-after -1", "--fault-after"),
    ("rig-emulator --raise-after nan", "--raise-after"),
    ("rig-emulator --poke 1,2", "--poke"),
    ("rig-emulator --friction 1,2", "--friction"),
    ("rig-emulator --friction -1,0.005,2,0.05,20", "F1"),
    ("rig-emulator --pendulum medium", "pendulum"),
    ("rig-emulator --calibration {bad.json}", "bad.json"),
    ("rig-emulator --seed abc", "--seed"),
    ("rig-emulator --firmware {new}.hex", "not found"),
    # ---------------------------------------------------------------- compare
    ("compare", "RUN"),
    ("compare {new}", "does not exist"),
    ("compare {empty_dir}", "empty_dir"),
    ("compare {nan_run}", "not a number"),
    ("compare {cut_run}", "cut before the poke"),
    ("compare {old_lab_short}", "cut short"),
    ("compare {earlier_run} --out {a_file}", "is a file"),
    ("compare {earlier_run} --out " + RO, "cannot write"),
    ("compare {earlier_run} --out {earlier_cmp}", "earlier result"),
    ("compare {earlier_run} --pendulum medium", "pendulum"),
    ("compare {earlier.json}", "earlier.json"),
    # ---------------------------------------------------------------- sweep
    ("sweep {new}.toml --out {new}", "does not exist"),
    ("sweep {sweep_bad_toml.toml} --out {new}", "sweep_bad_toml.toml"),
    ("sweep {sweep_bad_key.toml} --out {new}", "wobble"),
    ("sweep {sweep_low_high.toml} --out {new}", "F1"),
    ("sweep {sweep.toml} --out {a_file}", "is a file"),
    ("sweep {sweep.toml} --out " + RO + "/s", "cannot write"),
    ("sweep {sweep.toml} --out {earlier_sweep}", "earlier"),
    ("sweep {sweep.toml} --out {new} --resume", "--resume"),
    ("sweep {sweep.toml} --out {new} --workers 0", "--workers"),
    ("sweep {sweep.toml} --out {new} --scheduler bogus", "--scheduler"),
    ("sweep {sweep.toml}", "--out"),
    # ---------------------------------------------------------------- others
    ("gui --out {a_file}", "is a file"),
    ("gui --port abc", "--port"),
    ("build-fmus --out {a_file}", "is a file"),
    ("build-fmus --out " + RO, "cannot write"),
    ("build-fmus Plant9", "unknown FMU"),
    ("docs --bogus", "unrecognized arguments"),
    ("docs extra", "unrecognized arguments"),
    ("docs --frobnicate", "--frobnicate"),
    ("docs --out " + RO, "--out"),
    ("frobnicate", "frobnicate"),
    ("--nonsense", "nonsense"),
]


def _snapshot(folder):
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir"
            for p in sorted(folder.rglob("*"))}


#: Cases that are logs a fit cannot learn from (exit 3, with what to record instead), not bad arguments.
DETERMINES_NOTHING = {"fit {flat.csv}"}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    root = _inputs(tmp_path_factory.mktemp("corpus") / "inputs")
    return root, _snapshot(root)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the unwritable place is Linux sysfs")
@pytest.mark.parametrize("line, fragment", CASES, ids=[c[0][:60] for c in CASES])
def test_bad_input(line, fragment, inputs, tmp_path, monkeypatch, capsys):
    root, before = inputs
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    words = line.split()
    argv = []
    for word in words:
        for name in [p.name for p in root.iterdir()]:
            word = word.replace("{" + name + "}", str(root / name))
        argv.append(word.replace("{new}", str(work / "new")))
    assert "{" not in " ".join(argv), argv
    status = main(argv)
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    # A log that determines nothing is not a usage error: the fit refuses it with exit 3 (issue 19).
    assert status == (3 if line in DETERMINES_NOTHING else 2), (status, out, err)
    assert len(lines) == 1 and "Traceback" not in err, err
    assert fragment.lower() in lines[0].lower(), lines[0]
    assert _snapshot(root) == before, "an earlier run's file changed"
    assert list(work.iterdir()) == [], f"left behind: {list(work.rglob('*'))}"


def test_the_corpus_covers_every_command():
    from pendulab.cli.main import SUBCOMMANDS

    commands = {line.split()[0] for line, _ in CASES}
    assert {name.replace("_", "-") for name in SUBCOMMANDS} <= commands
    assert len(CASES) >= 150
