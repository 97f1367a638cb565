"""A dependency-free progress bar for runs: frames, steps/s, ETA and a few diagnostics on one line.

On a terminal the line is redrawn in place (carriage return); into a file or pipe one line per frame is
written instead, so logs stay readable.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Mapping
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
    """Progress over ``total`` frames starting at frame ``start``.

    The rate (steps/s) and the ETA leave out the steps before :meth:`warmed`: the first steps of a run load or
    compile the kernels (a first build takes tens of seconds, then the cache serves it), and counting them
    would predict the whole run at the speed of a compilation. A bar never told :meth:`warmed` counts every
    step. ``clock`` (seconds, monotonic) is replaceable for tests."""

    def __init__(
        self,
        total: int,
        start: int = 0,
        stream: TextIO | None = None,
        width: int = 24,
        label: str = "",
        clock: Callable[[], float] = time.perf_counter,
    ):
        self.total, self.start, self.width, self.label = int(total), int(start), int(width), label
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.clock = clock
        self.t0 = clock()
        self.steps = 0
        self.warm: tuple[float, int] | None = None  # (clock, steps done) when the kernels were ready

    def warmed(self, steps_done: int) -> None:
        """The kernels are built: time the rate from now, from ``steps_done`` steps on (the first call counts)."""
        if self.warm is None:
            self.warm = (self.clock(), int(steps_done))

    def rate(self, steps_done: int) -> float:
        """Steps per second since :meth:`warmed` (since the start if it was never called); NaN while no step has
        been timed."""
        t, s = self.warm if self.warm is not None else (self.t0, 0)
        timed = steps_done - s
        return timed / max(self.clock() - t, 1e-9) if timed > 0 else float("nan")

    def eta(self, frame: int, steps_done: int) -> float:
        """Seconds to frame ``total``: the steps left (at this run's steps per frame so far) at :meth:`rate`."""
        done = frame - self.start
        if done <= 0 or steps_done <= 0:
            return float("nan")
        return (self.total - frame) * (steps_done / done) / self.rate(steps_done)

    def update(self, frame: int, steps_done: int, info: Mapping[str, float] | None = None) -> str:
        """Show frame ``frame`` reached after ``steps_done`` steps in this run; returns the line."""
        self.steps = steps_done
        elapsed = max(self.clock() - self.t0, 1e-9)
        done = frame - self.start
        todo = self.total - self.start
        frac = done / todo if todo > 0 else 1.0
        filled = int(round(self.width * frac))
        rate = self.rate(steps_done)
        extras = " ".join(f"{k} {v:.3g}" for k, v in (info or {}).items())
        line = (
            f"{self.label}frame {frame}/{self.total} [{'#' * filled}{'.' * (self.width - filled)}] "
            f"{'?' if rate != rate else f'{rate:.1f}'} steps/s, elapsed {format_duration(elapsed)}, "
            f"ETA {format_duration(self.eta(frame, steps_done))}" + (f" | {extras}" if extras else "")
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
