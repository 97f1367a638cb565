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

from couplekit.bench.effects import markdown_table, run_effect_costs
from couplekit.bench.runner import plot_effects

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=32, help="cells per side")
    ap.add_argument("--steps", type=int, default=4, help="steps per block")
    ap.add_argument("--alternations", type=int, default=10, help="on/off pairs of blocks")
    ap.add_argument("--backend", default="cpu")
    ap.add_argument(
        "--clock", choices=("wall", "cpu"), default="wall", help="cpu: process time (run with OMP_NUM_THREADS=1)"
    )
    ap.add_argument("--only", nargs="*", default=None, help="effect names (default: all)")
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
