"""Writing MATLAB v7.3 (HDF5) files as MATLAB does, for tests of the old lab's files."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def save_mat73(path: Path, variables: dict[str, np.ndarray]) -> Path:
    """A MAT v7.3 file: 512-byte MATLAB header, then HDF5 datasets stored column-major (transposed)."""
    import h5py

    with h5py.File(path, "w", userblock_size=512) as handle:
        for name, value in variables.items():
            array = np.atleast_2d(np.asarray(value, dtype=float))
            handle.create_dataset(name, data=array.T)
            handle[name].attrs["MATLAB_class"] = np.bytes_("double")
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Nov 23 08:00:00 2026 HDF5 schema 1.00 ."
    header = header.ljust(116, b" ") + bytes(8) + b"\x00\x02" + b"IM"
    with open(path, "r+b") as handle:
        handle.write(header)
    return path
