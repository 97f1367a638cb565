"""GPU-side build report without a GPU: registers, stack and spills of every kernel for sm_80 and sm_90.

    python benchmarks/kernel_build_report.py            # writes benchmarks/results/kernel_build_report.json

Compiles every ``kernels/*.cu`` (every declared build variant) with nvcc and ptxas -v.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

from couplekit.backend.nvcc import build_variants, kernel_sources, nvcc_build, nvcc_path

RESULTS = Path(__file__).resolve().parent / "results"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--arch", nargs="+", default=["sm_80", "sm_90"])
    parser.add_argument("--out", type=Path, default=RESULTS / "kernel_build_report.json")
    args = parser.parse_args(argv)
    nvcc = nvcc_path()
    if nvcc is None:
        print("nvcc is not on the PATH; nothing to report", file=sys.stderr)
        return 1
    version = subprocess.run([nvcc, "--version"], capture_output=True, text=True).stdout.strip().splitlines()[-1]
    rows = []
    for src in kernel_sources():
        for defines in build_variants(src):
            t0 = time.perf_counter()
            reports = nvcc_build(src, args.arch, defines)
            for arch in args.arch:
                for kernel, info in sorted(reports[arch].items()):
                    rows.append({"source": src.name, "defines": defines, "arch": arch, "kernel": kernel, **info})
                    print(
                        f"{src.name:24s} {arch} {kernel:28s} regs {info.get('registers', '?'):>3} "
                        f"stack {info.get('stack_bytes', 0):>4} spill st/ld {info.get('spill_store_bytes', 0)}/"
                        f"{info.get('spill_load_bytes', 0)}  {defines or ''} ({time.perf_counter() - t0:.1f} s)"
                    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"nvcc": version, "host": platform.node(), "kernels": rows}, indent=1) + "\n")
    spills = [r for r in rows if r.get("spill_store_bytes") or r.get("spill_load_bytes")]
    print(f"wrote {args.out}: {len(rows)} kernel builds, {len(spills)} with spills")
    return 0 if not spills else 2


if __name__ == "__main__":
    sys.exit(main())
