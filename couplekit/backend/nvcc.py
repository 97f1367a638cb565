"""Offline GPU builds: compile kernel sources with nvcc and read ptxas' register and spill report.

Used by the build tests (every kernel builds for sm_80 and sm_90 without spills) and by
``benchmarks/kernel_build_report.py``, so GPU-side costs are visible on machines without a GPU.
"""

from __future__ import annotations

import itertools
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

from .host import define_flags
from .sources import kernel_dir

_VARIANTS = re.compile(r"^\s*//\s*variants:\s*(.+)$", re.MULTILINE)
_FUNC = re.compile(r"Compiling entry function '(\w+)' for '(sm_\d+)'")
_SPILL = re.compile(r"(\d+) bytes stack frame, (\d+) bytes spill stores, (\d+) bytes spill loads")
_REGS = re.compile(r"Used (\d+) registers")


_BLOCK = re.compile(r"^#define CK_BLOCK_SIZE (\d+)\s*$", re.MULTILINE)
_MIN_BLOCKS = re.compile(r"^#define CK_MIN_BLOCKS_PER_SM (\d+)\s*$", re.MULTILINE)

# the register budget per thread on sm_90: 65536 registers / (256 threads x 2 blocks), kernels/common.cuh
REGISTER_LIMIT = 128
# kernels allowed to spill under the budget: kernel -> (most spill bytes allowed, stores or loads, the measured
# reason); docs/backends.md, "Register budget"
REGISTER_EXCEPTIONS: dict[str, tuple[int, str]] = {
    "lbm_collide_stream": (
        4,
        "one register (4 B spill store + load) over 128 in two variants on sm_80: the single-phase "
        "CK_EXT_FORCE=1 builds with CK_MIXTURE=0 (surface tension 0 or 1), since the shifted storage of f "
        "(docs/precision.md). Every sm_90 build and every fp16-storage build spills nothing since session 14 "
        "(the all-closures variants' 4 B went when the odd-rate re-read of the populations stopped being merged "
        "with the first loads, kernels/lbm_collide.cu); an order that removes the sm_80 spill (the pressure "
        "gradient's loads made to wait for the raw moments) made the fp16 single-phase builds spill 28-32 B",
    )
}


def within_exception(kernel: str, info: dict) -> bool:
    """Whether a kernel build's spills are within its REGISTER_EXCEPTIONS allowance (no spills: True)."""
    spill = max(info.get("spill_store_bytes", 0), info.get("spill_load_bytes", 0))
    return spill == 0 or (kernel in REGISTER_EXCEPTIONS and spill <= REGISTER_EXCEPTIONS[kernel][0])


def launch_bounds() -> tuple[int, int]:
    """(CK_BLOCK_SIZE, CK_MIN_BLOCKS_PER_SM) of kernels/common.cuh: the block size every kernel is built for
    (the cuda backend must launch with it) and the blocks per SM its register cap guarantees."""
    text = (kernel_dir() / "common.cuh").read_text()
    block, blocks = _BLOCK.search(text), _MIN_BLOCKS.search(text)
    if block is None or blocks is None:
        raise RuntimeError("kernels/common.cuh defines no CK_BLOCK_SIZE / CK_MIN_BLOCKS_PER_SM")
    return int(block.group(1)), int(blocks.group(1))


def kernel_sources() -> list[Path]:
    """Every ``*.cu`` file in the kernel directory, sorted."""
    return sorted(kernel_dir().glob("*.cu"))


def build_variants(source: Path) -> list[dict[str, str]]:
    """The define combinations a source declares with ``// variants: A=0,1 B=0,1`` lines ([{}] if none).

    Each line is the product of its axes; several lines add their products (e.g. a second line for the
    superset of every optional effect), duplicates dropped."""
    out: list[dict[str, str]] = []
    for line in _VARIANTS.findall(source.read_text()):
        axes: list[tuple[str, list[str]]] = []
        for item in line.split():
            name, _, values = item.partition("=")
            if not name.isidentifier() or not values:
                raise ValueError(f"{source.name}: cannot read variant {item!r} (expected NAME=v1,v2)")
            axes.append((name, values.split(",")))
        names = [a[0] for a in axes]
        for combo in itertools.product(*(a[1] for a in axes)):
            variant = dict(zip(names, combo, strict=True))
            if variant not in out:
                out.append(variant)
    return out or [{}]


def nvcc_path() -> str | None:
    """nvcc on the PATH, or None."""
    return shutil.which("nvcc")


def nvcc_build(
    source: Path, archs: str | list[str], defines: dict | None = None
) -> dict[str, dict[str, dict[str, int]]]:
    """Build ``source`` for each of ``archs`` (e.g. ``["sm_80", "sm_90"]``) in one nvcc call and return
    ptxas' report ``{arch: {kernel: {"registers", "stack_bytes", "spill_store_bytes", "spill_load_bytes"}}}``.

    Raises RuntimeError with the command and nvcc's output if the build fails.
    """
    nvcc = nvcc_path()
    if nvcc is None:
        raise RuntimeError("nvcc is not on the PATH")
    archs = [archs] if isinstance(archs, str) else list(archs)
    gencode = [f"-gencode=arch=compute_{a[3:]},code={a}" for a in archs]
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [
            nvcc,
            "-std=c++17",
            "-c",
            *gencode,
            "-Xptxas",
            "-v",
            f"-I{source.parent}",
            *define_flags(defines),
            str(source),
            "-o",
            str(Path(tmp) / "out.o"),
        ]
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"nvcc failed on {source.name} ({archs}, {defines}):\n{' '.join(cmd)}\n{proc.stderr}")
    report: dict[str, dict[str, dict[str, int]]] = {a: {} for a in archs}
    current = None
    for line in proc.stderr.splitlines():
        if m := _FUNC.search(line):
            current = report.setdefault(m.group(2), {}).setdefault(m.group(1), {})
        elif current is not None and (m := _SPILL.search(line)):
            current.update(
                stack_bytes=int(m.group(1)), spill_store_bytes=int(m.group(2)), spill_load_bytes=int(m.group(3))
            )
        elif current is not None and (m := _REGS.search(line)):
            current["registers"] = int(m.group(1))
    return report
