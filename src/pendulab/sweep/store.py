"""A sweep's output folder: a journal, Parquet parts written as the sweep goes, and results.parquet.

Layout of ``DIR``::

    sweep.toml         the spec, as given
    journal.jsonl      first line: the sweep (spec digest, number of runs, columns); then one line
                       per part, appended after the part was written and synced
    parts/part-*.parquet   the rows of the runs completed so far
    results.parquet    at the end: every run, one row each, sorted by run_id
    plots/*.png        at the end

A run counts as done once its part is in the journal. ``--resume`` reads the journal, runs only the
runs it does not list, and ignores a part written after the last journal line (the sweep was killed
between the two); a resumed sweep therefore never records a run twice. A folder without
``results.parquet`` is an unfinished sweep, not a result.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Any, Iterable

from pendulab.errors import UserError

JOURNAL = "journal.jsonl"
RESULTS = "results.parquet"
PARTS = "parts"
FORMAT = "pendulab-sweep-journal"
#: A part is written when this many rows are waiting, or ``[sweep] save_every`` seconds after the last part.
PART_ROWS = 2000


def schema(spec: Any) -> Any:
    """The Arrow schema of a sweep's rows: ids, the varied inputs, status, metrics, time and worker."""
    import pyarrow as pa

    from pendulab.analysis.metrics import METRIC_KEYS

    fields = [pa.field("run_id", pa.int64()), pa.field("point", pa.int64()), pa.field("sample", pa.int64())]
    fields += [pa.field(name, pa.int64() if name == "delay" else pa.float64()) for name in spec.input_names]
    fields += [pa.field("status", pa.string()), pa.field("message", pa.string()),
               pa.field("safety_cut_reason", pa.string()), pa.field("warnings", pa.string())]
    fields += [pa.field(k, pa.bool_() if k == "stable" else pa.float64()) for k in METRIC_KEYS]
    fields += [pa.field("time_s", pa.float64()), pa.field("worker", pa.string())]
    return pa.schema(fields)


def _fsync_write(path: Path, data: bytes, *, append: bool = False) -> None:
    with open(path, "ab" if append else "wb") as handle:
        handle.write(data)
        handle.flush()
        os.fsync(handle.fileno())


