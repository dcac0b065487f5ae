"""Atomic file output: every file the planner writes (plans, CSV, JSON, figures) goes
through here, so an interrupted run leaves the old file or the new one, never part of one.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import IO, Iterator


@contextlib.contextmanager
def atomic_output(path: str | Path, binary: bool = False) -> Iterator[tuple[IO, Path]]:
    """Open a temporary file next to ``path``; on a clean exit, flush it to disk and
    :func:`os.replace` it onto ``path``; on any exception, delete it.

    Yields ``(file, temporary_path)``: write through ``file``, or, for writers that want
    a file name (matplotlib's ``savefig``), write to ``temporary_path`` and leave ``file``
    alone. The temporary name keeps the target's suffix so format sniffing works.
    """
    target = Path(path)
    try:
        mode = target.stat().st_mode & 0o7777
    except FileNotFoundError:
        mode = 0o644
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp" + target.suffix)
    tmp_path = Path(tmp)
    try:
        if binary:
            f: IO = os.fdopen(fd, "wb")
        else:
            f = os.fdopen(fd, "w", encoding="utf-8", newline="\n")
        with f:
            yield f, tmp_path
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp_path, mode)
        os.replace(tmp_path, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp_path)
        raise


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (UTF-8, ``\\n`` line ends)."""
    with atomic_output(path) as (f, _tmp):
        f.write(text)
    return Path(path)


def write_bytes_atomic(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""
    with atomic_output(path, binary=True) as (f, _tmp):
        f.write(data)
    return Path(path)
