"""Compulsory memory traffic of the bulk kernels, and what it implies: bytes moved per work item (interior
cell or particle), GPU occupancy from a register count, and bandwidth-bound throughput.

One place for these numbers: ``benchmarks/fluid_throughput.py`` (cpu rooflines) and
``benchmarks/kernel_build_report.py`` (GPU projections) both read them.

Counting rule: every array a kernel reads or writes is touched once per work item (float32 = 4 B, a cell
flag or mask 1 B, stencil neighbours hit in cache); for the MPM particle kernels only the particle arrays
count, the grid they gather from / scatter to is counted once per cell by ``mpm_grid_update`` and
``mpm_clear_grid`` (at 8 particles per cell its per-particle share is small).  Kernels on link or ghost lists
(halo copies, wall bounce-back, folds) and the test / micro-benchmark kernels have no entry.
"""

from __future__ import annotations

from dataclasses import dataclass

F4 = 4  # bytes of a float32
FLAG = 1  # bytes of a cell flag or mask


@dataclass(frozen=True)
class Traffic:
    """Bytes one work item of a kernel moves, and what a work item is ("cell" or "particle")."""

    bytes: int
    item: str
    what: str


# per interior cell and step (the fluid kernels), per particle and step (the MPM particle kernels)
KERNEL_TRAFFIC: dict[str, Traffic] = {
    "lbm_collide_stream": Traffic(27 * F4 * 2 + FLAG + 3 * F4 + F4, "cell", "f read+write, flags, u write, p-bar"),
    # mu_phi of Eq. 22 computed from phi's stencil (lbm_gradient's LAP), not read from a field
    "lbm_collide_stream (two-phase)": Traffic(
        27 * F4 * 2 + FLAG + 3 * F4 + 2 * F4, "cell", "f read+write, flags, u write, p-bar, phi"
    ),
    "lbm_macro_pressure": Traffic(27 * F4 + FLAG + 2 * F4 + F4, "cell", "f read, flags, p read+write, phi"),
    "lbm_pressure_filter": Traffic(F4 + F4 + FLAG, "cell", "p read, p-bar write, flags"),
    # coupled steps: Σ f c for the exchange, and Σ (f − w) kept for the pressure update (FluidSolver.current_velocity)
    "lbm_momentum": Traffic(27 * F4 + FLAG + 3 * F4 + F4, "cell", "f read, flags, momentum write, Σ(f − w) write"),
    # the coupled step's pressure update: Σ (f − w) from lbm_momentum's pass instead of the 27 populations
    "lbm_macro_pressure (kept Σ)": Traffic(F4 + FLAG + 2 * F4 + F4, "cell", "Σ(f − w) read, flags, p read+write, phi"),
    "phase_macroscopic": Traffic(7 * F4 + F4 + FLAG, "cell", "h read, phi write, flags"),
    # a diagnostic now (FluidSolver.phase_gradients), not a stage of the step
    "phase_gradients": Traffic(F4 + 3 * F4 + F4 + FLAG, "cell", "phi read, grad write, mu write, flags"),
    # grad phi computed from phi's stencil (pf_gradient_sums), not read from a field
    "phase_collide_stream": Traffic(
        7 * F4 * 2 + F4 + 3 * F4 + F4 + FLAG, "cell", "h read+write, phi, u, source, flags"
    ),
    "mpm_p2g": Traffic(3 * F4 + 3 * F4 + 9 * F4 + 6 * F4 + F4 + F4, "particle", "x, v, C, tau, mass, volume"),
    "mpm_g2p": Traffic(
        (3 + 3 + 9 + 9 + 9 + 6 + 1 + 1 + 1 + 1 + 1 + 1) * F4 + 3 * F4,
        "particle",
        "x read+write, v write, C write, F read+write, tau write, q read+write, vc read+write, saturation",
    ),
    "mpm_grid_update": Traffic(F4 + 3 * F4 + 3 * F4, "cell", "m, mv read, v written over mv"),
    # x read (+ written where a particle is inside); the 8 SDF nodes around it mostly from cache
    "mpm_sdf_project": Traffic(3 * F4 + 3 * F4, "particle", "x read+write"),
    "mpm_clear_grid": Traffic(F4 + 3 * F4 + F4, "cell", "m, mv, volume written"),
}

# the stages of one two-phase flow step (what benchmarks/fluid_throughput.py measures), by kernel
TWO_PHASE_STEP = (
    "lbm_macro_pressure",
    "lbm_pressure_filter",
    "lbm_collide_stream (two-phase)",
    "phase_macroscopic",
    "phase_collide_stream",
)


@dataclass(frozen=True)
class GPU:
    """A GPU for the projections: name, memory (GB) and peak memory bandwidth (TB/s, the vendor's figure)."""

    name: str
    memory_gb: float
    bandwidth_tbs: float


