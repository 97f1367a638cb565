"""A dependency-free progress bar for runs: frames, steps/s, ETA and a few diagnostics on one line.

On a terminal the line is redrawn in place (carriage return); into a file or pipe one line per frame is
written instead, so logs stay readable.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Mapping
from typing import TextIO

__all__ = ["ProgressBar", "format_duration"]


def format_duration(seconds: float) -> str:
    """H:MM:SS (or M:SS)."""
    if seconds != seconds or seconds == float("inf"):
        return "?"
    s = int(round(seconds))
    h, rem = divmod(s, 3600)
    m, s = divmod(rem, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


class ProgressBar:
    """Progress over ``total`` frames starting at frame ``start``."""

    def __init__(self, total: int, start: int = 0, stream: TextIO | None = None, width: int = 24, label: str = ""):
        self.total, self.start, self.width, self.label = int(total), int(start), int(width), label
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.t0 = time.perf_counter()
        self.steps = 0

    def update(self, frame: int, steps_done: int, info: Mapping[str, float] | None = None) -> str:
        """Show frame ``frame`` reached after ``steps_done`` steps in this run; returns the line."""
        self.steps = steps_done
        elapsed = max(time.perf_counter() - self.t0, 1e-9)
        done = frame - self.start
        todo = self.total - self.start
        frac = done / todo if todo > 0 else 1.0
        filled = int(round(self.width * frac))
        eta = elapsed / done * (self.total - frame) if done > 0 else float("nan")
        extras = " ".join(f"{k} {v:.3g}" for k, v in (info or {}).items())
        line = (
            f"{self.label}frame {frame}/{self.total} [{'#' * filled}{'.' * (self.width - filled)}] "
            f"{steps_done / elapsed:.1f} steps/s, elapsed {format_duration(elapsed)}, ETA {format_duration(eta)}"
            + (f" | {extras}" if extras else "")
        )
        if self.tty:
            self.stream.write("\r" + line + "\x1b[K")
        else:
            self.stream.write(line + "\n")
        self.stream.flush()
        return line

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()
