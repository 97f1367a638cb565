"""Paper 000's Table 1 row by row on this machine, and projected to the paper's GPU, an H100 and an H200.

    python benchmarks/table1.py [--quick] [--out benchmarks/results]

A thin script over couplekit.bench (the measuring code `couplekit bench` runs too): writes table1.json,
table1.png, table1.md and the effect costs next to them (couplekit/bench/runner.py)."""

from __future__ import annotations

import argparse

from couplekit.bench.runner import run_bench

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    res = run_bench(args.out, quick=args.quick)
    print(res["table1_md"])
