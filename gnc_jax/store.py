"""Study directories on disk: chunked Parquet results that survive the process.

A study written with ``out=DIR`` (``gnc-jax run ... --out DIR``) keeps nothing it has finished
only in memory. The directory holds::

    study.json        the manifest: scenario (its resolved TOML and a hash of it), seed, runs,
                      chunk size, code version, and ``state`` = "partial" or "complete"
    runs/chunk-000012.parquet
                      one file per finished chunk (runs start..stop-1, one row per run, the
                      columns of ``runs.parquet`` before), written under a temporary name and
                      renamed, with the run range and a SHA-256 of its columns in the file's
                      metadata: a file that is there is whole, and a damaged one is detected
    scenario.toml, summary.json, *.png
                      written last, each atomically, once every chunk is there
    .lock             held (``fcntl.flock``) by the one process writing the study

``runs/`` opens as one table in pandas (``pd.read_parquet(DIR / "runs")``), polars
(``pl.read_parquet(DIR / "runs" / "*.parquet")``) or pyarrow (``pq.read_table``). A directory
either holds one complete study (``state: complete`` and ``summary.json``) or says that it is
partial; a study is resumed (finished chunks kept, partial or damaged ones recomputed) only with
the same scenario, seed, run count, chunk size and code version.
"""

import contextlib
import fcntl
import functools
import hashlib
import json
import os
import pathlib
import shutil
import tempfile
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from ._status import Status
from .schema import ScenarioError

MANIFEST = "study.json"
RUNS_DIR = "runs"
LOCK = ".lock"
_FORMAT = 1
# Files a study writes at the top of its directory: what --overwrite removes (besides runs/).
_STUDY_FILES = ("study.json", "summary.json", "scenario.toml", "runs.parquet")


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """The package version and a hash of its source and data files: a resumed study is only
    continued by the code that started it."""
    from ._version import __version__

    root = pathlib.Path(__file__).resolve().parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*")):
        if path.suffix in (".py", ".toml", ".npz") and "__pycache__" not in path.parts:
            h.update(str(path.relative_to(root)).encode())
            h.update(path.read_bytes())
    return f"{__version__}+{h.hexdigest()[:12]}"


