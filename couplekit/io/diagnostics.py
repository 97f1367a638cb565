"""The per-frame diagnostics log: one JSON object per line (``diagnostics.jsonl``), flushed every frame.

Non-finite floats are written as the strings "nan", "inf", "-inf" (strict JSON has no such numbers), and read
back as floats by :func:`read_diagnostics`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["DiagnosticsLog", "read_diagnostics"]


def _clean(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
    if hasattr(v, "item"):
        return _clean(v.item())
    return v


class DiagnosticsLog:
    """Append-only JSON-lines log; ``append=True`` continues an existing file (a resumed run). ``until_step``
    (with ``append``): the records of later steps are dropped first, so a run resumed from an earlier checkpoint
    of its folder does not log those frames twice (as :class:`~couplekit.io.vtk.PvdIndex` drops later entries)."""

    def __init__(self, path: str | Path, append: bool = False, until_step: int | None = None):
        self.path = Path(path)
        if append and until_step is not None and self.path.is_file():
            kept = []
            for line in self.path.read_text(encoding="utf-8").splitlines():
                try:
                    step = json.loads(line).get("step")
                except (ValueError, AttributeError):  # a truncated last line of an interrupted write
                    continue
                if not isinstance(step, (int, float)) or step <= until_step:
                    kept.append(line)
            tmp = self.path.with_name(self.path.name + ".tmp")
            tmp.write_text("".join(line + "\n" for line in kept), encoding="utf-8")
            tmp.replace(self.path)
        self._fh = open(self.path, "a" if append else "w", encoding="utf-8")

    def write(self, record: Mapping[str, Any]) -> None:
        self._fh.write(json.dumps({k: _clean(v) for k, v in record.items()}, allow_nan=False) + "\n")
        self._fh.flush()

    def close(self) -> None:
        self._fh.close()

    def __enter__(self) -> DiagnosticsLog:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_diagnostics(path: str | Path) -> list[dict[str, Any]]:
    """All records of a log (strings "nan"/"inf"/"-inf" back to floats)."""
    out = []
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        if line.strip():
            rec = json.loads(line)
            out.append({k: float(v) if v in ("nan", "inf", "-inf") else v for k, v in rec.items()})
    return out
