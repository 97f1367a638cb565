"""GPU-side build report without a GPU: registers, stack, spills, occupancy and bandwidth-bound throughput of
every kernel for sm_80 and sm_90.

    python benchmarks/kernel_build_report.py            # writes benchmarks/results/kernel_build_report.json

Compiles every ``kernels/*.cu`` (every declared build variant) with nvcc and ptxas -v.  Per kernel build:
ptxas' registers / stack / spills; the theoretical occupancy on one SM at the cuda backend's block size
(couplekit.backend.traffic.occupancy); for the bulk kernels the compulsory bytes per cell or particle
(couplekit.backend.traffic.KERNEL_TRAFFIC) and the bandwidth-bound throughput that implies on an H100
(3.35 TB/s) and an H200 (4.8 TB/s) at BANDWIDTH_EFFICIENCY of peak.  Exit status 2 if a kernel spills or
exceeds the register budget without a recorded exception (couplekit.backend.nvcc.REGISTER_EXCEPTIONS).
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

from _args import cuda_arch, one_of

from couplekit.backend.nvcc import (
    REGISTER_EXCEPTIONS,
    REGISTER_LIMIT,
    build_variants,
    kernel_sources,
    launch_bounds,
    nvcc_build,
    nvcc_path,
    within_exception,
)
from couplekit.backend.traffic import (
    BANDWIDTH_EFFICIENCY,
    GPU_BANDWIDTH,
    KERNEL_TRAFFIC,
    bytes_per_item,
    occupancy,
    projected_items_per_s,
)

RESULTS = Path(__file__).resolve().parent / "results"


def traffic_key(kernel: str, defines: dict[str, str]) -> str:
    """The KERNEL_TRAFFIC entry of a kernel build: the two-phase collide-stream reads phi and mu too."""
    if kernel == "lbm_collide_stream" and str(defines.get("CK_TWO_PHASE", "0")) == "1":
        return "lbm_collide_stream (two-phase)"
    return kernel


def derived(kernel: str, defines: dict[str, str], registers: int | None, block_size: int) -> dict:
    """Occupancy at ``block_size`` and, for a kernel with a traffic entry, bytes per item and the projected
    bandwidth-bound throughput (items/s) on each GPU of GPU_BANDWIDTH."""
    out: dict = {}
    if registers:
        out["occupancy"] = occupancy(registers, block_size)
    key = traffic_key(kernel, defines)
    traffic = KERNEL_TRAFFIC.get(key)
    if traffic is not None:
        fp16 = str(defines.get("CK_STORAGE_FP16", "0")) == "1"
        nbytes = bytes_per_item(key, "fp16" if fp16 else "fp32")
        out["bytes_per_item"] = nbytes
        out["item"] = traffic.item
        out["traffic"] = traffic.what + (" (f / h stored as fp16)" if fp16 and nbytes != traffic.bytes else "")
        out["projected_items_per_s"] = {gpu: projected_items_per_s(nbytes, bw) for gpu, bw in GPU_BANDWIDTH.items()}
    return out


def over_budget(row: dict) -> bool:
    """A kernel build over REGISTER_LIMIT on sm_90, or spilling beyond its REGISTER_EXCEPTIONS allowance."""
    if row["arch"] == "sm_90" and row.get("registers", 0) > REGISTER_LIMIT:
        return True
    return not within_exception(row["kernel"], row)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description="GPU-side build report without a GPU: registers, stack, spills, occupancy and bandwidth-bound "
        "throughput of every kernel for sm_80 and sm_90, written to benchmarks/results/kernel_build_report.json."
    )
    parser.add_argument("--arch", nargs="+", type=cuda_arch, default=["sm_80", "sm_90"])
    parser.add_argument("--out", type=Path, default=RESULTS / "kernel_build_report.json")
    parser.add_argument(
        "--only", nargs="+", type=one_of("kernel source", [p.name for p in kernel_sources()]), default=None,
        metavar="SOURCE",
        help="rebuild only these sources (e.g. mpm_g2p.cu); the other rows are kept from the existing --out",
    )  # fmt: skip
    args = parser.parse_args(argv)
    if args.only and not args.out.is_file():
        parser.error(f"--only keeps the other rows of --out, and there is no {args.out}: run without --only first")
    nvcc = nvcc_path()
    if nvcc is None:
        print("nvcc is not on the PATH; nothing to report", file=sys.stderr)
        return 1
    version = subprocess.run([nvcc, "--version"], capture_output=True, text=True).stdout.strip().splitlines()[-1]
    block_size, min_blocks = launch_bounds()
    rows = []
    if args.only:
        rows = [r for r in json.loads(args.out.read_text())["kernels"] if r["source"] not in args.only]
    for src in kernel_sources():
        if args.only and src.name not in args.only:
            continue
        for defines in build_variants(src):
            t0 = time.perf_counter()
            reports = nvcc_build(src, args.arch, defines)
            for arch in args.arch:
                for kernel, info in sorted(reports[arch].items()):
                    row = {"source": src.name, "defines": defines, "arch": arch, "kernel": kernel, **info}
                    row.update(derived(kernel, defines, info.get("registers"), block_size))
                    rows.append(row)
                    occ = row.get("occupancy", {}).get("occupancy")
                    print(
                        f"{src.name:24s} {arch} {kernel:28s} regs {info.get('registers', '?'):>3} "
                        f"occ {'?' if occ is None else f'{occ:.0%}':>4} "
                        f"stack {info.get('stack_bytes', 0):>4} spill st/ld {info.get('spill_store_bytes', 0)}/"
                        f"{info.get('spill_load_bytes', 0)}  {defines or ''} ({time.perf_counter() - t0:.1f} s)"
                    )
    order = {p.name: i for i, p in enumerate(kernel_sources())}
    rows.sort(key=lambda r: order.get(r["source"], len(order)))  # stable: a source's variants keep their order
    failing = [r for r in rows if over_budget(r)]
    report = {
        "nvcc": version,
        "host": platform.node(),
        "launch": {"block_size": block_size, "min_blocks_per_sm": min_blocks},
        "register_limit_sm_90": REGISTER_LIMIT,
        "register_exceptions": REGISTER_EXCEPTIONS,
        "bandwidth_bytes_per_s": GPU_BANDWIDTH,
        "bandwidth_efficiency": BANDWIDTH_EFFICIENCY,
        "projection_note": (
            "projected_items_per_s = bandwidth x efficiency / bytes_per_item: the bandwidth-bound ceiling of "
            "one kernel (cells or particles per second), not a measurement; occupancy is theoretical (registers "
            "and block size only, no shared memory), for one SM of sm_80 / sm_90 (65536 registers, 2048 threads)"
        ),
        "kernels": rows,
        "over_budget": [f"{r['source']} {r['arch']} {r['kernel']} {r['defines']}" for r in failing],
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=1) + "\n")
    print(f"wrote {args.out}: {len(rows)} kernel builds, {len(failing)} over the register budget or spilling")
    return 0 if not failing else 2


if __name__ == "__main__":
    sys.exit(main())
