"""What each effect costs in time per step and memory (as allocated), on and off.

    python benchmarks/effect_costs.py [--n 40] [--steps 20] [--out benchmarks/results/effect_costs.json]

A thin script over couplekit.bench.effects (the code `couplekit bench` runs too)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from couplekit.bench.effects import markdown_table, run_effect_costs

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--n", type=int, default=40, help="cells per side (at 16 the fixed per-step costs hide the effects)"
    )
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--backend", default="cpu")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "effect_costs.json")
    args = ap.parse_args()
    res = run_effect_costs(args.n, args.backend, args.steps, progress=lambda s: print(s, flush=True))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(res, indent=1) + "\n")
    print(markdown_table(res))
