"""What each effect costs in time per step and memory (as allocated), on and off, measured interleaved.

    python benchmarks/effect_costs.py [--n 32] [--steps 4] [--alternations 10] [--out benchmarks/results/effect_costs.json]

A thin script over couplekit.bench.effects (the code `couplekit bench` runs too): per effect both scenes are
built and warmed up, then stepped in alternating blocks; the ratio is the median of the pairs' on/off ratios,
with the interquartile range as its spread (couplekit.bench.effects.measure_pair). Writes the JSON, a PNG
beside it and prints the markdown table."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from _args import int_in, one_of

from couplekit.bench.effects import base_scene, effect_variants, markdown_table, run_effect_costs
from couplekit.bench.runner import plot_effects

MIN_N = 11
"""The smallest --n every effect's scenes build at: at 10 the sand_emission outlet, which carries sand, reaches
the MPM wall layers (2 cells), below 10 the sand ball does (SceneError)."""
EFFECTS = list(effect_variants(base_scene(MIN_N)))

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int_in(MIN_N, why="smaller boxes put the sand in the MPM wall layers"), default=32,
                    help=f"cells per side (>= {MIN_N})")  # fmt: skip
    ap.add_argument("--steps", type=int_in(1), default=4, help="steps per block")
    ap.add_argument("--alternations", type=int_in(1), default=10, help="on/off pairs of blocks")
    ap.add_argument("--backend", choices=("cpu", "numpy", "cuda", "cpu-device"), default="cpu")
    ap.add_argument(
        "--clock", choices=("wall", "cpu"), default="wall", help="cpu: process time (run with OMP_NUM_THREADS=1)"
    )
    ap.add_argument("--only", nargs="+", type=one_of("effect", EFFECTS), default=None, metavar="EFFECT",
                    help=f"effect names (default: all): {', '.join(EFFECTS)}")  # fmt: skip
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "effect_costs.json")
    args = ap.parse_args()
    res = run_effect_costs(
        args.n, args.backend, args.steps, args.only, progress=lambda s: print(s, flush=True),
        alternations=args.alternations, clock=args.clock,
    )  # fmt: skip
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(res, indent=1) + "\n")
    plot_effects(res, args.out.with_suffix(".png"))
    print(markdown_table(res))
