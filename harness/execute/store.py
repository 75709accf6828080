"""The crash-safe store of finished jobs: SQLite inside the run folder.

One transaction per finished job, in WAL mode: a SIGINT or SIGKILL at any
moment leaves every committed job whole and no half-written row (SQLite's
atomic commit). CSV files are exports written from the store, each
atomically (temporary file, then rename), so a kill during an export leaves
the previous file, never a truncated one.

The store holds results by job key; which keys belong to a run is decided
by the job list of the command that reads it, so a changed configuration
(new keys) never reuses a stale result, and old results stay for a command
that asks for them again.
"""

from __future__ import annotations

import json
import os
import sqlite3
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Iterable

from .jobs import JobResult

STORE_NAME = "store.sqlite"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS results (
    key TEXT PRIMARY KEY,
    trial TEXT NOT NULL,
    backend TEXT NOT NULL,
    status TEXT NOT NULL,
    payload TEXT NOT NULL,
    finished REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS meta (
    name TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
"""


class Store:
    """Finished job results of one run folder.

    Parameters
    ----------
    path : Path
        The SQLite file (``<run folder>/store.sqlite``); created if missing.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # isolation_level=None: explicit transactions, one per put
        self._db = sqlite3.connect(str(self.path), timeout=30.0, isolation_level=None)
        self._db.execute("PRAGMA journal_mode=WAL")
        # NORMAL in WAL mode: a commit survives a process kill (SIGKILL); only
        # an OS crash or power loss may lose the last transactions, never corrupt
        self._db.execute("PRAGMA synchronous=NORMAL")
        self._db.executescript(_SCHEMA)

    @classmethod
    def in_folder(cls, folder: str | Path, fresh: bool = False) -> "Store":
        p = Path(folder) / STORE_NAME
        if fresh:
            for suffix in ("", "-wal", "-shm"):
                Path(str(p) + suffix).unlink(missing_ok=True)
        return cls(p)

    def close(self) -> None:
        self._db.close()

    def __enter__(self) -> "Store":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def put(self, result: JobResult) -> None:
        """Commit one finished job (replacing an earlier result of the same key)."""
        row = result.row
        with_tx = "BEGIN IMMEDIATE"
        self._db.execute(with_tx)
        try:
            self._db.execute(
                "INSERT OR REPLACE INTO results (key, trial, backend, status, payload, finished) VALUES (?,?,?,?,?,?)",
                (result.key, str(row.get("trial", "")), str(row.get("backend", "")), str(row.get("status", "")),
                 result.to_json(), time.time()))
            self._db.execute("COMMIT")
        except BaseException:
            self._db.execute("ROLLBACK")
            raise

    def keys(self) -> set[str]:
        return {k for (k,) in self._db.execute("SELECT key FROM results")}

    def get_many(self, keys: Iterable[str]) -> dict[str, JobResult]:
        out: dict[str, JobResult] = {}
        keys = list(keys)
        for i in range(0, len(keys), 500):
            chunk = keys[i:i + 500]
            q = f"SELECT key, payload FROM results WHERE key IN ({','.join('?' * len(chunk))})"
            for k, payload in self._db.execute(q, chunk):
                out[k] = JobResult.from_json(k, payload)
        return out

    def __len__(self) -> int:
        return int(self._db.execute("SELECT COUNT(*) FROM results").fetchone()[0])

    def set_meta(self, name: str, value: Any) -> None:
        self._db.execute("INSERT OR REPLACE INTO meta (name, value) VALUES (?, ?)", (name, json.dumps(value)))

    def get_meta(self, name: str, default: Any = None) -> Any:
        r = self._db.execute("SELECT value FROM meta WHERE name = ?", (name,)).fetchone()
        return json.loads(r[0]) if r else default


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it into place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        write(tmp_path)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp makes 0600; an export is as readable as any new file
        os.replace(tmp_path, path)
    finally:
        tmp_path.unlink(missing_ok=True)
    return path


def atomic_csv(df: Any, path: str | Path) -> Path:
    return atomic_write(path, lambda p: df.to_csv(p, index=False))


def atomic_text(text: str, path: str | Path) -> Path:
    return atomic_write(path, lambda p: p.write_text(text))
