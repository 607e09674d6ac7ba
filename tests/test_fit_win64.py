"""The fit's compiled replay as a Windows PC with MinGW builds it, proven under Wine: the virtual machine's bits.

On Windows the fit's C is compiled without AVX (:data:`pendulab.simd.WINDOWS_FLAGS`: MinGW's gcc does not align
32-byte vectors on the stack), with OpenMP from MinGW's libgomp, and loaded from Python by ctypes; here the same
C, built by mingw-w64, runs in a plain host (tests/hosts/replay_host.c) under Wine.
"""

from __future__ import annotations

import os
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pendulab import simd
from pendulab.calibration import _replay  # private: the fit's compiled replay is what this checks
from pendulab.calibration.synthetic import RIGS, synthetic_log
from pendulab.fmu.build import WIN64_COMPILER

HOST = Path(__file__).parent / "hosts" / "replay_host.c"
WINE = shutil.which("wine64") or ("/usr/lib/wine/wine64" if Path("/usr/lib/wine/wine64").exists() else None)


def mingw_dll(name: str) -> Path:
    """Where mingw-w64's gcc keeps a runtime DLL (the OpenMP runtime and what it needs)."""
    found = subprocess.run([WIN64_COMPILER, f"-print-file-name={name}"], capture_output=True, text=True, check=True).stdout.strip()
    if not Path(found).is_file():  # Debian keeps libwinpthread beside the import libraries
        found = next(iter(Path("/usr/x86_64-w64-mingw32/lib").glob(name)), Path(found))
    return Path(found)


def test_the_win64_replay_gives_the_virtual_machines_bits(tmp_path):
    log = synthetic_log("chirp", RIGS["sticky"], duration=2.0, voltage_noise=0.0)
    V, t = np.ascontiguousarray(log.V[:-1]), np.ascontiguousarray(log.t[:-1])
    n, m, free = len(V), 11, ("F1", "v1", "F2", "v2", "B", "Beq", "force_gain")
    base = np.asarray(RIGS["sticky"].as_vector(), dtype=float)
    sets = base * np.exp(np.random.default_rng(2).normal(0.0, 0.2, (m, base.size)))
    key, P, h = _replay._key(sets, t, free)
    x0, r, sr = np.zeros(4), np.zeros(n), np.zeros((n, 4))
    r[900], sr[900] = 1.0, (0.01, 0.02, 0.0, 0.0)  # a restart

    (tmp_path / "lanes.c").write_text(_replay._source(*key))
    subprocess.run([WIN64_COMPILER, "-shared", "-static-libgcc", "-fno-math-errno", *simd.WINDOWS_FLAGS, "-fopenmp", *_replay.EXACT_MATH,
                    str(tmp_path / "lanes.c"), "-o", str(tmp_path / "lanes.dll")], check=True, capture_output=True)
    dump = subprocess.run(["x86_64-w64-mingw32-objdump", "-d", str(tmp_path / "lanes.dll")], capture_output=True, text=True, check=True).stdout
    assert "ymm" not in dump and "zmm" not in dump  # no 32- or 64-byte vectors for MinGW to misalign
    subprocess.run([WIN64_COMPILER, "-O1", str(HOST), "-o", str(tmp_path / "replay_host.exe")], check=True, capture_output=True)
    for name in ("libgomp-1.dll", "libgcc_s_seh-1.dll", "libwinpthread-1.dll"):
        shutil.copy(mingw_dll(name), tmp_path)
    with open(tmp_path / "in.bin", "wb") as f:
        f.write(struct.pack("<iiid", m, n, P.shape[1], h))
        for a in (x0, V, t, r, sr, P):
            f.write(np.ascontiguousarray(a, dtype="<f8").tobytes())

    env = {**os.environ, "WINEDEBUG": "-all", "WINEPREFIX": str(tmp_path / "prefix")}
    run = subprocess.run([WINE, "replay_host.exe", "lanes.dll"], cwd=tmp_path, capture_output=True, text=True, timeout=300, env=env)
    assert run.returncode == 0, (run.stdout, run.stderr)
    on_windows = np.fromfile(tmp_path / "out.bin", dtype="<f8").reshape(m, n, 4)
    in_vm = _replay._in_vm(_replay._sample(*key), x0, [V[None], t[None], r[None], sr.T], P, h)[0]
    assert np.array_equal(on_windows, in_vm)
    assert np.ptp(on_windows[:, -1, 0]) > 1e-3  # the sets differ


pytestmark = pytest.mark.skipif(WINE is None or shutil.which(WIN64_COMPILER) is None, reason="needs mingw-w64 and wine64")
