"""Bytes each stage moves per cell or particle, and the bandwidth-bound projection of a step on a GPU.

The byte counts are compulsory traffic (each array a kernel touches read or written once, float32 = 4 B,
flags 1 B): the fluid kernels' counts are :data:`couplekit.backend.traffic.KERNEL_TRAFFIC`, the table the GPU
build report and ``benchmarks/fluid_throughput.py`` use too, mapped here onto the scheduler's stages; the sand and coupling counts follow the arrays the kernels read and write
(``kernels/mpm_*.cu``, ``kernels/coupling*.cu``; the 27-node gathers and scatters of a particle are assumed to
hit cache, so the grid is counted once per node).

Projection: ``time = bytes / (peak bandwidth × efficiency) + launches × launch overhead``.

Efficiency assumptions (not measured here: no GPU was at hand; re-derive them from ``scripts/gpu_check.sh``'s
throughput results once it has run on a GPU):

* grid kernels (LBM, phase field, coupling fields, MPM grid update): 0.80 of peak, the fraction that
  bandwidth-bound LBM kernels reach on recent NVIDIA GPUs in FluidX3D's published benchmark table
  (github.com/ProjectPhysX/FluidX3D, README "Single-GPU/CPU Benchmarks": measured MLUPs against the
  bandwidth roofline, 70-90 % on A100 / H100-class cards);
* particle kernels (P2G with atomic scatter, G2P with its SVD): 0.40 of peak, our assumption: atomics and
  the per-particle SVD keep MPM kernels well below the roofline (MPM GPU codes report 30-50 % of peak).

Launch overhead: 5 µs per kernel launch (CUDA launch latency on a busy stream), ~25 launches a coupled step.
"""

from __future__ import annotations

from ..backend.traffic import (
    BANDWIDTH_EFFICIENCY,
    GPU,
    GPUS,
    KERNEL_TRAFFIC,
    PARTICLE_BANDWIDTH_EFFICIENCY,
    two_phase_step_bytes,
)

F32 = 4

# ---------------------------------------------------------------------------------------------- fluid, per cell
# compulsory traffic per interior cell and step of each fluid kernel: couplekit.backend.traffic.KERNEL_TRAFFIC
BYTES_TWO_PHASE_STEP = two_phase_step_bytes()

# the scheduler's stages (couplekit.schedulers.base) -> bytes per fluid cell and step
FLUID_STAGE_BYTES_PER_CELL = {
    "lbm_pressure": BYTES_TWO_PHASE_STEP["lbm_macro_pressure"],
    "lbm_pressure_filter": BYTES_TWO_PHASE_STEP["lbm_pressure_filter"],
    "lbm_collide_stream": BYTES_TWO_PHASE_STEP["lbm_collide_stream (two-phase)"],
    "phase_field_macroscopic": BYTES_TWO_PHASE_STEP["phase_macroscopic"],
    "phase_field_collide_stream": BYTES_TWO_PHASE_STEP["phase_collide_stream"],
    "volume_controller": 2 * F32 + 1,  # phi and source read, flags (a reduction)
}
# mixture inputs read by the collide kernel when coupled: ε, force (it reads no sand velocity)
MIXTURE_BYTES_PER_CELL = (1 + 3) * F32
# the coupled (lockstep) step's pressure update: Σ (f − w) kept by the exchange velocity's pass (fluid_velocity)
# instead of f, with Eq. 39's sand terms already folded into it by the sand_velocity stage (no mixture inputs)
COUPLED_PRESSURE_BYTES_PER_CELL = KERNEL_TRAFFIC["lbm_macro_pressure (kept Σ)"].bytes

# ---------------------------------------------------------------------------------------------- coupling
COUPLING_STAGE_BYTES_PER_CELL = {
    "volume_fractions": 2 * F32,  # node volume read, ε̃ write (the sand and water fractions are not stored)
    # f read, Σ f c and Σ (f − w) written; before it the slip term's fluid part (kernels/coupling_pressure.cu
    # coupling_pressure_slip_fluid): u, ε, φ read and the part written into the sum, which the momentum reads back
    "fluid_velocity": KERNEL_TRAFFIC["lbm_momentum"].bytes + (3 + 1 + 1 + 1 + 1) * F32 + 2,
    "drag_buoyancy": 3 * F32 + 3 * F32 + F32 + F32,  # force write, sand velocity read, ε, p
    "retention_source": 4 * F32 + F32,  # ε, ε_prev, φ, source write, d_bound
    # the rest of Eq. 39's sand terms into the kept sum: grid velocity, ε, φ read, the sum read and written, the
    # slip-cell and flag bytes (kernels/coupling_pressure.cu; the fluid velocity's part: fluid_velocity's)
    "sand_velocity": (3 + 1 + 1 + 2) * F32 + 2,
    "coupling_finish": 2 * F32,  # ε_prev ← ε
    "moisture": 2 * F32,  # ε̃ and φ, from which the gather computes the water fraction of Eq. 59
}
COUPLING_STAGE_BYTES_PER_PARTICLE = {
    "volume_fractions": 3 * F32 + F32,  # x, volume (scatter into ε)
    "drag_buoyancy": 3 * F32 + 3 * F32 + F32,  # x, v read, volume (gather u, scatter force)
    "moisture": 3 * F32 + 2 * F32,  # x read, saturation read+write (+ ε̃ and φ per node: the water fraction)
    "sand_velocity": 3 * F32 * 2 + F32,  # x, v, mass
}

