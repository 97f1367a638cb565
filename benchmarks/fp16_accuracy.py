"""Accuracy of fp16 storage of the populations f and h against fp32, on the cpu kernels (issue 14).

    python benchmarks/fp16_accuracy.py [--only taylor_green laplace shear_wave sand_drop] [--threads 1]

Each case runs with ``storage="fp32"`` and ``storage="fp16"`` (same code, same run) and records both numbers:

* Taylor–Green decay, N = 24 and 48 (tests/fluid/test_flow_validation.py, unfiltered stored pressure): the
  relative error of the decay rate against 2 ν k²;
* Laplace jump of a static drop at 1000:1, 32³ (R = 9.6) and 40³ (R = 12), 800 steps
  (tests/fluid/test_two_phase_validation.py): the jump over 2σ/R, the spurious currents, the volume drift;
* shear-wave decay at ν = 1e-3, N = 32 and 64, 4000 steps (tests/fluid/test_shear_wave_precision.py): the
  fitted rate over ν k²;
* fluid volume drift of ``examples/fig13_sand_drop_beaker_small.toml`` (coupled, 800:1, volume controller on)
  shortened to ``SAND_DROP_FRAMES`` frames.

The measurements are the test modules' own functions (imported from tests/fluid), so the table and the tests
measure the same thing. Writes ``benchmarks/results/fp16_accuracy.json`` and prints a Markdown table.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from _args import int_in, one_of

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
sys.path.insert(0, str(ROOT / "tests" / "fluid"))

CASES = ("taylor_green", "laplace", "shear_wave", "sand_drop")
SAND_DROP_FRAMES = 4
"""Frames of the shortened Fig. 13 scene (69 steps each): the ball enters the water in frame 3."""


def taylor_green(cpu, storage: str, sizes=(24, 48)) -> dict:
    from test_flow_validation import _taylor_green_rate_error

    return {f"N={n}": _taylor_green_rate_error(cpu, n, False, storage=storage) for n in sizes}


def laplace(cpu, storage: str, cases=((32, 9.6), (40, 12.0))) -> dict:
    from test_two_phase_validation import static_droplet

    return {f"N={n}": static_droplet(cpu, n, r, storage=storage) for n, r in cases}


def shear_wave(storage: str, sizes=(32, 64), nu: float = 1e-3) -> dict:
    from test_shear_wave_precision import decay_ratio

    return {f"N={n}": decay_ratio("cpu", n, nu, 4000, storage=storage) for n in sizes}


def sand_drop(storage: str, frames: int = SAND_DROP_FRAMES, threads: int = 2) -> dict:
    """fluid_volume_drift of the Fig. 13 small scene after each of ``frames`` frames, and at the end."""
    import tomllib

    from couplekit.scene import Scene
    from couplekit.simulation import Simulation

    data = tomllib.loads((ROOT / "examples" / "fig13_sand_drop_beaker_small.toml").read_text())
    data["fluid"]["storage"] = storage
    sim = Simulation(Scene.from_dict(data, source_name="fig13 small"), backend="cpu", threads=threads, log=None)
    drifts = []
    for _ in range(frames):
        sim.step(sim.scene.time.steps_per_frame)
        sim.check_finite()
        drifts.append(float(sim.diagnostics()["fluid_volume_drift"]))
    return {"steps": sim.step_count, "drift_by_frame": drifts, "drift": drifts[-1]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", nargs="+", type=one_of("case", CASES), default=list(CASES), metavar="CASE",
                        help=f"cases to run, updating them in --out (default all: {' '.join(CASES)})")  # fmt: skip
    parser.add_argument("--threads", type=int_in(1), default=1, help="host threads of the kernels (sand drop: 2)")
    parser.add_argument("--out", type=Path, default=RESULTS / "fp16_accuracy.json")
    args = parser.parse_args()
    from couplekit.backend import get_backend

    cpu = get_backend("cpu", threads=args.threads)
    out: dict = {}
    if args.out.exists():
        out = json.loads(args.out.read_text())  # --only updates the cases it runs
    for case in args.only:
        out[case] = {}
        for storage in ("fp32", "fp16"):
            t = time.perf_counter()
            if case == "taylor_green":
                res = taylor_green(cpu, storage)
            elif case == "laplace":
                res = laplace(cpu, storage)
            elif case == "shear_wave":
                res = shear_wave(storage)
            else:  # "sand_drop" (--only accepts CASES only)
                res = sand_drop(storage)
            out[case][storage] = res
            print(f"{case} {storage} ({time.perf_counter() - t:.0f} s): {json.dumps(res)}", flush=True)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(out, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
