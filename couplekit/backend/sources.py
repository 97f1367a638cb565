"""Kernel sources: where they live, what they include, and the text each backend compiles."""

from __future__ import annotations

import hashlib
import re
from importlib import resources
from pathlib import Path

_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.MULTILINE)


def kernel_dir() -> Path:
    """The directory holding the kernel sources (``kernels/`` in a checkout, ``couplekit/kernels`` when installed)."""
    return Path(str(resources.files("couplekit.kernels")))


def kernel_path(name: str) -> Path:
    """Path of the kernel source ``name`` (e.g. ``"selfcheck.cu"``, or an absolute path to a source elsewhere);
    a clear error if it does not exist."""
    path = Path(name) if Path(name).is_absolute() else kernel_dir() / name
    if not path.is_file():
        available = ", ".join(sorted(p.name for p in kernel_dir().glob("*.cu"))) or "none"
        raise FileNotFoundError(f"no kernel source {name!r} in {kernel_dir()} (available: {available})")
    return path


def local_includes(path: Path, _seen: set[Path] | None = None) -> list[Path]:
    """Every ``#include "..."`` reached from ``path``, recursively, in first-seen order (system headers skipped)."""
    seen = set() if _seen is None else _seen
    found: list[Path] = []
    for name in _INCLUDE.findall(path.read_text()):
        inc = (path.parent / name).resolve()
        if inc in seen:
            continue
        if not inc.is_file():
            raise FileNotFoundError(f"{path.name} includes {name!r}, which is not in {path.parent}")
        seen.add(inc)
        found.append(inc)
        found.extend(local_includes(inc, seen))
    return found


def expanded_source(path: Path) -> str:
    """The source with every local ``#include "..."`` pasted in (once each, honouring ``#pragma once``).

    The cuda path compiles this text: CuPy's compile cache is keyed by the source text only, so pasting the
    headers in makes an edited header a new cache key. ``#line`` directives keep compiler messages pointing
    at the original files.
    """
    done: set[Path] = set()

    def expand(p: Path) -> str:
        out = [f'#line 1 "{p.name}"']
        for lineno, line in enumerate(p.read_text().splitlines(), start=1):
            m = _INCLUDE.match(line)
            if m:
                inc = (p.parent / m.group(1)).resolve()
                if inc not in done:
                    done.add(inc)
                    out.append(expand(inc))
                out.append(f'#line {lineno + 1} "{p.name}"')
            elif line.strip() == "#pragma once":
                out.append("")
            else:
                out.append(line)
        return "\n".join(out)

    done.add(path.resolve())
    return expand(path) + "\n"


def source_digest(path: Path, extra: str = "") -> str:
    """SHA-256 over the source, every local header it includes, and ``extra`` (flags, compiler version)."""
    h = hashlib.sha256()
    for p in [path, *local_includes(path)]:
        h.update(p.name.encode())
        h.update(b"\0")
        h.update(p.read_bytes())
        h.update(b"\0")
    h.update(extra.encode())
    return h.hexdigest()