# ---------------------------------------------------------------------------------------------- sand
# per particle: x v C F (3+3+9+9), tau 6, q, vc, saturation, mass, volume
SAND_STAGE_BYTES_PER_PARTICLE = {
    "mpm_p2g": (3 + 3 + 9 + 6 + 1 + 1) * F32,  # x, v, C, tau, mass, volume read
    "mpm_g2p": (3 + 3 + 9 + 9 + 1 + 1 + 1) * F32 + (3 + 3 + 9 + 9 + 6 + 1 + 1) * F32,  # read, write
}
SAND_STAGE_BYTES_PER_NODE = {
    # clear and accumulate mass and momentum; the volume only with sand of several densities (+8 B; one density:
    # the node volume is the mass over it, SandSolver.node_volume)
    "mpm_p2g": (1 + 3) * F32 * 2,
    "mpm_grid_update": (1 + 3 + 3 + 1) * F32,  # mass, momentum read, velocity written over it, sdf
    "mpm_g2p": 3 * F32,  # velocity read
}

GRID_EFFICIENCY = BANDWIDTH_EFFICIENCY
PARTICLE_EFFICIENCY = PARTICLE_BANDWIDTH_EFFICIENCY
LAUNCH_OVERHEAD_S = 5e-6
LAUNCHES_PER_STEP = 25

__all__ = ["GPU", "GPUS", "stage_bytes", "projected_step", "assumptions"]


def stage_bytes(cells: float, particles: float, two_phase: bool = True, coupled: bool = True) -> dict[str, dict]:
    """Bytes each stage moves in one step: ``{stage: {"grid": bytes, "particles": bytes}}``."""
    out: dict[str, dict] = {}

    def add(stage: str, grid: float = 0.0, part: float = 0.0) -> None:
        e = out.setdefault(stage, {"grid": 0.0, "particles": 0.0})
        e["grid"] += grid
        e["particles"] += part

    if cells:
        for s, b in FLUID_STAGE_BYTES_PER_CELL.items():
            if coupled and s == "lbm_pressure":
                b = COUPLED_PRESSURE_BYTES_PER_CELL
            if two_phase or not s.startswith(("phase", "volume")):
                add(s, b * cells)
        if coupled:
            add("lbm_collide_stream", MIXTURE_BYTES_PER_CELL * cells)
    if particles:
        for s, b in SAND_STAGE_BYTES_PER_NODE.items():
            add(s, b * cells)
        for s, b in SAND_STAGE_BYTES_PER_PARTICLE.items():
            add(s, 0.0, b * particles)
    if coupled and cells and particles:
        for s, b in COUPLING_STAGE_BYTES_PER_CELL.items():
            add(s, b * cells)
        for s, b in COUPLING_STAGE_BYTES_PER_PARTICLE.items():
            add(s, 0.0, b * particles)
    return out


def projected_step(gpu: GPU, cells: float, particles: float, two_phase: bool = True, coupled: bool = True) -> dict:
    """Projected seconds per step on ``gpu``: per stage and in total (module docstring: the model)."""
    bw = gpu.bandwidth_tbs * 1e12
    per_stage = {
        s: b["grid"] / (bw * GRID_EFFICIENCY) + b["particles"] / (bw * PARTICLE_EFFICIENCY)
        for s, b in stage_bytes(cells, particles, two_phase, coupled).items()
    }
    total = sum(per_stage.values()) + LAUNCHES_PER_STEP * LAUNCH_OVERHEAD_S
    return {"stages_s": per_stage, "launch_overhead_s": LAUNCHES_PER_STEP * LAUNCH_OVERHEAD_S, "step_s": total}


def assumptions() -> dict:
    """The projection's assumptions, for the JSON results."""
    return {
        "grid_efficiency": GRID_EFFICIENCY,
        "particle_efficiency": PARTICLE_EFFICIENCY,
        "launch_overhead_s": LAUNCH_OVERHEAD_S,
        "launches_per_step": LAUNCHES_PER_STEP,
        "gpus": [g.__dict__ for g in GPUS],
        "source": "couplekit/bench/traffic.py and couplekit/backend/traffic.py docstrings",
    }
