"""The report's data files: ``report.json`` (JSON-safe) and the frame and bytes CSVs, written atomically."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
import tempfile
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.report.framelog import COLUMNS, FrameLog
from walkstream.shared.errors import InputError

if TYPE_CHECKING:
    pass

from walkstream.shared.arrays import F64

__all__ = [
    "BytesLog",
    "json_safe",
    "write_json",
    "write_frames_csv",
    "read_frames_csv",
    "write_bytes_csv",
    "read_bytes_csv",
    "load_run",
    "atomic_open",
    "bytes_arrays",
]


#: ``(t, cumulative bytes)`` samples of the link: two equal-length 1-D arrays.
BytesLog = tuple[ArrayLike, ArrayLike]


# --------------------------------------------------------------------------- JSON, files


def json_safe(obj: Any) -> Any:
    """A copy of ``obj`` that :func:`json.dumps` accepts with ``allow_nan=False``.

    numpy scalars and arrays become Python numbers and lists, NaN and infinities
    become ``None``, tuples and sets become lists, paths become strings, dataclasses
    become dicts and mapping keys become strings.
    """
    if obj is None or isinstance(obj, bool | str):
        return obj
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return json_safe(dataclasses.asdict(obj))
    if isinstance(obj, Mapping):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple | set | frozenset):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.generic):
        return json_safe(obj.item())
    raise InputError(f"cannot write a {type(obj).__name__} to JSON: {obj!r}")


@contextmanager
def atomic_open(path: Path, mode: str = "w") -> Iterator[IO[Any]]:
    """Open a temporary file next to ``path``; on success move it over ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        kw: dict[str, Any] = {} if "b" in mode else {"encoding": "utf-8", "newline": ""}
        with os.fdopen(fd, mode, **kw) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def write_json(path: str | os.PathLike[str], obj: Any) -> Path:
    """Write ``json_safe(obj)`` to ``path`` atomically (indented, keys in given order)."""
    p = Path(path)
    text = json.dumps(json_safe(obj), indent=2, allow_nan=False) + "\n"
    with atomic_open(p) as f:
        f.write(text)
    return p


def write_frames_csv(path: str | os.PathLike[str], frames: FrameLog) -> Path:
    """Write the log as CSV (header = column names, flags as 0/1) atomically."""
    p = Path(path)
    cols = []
    for name, dtype in COLUMNS:
        a = getattr(frames, name)
        cols.append(a.astype(np.int64).tolist() if dtype is np.bool_ else a.tolist())
    with atomic_open(p) as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow([name for name, _ in COLUMNS])
        w.writerows(zip(*cols, strict=True))
    return p


def read_frames_csv(path: str | os.PathLike[str]) -> FrameLog:
    """Read a log written by :func:`write_frames_csv`.

    Raises
    ------
    InputError
        The file lacks a column or a value does not parse.
    """
    p = Path(path)
    with p.open(encoding="utf-8", newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise InputError(f"{p}: empty file, expected a header row")
    header = rows[0]
    missing = [name for name, _ in COLUMNS if name not in header]
    if missing:
        raise InputError(f"{p}: missing columns {missing}")
    body = rows[1:]
    out: dict[str, Any] = {}
    for name, dtype in COLUMNS:
        j = header.index(name)
        try:
            vals = [r[j] for r in body]
            if dtype is np.bool_:
                out[name] = np.array([int(v) for v in vals], np.int64).astype(np.bool_)
            elif dtype is np.int64:
                out[name] = np.array([int(v) for v in vals], np.int64)
            else:
                out[name] = np.array([float(v) for v in vals], np.float64)
        except (ValueError, IndexError) as exc:
            raise InputError(f"{p}: column {name!r}: {exc}") from exc
    return FrameLog(**out)


def bytes_arrays(bytes_log: BytesLog | None) -> tuple[F64, F64]:
    """``(times, cumulative bytes)`` of a link's bytes log as float arrays (empty without one)."""
    if bytes_log is None:
        return np.empty(0), np.empty(0)
    t = np.asarray(bytes_log[0], dtype=np.float64).reshape(-1)
    b = np.asarray(bytes_log[1], dtype=np.float64).reshape(-1)
    if t.shape != b.shape:
        raise InputError(
            f"bytes log: {t.shape[0]} times but {b.shape[0]} byte counts (must be equal)"
        )
    return t, b


def write_bytes_csv(path: str | os.PathLike[str], bytes_log: BytesLog | None) -> Path:
    """Write the link's ``(t, cumulative bytes)`` samples as CSV atomically."""
    p = Path(path)
    t, b = bytes_arrays(bytes_log)
    with atomic_open(p) as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["t", "bytes"])
        w.writerows(zip(t.tolist(), b.astype(np.int64).tolist(), strict=True))
    return p


def read_bytes_csv(path: str | os.PathLike[str]) -> tuple[F64, NDArray[np.int64]]:
    """Read a bytes log written by :func:`write_bytes_csv`."""
    p = Path(path)
    try:
        data = np.loadtxt(p, delimiter=",", skiprows=1, ndmin=2, dtype=np.float64)
    except ValueError as exc:
        raise InputError(f"{p}: {exc}") from exc
    if data.size == 0:
        return np.empty(0), np.empty(0, np.int64)
    if data.shape[1] != 2:
        raise InputError(f"{p}: expected 2 columns (t, bytes), got {data.shape[1]}")
    return data[:, 0].copy(), data[:, 1].astype(np.int64)


def load_run(
    report_dir: str | os.PathLike[str],
) -> tuple[dict[str, Any], FrameLog, tuple[F64, NDArray[np.int64]]]:
    """Read back ``(summary, frames, bytes_log)`` of a folder written by :func:`write_report`."""
    d = Path(report_dir)
    try:
        summary = json.loads((d / "report.json").read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(f"{d}: cannot read report.json: {exc}") from exc
    bytes_log = (
        read_bytes_csv(d / "bytes.csv")
        if (d / "bytes.csv").exists()
        else (np.empty(0), np.empty(0, np.int64))
    )
    return summary, read_frames_csv(d / "frames.csv"), bytes_log