class ResultStore:
    """The output folder of one sweep (see the module docstring)."""

    def __init__(self, out: Path, spec: Any, done: set[int], next_part: int) -> None:
        self.out = out
        self.spec = spec
        self.done = done
        self._schema = schema(spec)
        self._buffer: list[dict[str, Any]] = []
        self._next_part = next_part
        self._last_flush = time.monotonic()

    # ---------------------------------------------------------------- opening
    @staticmethod
    def check(out: Path, spec: Any, resume: bool, overwrite: bool = False) -> Any:
        """Check the folder before any work (the output rule of :mod:`pendulab.outputs`); returns its RunFolder.

        Without ``resume``, a folder holding an earlier run or sweep is refused (unless ``overwrite``);
        with it, the folder must hold a sweep of the same spec.
        """
        from pendulab.outputs import check_run_folder

        journal = out / JOURNAL
        if not resume:
            if journal.is_file() and not (out / RESULTS).is_file() and not overwrite:
                raise UserError(f"--out {out} holds an unfinished sweep; continue it with --resume, or add --overwrite to start again")
            return check_run_folder(out, overwrite=overwrite)
        if not journal.is_file():
            raise UserError(f"--resume: {out} holds no sweep ({JOURNAL} is missing); start the sweep without --resume")
        header = _read_journal(journal)[0]
        if header.get("digest") != spec.digest():
            raise UserError(f"--resume: the spec differs from the one {out} was started with ({out / 'sweep.toml'}); resume with that spec")
        return None

    @classmethod
    def open(cls, out: Path, spec: Any, spec_text: str, resume: bool, overwrite: bool = False) -> "ResultStore":
        """Create the folder (or open it to resume)."""
        from pendulab.outputs import atomic_write

        folder = cls.check(out, spec, resume, overwrite)
        if resume:
            lines = _read_journal(out / JOURNAL)
            # Keep only the whole lines: a line cut short by a kill would swallow the next one appended.
            text = "".join(json.dumps(line) + "\n" for line in lines).encode()
            atomic_write(out / JOURNAL, lambda f: f.write(text))
            done: set[int] = set()
            last = -1
            for entry in lines[1:]:
                done.update(_part_ids(out / entry["part"]))
                last = max(last, int(entry["part"].rsplit("-", 1)[1].split(".")[0]))
            return cls(out, spec, done, last + 1)
        folder.prepare(announce=lambda text: print(text, file=sys.stderr))
        try:
            (out / PARTS).mkdir(exist_ok=True)
        except OSError as exc:
            raise UserError(f"cannot create --out {out}: {exc.strerror or exc}; choose another folder") from None
        atomic_write(out / "sweep.toml", lambda f: f.write(spec_text.encode("utf-8")))
        header = {"format": FORMAT, "digest": spec.digest(), "runs": spec.n_runs, "columns": [f.name for f in schema(spec)]}
        atomic_write(out / JOURNAL, lambda f: f.write((json.dumps(header) + "\n").encode()))
        return cls(out, spec, set(), 0)

    @property
    def complete(self) -> bool:
        return (self.out / RESULTS).is_file()

    # ---------------------------------------------------------------- writing
    def add(self, rows: Iterable[dict[str, Any]]) -> None:
        """Keep rows; written as a part when enough wait or enough time has passed."""
        for row in rows:
            if row["run_id"] not in self.done:  # a batch that ran twice (its worker died late) counts once
                self._buffer.append(row)
                self.done.add(row["run_id"])
        if len(self._buffer) >= PART_ROWS or time.monotonic() - self._last_flush >= self.spec.save_every:
            self.flush()

    def flush(self) -> None:
        """Write the waiting rows as a part, then record it in the journal."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        from pendulab.outputs import atomic_write

        self._last_flush = time.monotonic()
        if not self._buffer:
            return
        rows, self._buffer = self._buffer, []
        table = pa.Table.from_pylist(rows, schema=self._schema)
        name = f"{PARTS}/part-{self._next_part:06d}.parquet"
        self._next_part += 1
        atomic_write(self.out / name, lambda f: pq.write_table(table, f))
        _fsync_write(self.out / JOURNAL, (json.dumps({"part": name, "rows": len(rows)}) + "\n").encode(), append=True)

    def finish(self) -> Path:
        """Write ``results.parquet`` (every journalled part, sorted by run id), then remove the parts."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        from pendulab.outputs import atomic_write

        self.flush()
        lines = _read_journal(self.out / JOURNAL)
        tables = [pq.read_table(self.out / entry["part"], schema=self._schema) for entry in lines[1:]]
        table = pa.concat_tables(tables) if tables else self._schema.empty_table()
        table = table.sort_by("run_id")
        ids = table.column("run_id").to_pylist()
        if ids != list(range(self.spec.n_runs)):
            raise RuntimeError(f"the journal holds {len(ids)} rows for {self.spec.n_runs} runs ({len(set(ids))} distinct)")
        path = atomic_write(self.out / RESULTS, lambda f: pq.write_table(table, f))
        for entry in lines[1:]:
            (self.out / entry["part"]).unlink(missing_ok=True)
        try:
            (self.out / PARTS).rmdir()
        except OSError:
            pass
        return path


def _read_journal(path: Path) -> list[dict[str, Any]]:
    lines = []
    for text in path.read_text(encoding="utf-8").splitlines():
        try:
            lines.append(json.loads(text))
        except json.JSONDecodeError:
            break  # a line cut short by a kill: the part it names is not counted
    if not lines or lines[0].get("format") != FORMAT:
        raise UserError(f"{path} is not a pendulab sweep journal; start the sweep in a new folder")
    return lines


def _part_ids(path: Path) -> list[int]:
    import pyarrow.parquet as pq

    return pq.read_table(path, columns=["run_id"]).column("run_id").to_pylist()


def read_results(out: str | os.PathLike[str]) -> Any:
    """``DIR/results.parquet`` as a pyarrow Table."""
    import pyarrow.parquet as pq

    path = Path(out) / RESULTS
    if not path.is_file():
        raise UserError(f"{path} does not exist: the sweep has not finished (continue it with --resume)")
    return pq.read_table(path)
