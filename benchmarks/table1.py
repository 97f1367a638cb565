"""Paper 000's Table 1 row by row on this machine, and projected to the paper's GPU, an H100 and an H200.

    python benchmarks/table1.py [--quick] [--out benchmarks/results]

A thin script over couplekit.bench (the measuring code `couplekit bench` runs too): writes table1.json,
table1.png, table1.md and the effect costs next to them (couplekit/bench/runner.py)."""

from __future__ import annotations

import argparse

from couplekit.bench.runner import run_bench

if __name__ == "__main__":
    ap = argparse.ArgumentParser(
        description="Paper 000's Table 1 row by row on this machine, and projected to the paper's GPU, an H100 and "
        "an H200; also measures the effect costs, as `couplekit bench` does."
    )
    ap.add_argument("--quick", action="store_true", help="Fig. 13's row and five coupled-scene effects only (minutes)")
    ap.add_argument(
        "--out",
        default=None,
        help="folder for table1.json, table1.png, table1.md and, by design, the effect costs measured in the "
        "same run: effect_costs.json, effect_costs.png, effect_costs.md (default benchmarks/results)",
    )
    args = ap.parse_args()
    res = run_bench(args.out, quick=args.quick)
    print(res["table1_md"])