GPUS = (
    GPU("RTX PRO 6000 Blackwell (the paper's)", 96.0, 1.792),  # GDDR7, 512-bit, 28 Gbps
    GPU("H100 SXM", 80.0, 3.35),
    GPU("H200", 141.0, 4.8),
)
"""The GPUs the build report and ``couplekit bench`` project onto."""

# peak DRAM bandwidths (bytes/s) the build report projects onto
GPU_BANDWIDTH = {f"{g.name} ({g.bandwidth_tbs:g} TB/s)": g.bandwidth_tbs * 1e12 for g in GPUS}
# fraction of peak a well-written streaming kernel sustains (STREAM-like copies reach 85-92 % on H100; FluidX3D's
# benchmark table shows bandwidth-bound LBM kernels at 70-90 % of the roofline on A100 / H100-class cards)
BANDWIDTH_EFFICIENCY = 0.8
# particle kernels (P2G's atomic scatter, G2P's per-particle SVD): an assumption, MPM GPU codes report 30-50 %
PARTICLE_BANDWIDTH_EFFICIENCY = 0.4


# populations (f or h values) each kernel above moves per item: with fp16 storage (CK_STORAGE_FP16=1) each is
# 2 B instead of F4
POPULATION_VALUES = {
    "lbm_collide_stream": 27 * 2,
    "lbm_collide_stream (two-phase)": 27 * 2,
    "lbm_macro_pressure": 27,
    "lbm_momentum": 27,
    "phase_macroscopic": 7,
    "phase_collide_stream": 7 * 2,
}


def bytes_per_item(kernel: str, storage: str = "fp32") -> int | None:
    """Compulsory bytes per work item of ``kernel`` (KERNEL_TRAFFIC), or None for a kernel without an entry;
    ``storage="fp16"``: its populations in 2 B (POPULATION_VALUES)."""
    entry = KERNEL_TRAFFIC.get(kernel)
    if entry is None:
        return None
    return entry.bytes - (F4 - 2) * POPULATION_VALUES.get(kernel, 0) * (storage == "fp16")


def two_phase_step_bytes(storage: str = "fp32") -> dict[str, int]:
    """Bytes per interior cell of each kernel of one two-phase step (``storage`` of the populations)."""
    return {k: bytes_per_item(k, storage) for k in TWO_PHASE_STEP}


def projected_items_per_s(nbytes: int, bandwidth: float, efficiency: float = BANDWIDTH_EFFICIENCY) -> float:
    """Work items per second of a bandwidth-bound kernel moving ``nbytes`` per item at ``efficiency`` of
    ``bandwidth`` (bytes/s)."""
    if nbytes <= 0:
        raise ValueError(f"bytes per item must be positive, got {nbytes}")
    return bandwidth * efficiency / nbytes


# sm_80 / sm_90 limits per SM (CUDA occupancy calculator)
SM_REGISTERS = 65536
SM_MAX_THREADS = 2048
SM_MAX_BLOCKS = 32
WARP = 32
REG_ALLOC_UNIT = 256  # registers are allocated per warp in units of 256
MAX_REGS_PER_THREAD = 255


def occupancy(registers: int, block_size: int, shared_bytes: int = 0) -> dict[str, float | int]:
    """Theoretical occupancy on one sm_80 / sm_90 SM of a kernel using ``registers`` per thread, launched with
    ``block_size`` threads per block (no shared memory: couplekit's kernels use none).

    Returns ``{"blocks_per_sm", "warps_per_sm", "occupancy"}`` (occupancy = resident warps / 64) and the
    limiting resource (``"limit"``: "registers", "threads" or "blocks")."""
    if shared_bytes:
        raise ValueError("shared memory is not modelled: couplekit's kernels use none")
    if not 1 <= registers <= MAX_REGS_PER_THREAD:
        raise ValueError(f"registers per thread must be in 1..{MAX_REGS_PER_THREAD}, got {registers}")
    if block_size <= 0 or block_size % WARP:
        raise ValueError(f"block size must be a positive multiple of {WARP}, got {block_size}")
    warps_per_block = block_size // WARP
    regs_per_warp = -(-registers * WARP // REG_ALLOC_UNIT) * REG_ALLOC_UNIT
    by_regs = (SM_REGISTERS // regs_per_warp) // warps_per_block
    by_threads = SM_MAX_THREADS // block_size
    blocks = min(by_regs, by_threads, SM_MAX_BLOCKS)
    limit = "registers" if blocks == by_regs else ("threads" if blocks == by_threads else "blocks")
    warps = blocks * warps_per_block
    return {
        "blocks_per_sm": blocks,
        "warps_per_sm": warps,
        "occupancy": warps / (SM_MAX_THREADS // WARP),
        "limit": limit,
    }
