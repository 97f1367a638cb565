"""A few steps of the small scenes on the cuda backend, for ``compute-sanitizer --tool memcheck`` (the memcheck
step of scripts/gpu_check.sh): every kernel of every effect set the scenes use is launched at least once.

    compute-sanitizer --tool memcheck --error-exitcode 9 python scripts/gpu_memcheck.py [--steps N]

CuPy's memory pool is switched off first, so that each array is its own allocation and a read or write past
its end is one memcheck sees (inside a pooled block it would land in a neighbour and go unseen). Prints one
line per scene; exit 0 when every scene stepped and stayed finite (memcheck's own verdict is its exit code).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from test_simulation_on_backend import CASES  # noqa: E402  (the scenes the simulation-vs-reference test runs)

from couplekit.scene import Scene  # noqa: E402
from couplekit.simulation import Simulation  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=4, help="steps per scene (default 4; the jet runs its own 70)")
    args = ap.parse_args(argv)
    import cupy

    cupy.cuda.set_allocator(None)  # one cudaMalloc per array (module docstring)
    cupy.cuda.set_pinned_memory_allocator(None)
    bad = 0
    for name, (scene, steps) in CASES.items():
        t0 = time.perf_counter()
        sim = Simulation(Scene.from_dict(scene), backend="cuda", log=None)
        n = steps if name == "jet" else args.steps  # the jet emits its first particles after ~60 steps
        sim.step(n)
        d = sim.diagnostics()
        finite = all(v == v for v in d.values() if isinstance(v, float))
        bad += not finite
        print(f"{name}: {n} steps in {time.perf_counter() - t0:.1f} s, finite: {finite}", flush=True)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
