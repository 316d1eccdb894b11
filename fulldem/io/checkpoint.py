"""Checkpoints that resume a run.

Checkpoints are single ``.npz`` files holding every array of the state plus counters and the random generators'
states; ``checkpoint.npz`` is replaced atomically, so a run killed at any moment resumes from the last one.
A file that is not such a checkpoint (truncated, not an .npz, no metadata) raises :class:`CheckpointError`.
"""

from __future__ import annotations

import io
import json
import zipfile
import zlib
from pathlib import Path

import numpy as np

from settler.output import atomic_write_bytes


def _reason(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    text = text if len(text) <= 100 else text[:97] + "..."
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def save_checkpoint(path, arrays: dict, meta: dict):
    """Write arrays and JSON metadata into one .npz, atomically."""
    buf = io.BytesIO()
    np.savez(buf, __meta__=np.frombuffer(json.dumps(meta, default=_json_default).encode(), dtype=np.uint8),
             **arrays)
    atomic_write_bytes(path, buf.getvalue())


class CheckpointError(ValueError):
    """A checkpoint that cannot be read: truncated, not an .npz, or an .npz without settler's metadata."""


def load_checkpoint(path):
    """Read a checkpoint written by :func:`save_checkpoint` -> (arrays dict, meta dict).

    A missing or unreadable file raises the usual OSError; a file that is not a complete checkpoint raises
    :class:`CheckpointError` with a one-line message naming the file and what is wrong.
    """
    path = Path(path)

    def bad(reason):
        return CheckpointError(f"{path} is truncated or not a checkpoint written by settler full: {reason}")

    with open(path, "rb") as fh:  # FileNotFoundError / PermissionError pass through as they are
        try:
            data = np.load(fh, allow_pickle=False)
        except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
            raise bad(f"not an .npz archive ({_reason(exc)})") from exc
        if not isinstance(data, np.lib.npyio.NpzFile):
            raise bad("a single .npy array, not an .npz archive")
        with data:
            if "__meta__" not in data.files:
                raise bad("no __meta__ entry")
            try:
                arrays = {k: data[k] for k in data.files if k != "__meta__"}
                raw = data["__meta__"]
            except (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as exc:
                raise bad(f"an array cannot be read ({_reason(exc)})") from exc
    try:
        meta = json.loads(bytes(raw).decode())
    except (ValueError, TypeError) as exc:
        raise bad(f"__meta__ is not JSON ({_reason(exc)})") from exc
    if not isinstance(meta, dict):
        raise bad("__meta__ is not a JSON object")
    return arrays, meta


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj)}")
