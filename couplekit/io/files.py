"""Several output files written all or none (``couplekit bench``'s results, ``plot``'s and ``compare``'s PNGs)."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Mapping
from pathlib import Path


def write_all(writers: Mapping[Path, Callable[[Path], object]]) -> list[Path]:
    """Write every file of ``writers`` (path -> a function writing that file at the path it is given) all or
    nothing: each to a hidden temporary name beside it first (``.NAME.tmp.SUFFIX``: the suffix keeps a format
    picked by it, as matplotlib's), then all moved into place, so a full disk or Ctrl-C leaves neither a
    truncated file nor a mix of new and old ones. On any failure the temporary files are removed, the files
    already there stay as they were, and the folders this call made are removed again (innermost first, only
    while empty). Returns the paths written."""
    made: list[Path] = []
    tmps: list[tuple[Path, Path]] = []
    try:
        for path in writers:
            for folder in reversed((path.parent, *path.parent.parents)):
                if not folder.exists():
                    folder.mkdir()
                    made.append(folder)
        for path, write in writers.items():
            tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
            tmps.append((tmp, path))
            write(tmp)
        for tmp, path in tmps:
            os.replace(tmp, path)
    except BaseException:
        for tmp, _ in tmps:
            tmp.unlink(missing_ok=True)
        for folder in reversed(made):
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise
    return list(writers)