def _atomic_write(path: pathlib.Path, write) -> None:
    """``write(tmp_path)`` then rename over ``path`` (same directory, fsynced first)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(pathlib.Path(tmp))
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_text_atomic(path, text: str) -> None:
    _atomic_write(pathlib.Path(path), lambda p: p.write_text(text))


def chunk_table(outcomes: dict[str, np.ndarray], start: int) -> pa.Table:
    """One row per run (``run`` = start, start+1, ...): status, its name, every outcome, vectors
    split into ``name_0``, ``name_1``, ... columns."""
    status = outcomes["status"]
    n = status.shape[0]
    cols: dict[str, Any] = {"run": np.arange(start, start + n, dtype=np.int64)}
    cols["status"] = status
    cols["status_name"] = [Status(int(s)).name for s in status]
    for name, arr in outcomes.items():
        if name == "status":
            continue
        if arr.ndim == 1:
            cols[name] = arr
        else:
            flat = arr.reshape(n, -1)
            for j in range(flat.shape[1]):
                cols[f"{name}_{j}"] = flat[:, j]
    return pa.table(cols)


def _checksum(table: pa.Table) -> str:
    h = hashlib.sha256()
    for name in table.column_names:
        if name == "status_name":  # derived from status
            continue
        h.update(name.encode())
        h.update(np.ascontiguousarray(table.column(name).to_numpy()).tobytes())
    return h.hexdigest()


def _shapes(outcomes: dict[str, np.ndarray]) -> dict[str, list[int]]:
    return {k: list(v.shape[1:]) for k, v in outcomes.items()}


def outcomes_from_table(table: pa.Table, shapes: dict[str, list[int]], names=None) -> dict:
    """The outcome arrays of a runs table (vectors re-assembled from their columns)."""
    out = {}
    for name, shape in shapes.items():
        if names is not None and name not in names:
            continue
        if not shape:
            out[name] = table.column(name).to_numpy()
            continue
        size = int(np.prod(shape))
        cols = [table.column(f"{name}_{j}").to_numpy() for j in range(size)]
        out[name] = np.stack(cols, axis=1).reshape((table.num_rows, *shape))
    return out


def _existing(path: pathlib.Path) -> dict | None:
    manifest = path / MANIFEST
    if not manifest.exists():
        return None
    try:
        return json.loads(manifest.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return {"scenario_name": "?", "state": "damaged"}


def _occupied(path: pathlib.Path) -> bool:
    return path.is_dir() and any(p.name != LOCK for p in path.iterdir())


def check_directory(path, manifest: dict, resume: bool = False, overwrite: bool = False) -> None:
    """:class:`ScenarioError` unless the directory ``path`` can take the study ``manifest``
    (new or empty, the same study with ``resume``, a gnc_jax study with ``overwrite``); reads
    the directory only, so a study checks it before compiling and writes it after."""
    path = pathlib.Path(path)
    old = _existing(path)
    looks_like_study = old is not None or any((path / n).exists() for n in _STUDY_FILES)
    if overwrite and _occupied(path):
        if not looks_like_study:
            raise ScenarioError(
                f"out: {path}: not empty and not a gnc_jax study directory; allowed: an "
                "empty or new directory, or one written by gnc_jax (--overwrite replaces "
                "only those)"
            )
    elif old is not None:
        differs = [
            k
            for k in ("scenario_sha256", "seed", "runs", "chunk_size", "code_version")
            if old.get(k) != manifest.get(k)
        ]
        what = f"a {old.get('state', '?')} study of {old.get('scenario_name', '?')}"
        if not resume:
            raise ScenarioError(
                f"out: {path}: holds {what}; allowed: --resume (continue the same "
                "study) or --overwrite (replace it), or another directory"
            )
        if differs:
            names = {"scenario_sha256": "scenario", "chunk_size": "chunk size"}
            raise ScenarioError(
                f"out: {path}: cannot resume {what}: "
                + ", ".join(
                    f"{names.get(k, k.replace('_', ' '))} differs"
                    + (
                        f" ({old.get(k)} there, {manifest.get(k)} now)"
                        if k != "scenario_sha256"
                        else ""
                    )
                    for k in differs
                )
                + "; allowed: the same study, or --overwrite"
            )
    elif _occupied(path):
        raise ScenarioError(
            f"out: {path}: not empty and holds no gnc_jax study"
            + (" of this version (no study.json)" if looks_like_study else "")
            + "; allowed: an empty or new directory"
            + (", or --overwrite" if looks_like_study else "")
        )


class StudyStore:
    """The on-disk side of one study: manifest, lock, chunk files (see the module docstring).

    Opening it checks the directory against the study (refusing another study unless
    ``overwrite``, continuing this one only with ``resume``) and takes the lock, released by
    :meth:`close` (or by the operating system if the process dies).
    """

    def __init__(self, path, manifest: dict, resume: bool = False, overwrite: bool = False):
        self.path = pathlib.Path(path)
        self.runs_dir = self.path / RUNS_DIR
        self._lock_fd = None
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise ScenarioError(
                f"out: {self.path}: cannot create ({e.strerror or e}); allowed: a directory "
                "that can be created and written"
            ) from None
        self._lock()
        try:
            self.manifest = self._open(manifest, resume, overwrite)
        except BaseException:
            self.close()
            raise

    # -- directory rules ------------------------------------------------------------------
    def _lock(self) -> None:
        fd = os.open(self.path / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise ScenarioError(
                f"out: {self.path}: another process is writing a study there; allowed: another "
                "directory, or wait for it to finish"
            ) from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._lock_fd = fd

    def close(self) -> None:
        if self._lock_fd is not None:
            with contextlib.suppress(OSError):
                fcntl.flock(self._lock_fd, fcntl.LOCK_UN)
                os.close(self._lock_fd)
            self._lock_fd = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _clear(self) -> None:
        for name in _STUDY_FILES:
            with contextlib.suppress(FileNotFoundError):
                (self.path / name).unlink()
        shutil.rmtree(self.runs_dir, ignore_errors=True)
        for png in self.path.glob("*.png"):
            png.unlink()
        for tmp in self.path.glob(".*.tmp"):
            tmp.unlink()

    def _open(self, manifest: dict, resume: bool, overwrite: bool) -> dict:
        check_directory(self.path, manifest, resume, overwrite)
        if overwrite and _occupied(self.path):
            self._clear()
        m = dict(manifest, state="partial", format=_FORMAT)
        self.runs_dir.mkdir(exist_ok=True)
        for tmp in self.runs_dir.glob(".*.tmp"):  # a chunk a killed process did not finish
            tmp.unlink()
        # The study is partial from here until finish(): its summary and figures go first.
        for name in ("summary.json",):
            with contextlib.suppress(FileNotFoundError):
                (self.path / name).unlink()
        write_text_atomic(self.path / MANIFEST, json.dumps(m, indent=1) + "\n")
        return m

    # -- chunks --------------------------------------------------------------------------
    def chunk_path(self, c: int) -> pathlib.Path:
        return _chunk_path(self.path, c)

    def write_chunk(self, c: int, start: int, outcomes: dict[str, np.ndarray]) -> None:
        """Write chunk ``c`` (runs ``start`` ...) atomically, with its checksum."""
        table = chunk_table(outcomes, start)
        meta = {
            "gnc_jax.start": str(start),
            "gnc_jax.stop": str(start + table.num_rows),
            "gnc_jax.sha256": _checksum(table),
            "gnc_jax.shapes": json.dumps(_shapes(outcomes)),
        }
        table = table.replace_schema_metadata({**(table.schema.metadata or {}), **meta})
        _atomic_write(self.chunk_path(c), lambda p: pq.write_table(table, p))

    def discard_chunk(self, c: int) -> None:
        """Remove chunk ``c``'s file, if any (a damaged chunk before it is computed again)."""
        self.chunk_path(c).unlink(missing_ok=True)

    def finish(self, summary: dict, scenario_toml: str) -> None:
        """Write the scenario and the summary, then mark the study complete (all atomic)."""
        write_text_atomic(self.path / "scenario.toml", scenario_toml)
        write_text_atomic(self.path / "summary.json", json.dumps(summary, indent=2) + "\n")
        self.manifest = dict(self.manifest, state="complete")
        write_text_atomic(self.path / MANIFEST, json.dumps(self.manifest, indent=1) + "\n")


