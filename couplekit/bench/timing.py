"""Timing a simulation's steps for the benchmarks: warm-up first, then the fastest of several blocks."""

from __future__ import annotations

import time


def time_steps(sim, steps: int, repeats: int = 3, warmup: int = 3) -> float:
    """Seconds per step of ``sim``: ``warmup`` steps (kernel building and loading, first-touch of memory),
    then the fastest of ``repeats`` blocks of ``steps`` steps. The minimum is what the scene costs; slower
    blocks measure what else the machine was doing. The scene's stage timers are reset after the warm-up,
    so ``sim.cost_report()`` covers every timed block."""
    if warmup > 0:
        sim.step(warmup)
    sim.reset_timing()
    best = float("inf")
    for _ in range(max(1, int(repeats))):
        t = time.perf_counter()
        sim.step(steps)
        best = min(best, (time.perf_counter() - t) / steps)
    return best