def _chunk_valid(path: pathlib.Path, start: int, stop: int) -> bool:
    """The chunk file ``path`` is readable, covers runs start..stop-1 and matches its checksum."""
    if not path.is_file():
        return False
    try:
        table = pq.read_table(path)
        meta = table.schema.metadata or {}
        return (
            int(meta[b"gnc_jax.start"]) == start
            and int(meta[b"gnc_jax.stop"]) == stop
            and table.num_rows == stop - start
            and meta[b"gnc_jax.sha256"].decode() == _checksum(table)
        )
    except (pa.ArrowException, OSError, KeyError, ValueError):
        return False


def chunks_left(path, bounds: list[tuple[int, int]]) -> list[int]:
    """The chunks (``bounds[c]`` = its runs start..stop-1) of the study directory ``path``
    that a resumed study computes: missing or damaged. Reads the directory only."""
    return [
        c
        for c, (start, stop) in enumerate(bounds)
        if not _chunk_valid(_chunk_path(path, c), start, stop)
    ]


def _chunk_path(path, c: int) -> pathlib.Path:
    return pathlib.Path(path) / RUNS_DIR / f"chunk-{c:06d}.parquet"


def chunk_files(path) -> list[pathlib.Path]:
    return sorted((pathlib.Path(path) / RUNS_DIR).glob("chunk-*.parquet"))


def read_runs(path, columns=None) -> pa.Table:
    """The runs table of a study directory (every chunk, ordered by run)."""
    files = chunk_files(path)
    tables = [pq.read_table(f, columns=columns) for f in files]
    table = pa.concat_tables(tables) if tables else None
    return table


def read_outcomes(path, names=None) -> dict[str, np.ndarray]:
    """The outcome arrays of a study directory, ``names`` only (all by default), by run."""
    files = chunk_files(path)
    shapes = json.loads(pq.read_schema(files[0]).metadata[b"gnc_jax.shapes"])
    wanted = set(shapes) if names is None else set(names) | {"status"}
    columns = [
        c
        for name in wanted
        for c in (
            [name]
            if not shapes[name]
            else [f"{name}_{j}" for j in range(int(np.prod(shapes[name])))]
        )
    ]
    parts = [outcomes_from_table(pq.read_table(f, columns=columns), shapes, wanted) for f in files]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def outcome_names(path) -> list[str]:
    files = chunk_files(path)
    return list(json.loads(pq.read_schema(files[0]).metadata[b"gnc_jax.shapes"]))
