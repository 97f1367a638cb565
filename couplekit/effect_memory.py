"""What each effect costs in memory, FluidX3D's convention ("this costs N bytes per cell"): the arrays each
effect allocates, per padded fluid cell ((nx+2)(ny+2)(nz+2)), per sand-grid cell (nx·ny·nz) and per particle.

These are the arrays the solvers allocate for an effect (couplekit.fluid.solver, couplekit.coupling.coupler,
couplekit.scene.forces); tests/test_bench.py checks each against the bytes a scene with the effect on
allocates more than the same scene with it off.  An effect with 0 bytes either needs no field (volume
controller: a reduction; the closures: local rates; surface tension: the flow's collide computes μ_φ from φ;
drag, buoyancy: the force field belongs to the coupling)
or would keep its field when it is off because a kernel reads it in every variant, recorded in
:data:`KEPT_WHEN_OFF` (none now).  The source term S_φ costs 4 B per cell: without it (fluid-only scenes,
the Fig. 14 ablation) the phase-field kernels take the ``CK_PF_SOURCE=0`` variant and the field is not
allocated.  Hardening (q) and cohesion
(the saturation) cost 4 B per particle each; without them G2P takes the variant that never touches the field
and the sand solver does not allocate it, except the saturation of a coupled scene, which is the coupling's
moisture (Eq. 59) cohesion or not (and of particles seeded with a saturation, which carry it as data).
``fp16_storage`` (``fluid.storage = 'fp16'``) is a saving, reported as negative bytes: the populations f and,
two-phase, h take 2 B per value instead of 4 (54 + 14 B per padded cell)."""

from __future__ import annotations

F32 = 4

# effect -> (bytes per padded fluid cell, bytes per sand-grid cell, bytes per particle)
EFFECT_BYTES = {
    # h, phi (grad phi is computed inside the phase-field collide, kernels/phasefield.cu pf_gradient_sums)
    "phase_field": (F32 * (7 + 1), 0, 0),
    "surface_tension": (0, 0, 0),  # mu_phi: computed inside the flow collide from phi (lbm_laplacian_sum)
    "volume_controller": (0, 0, 0),
    # S_phi (coupled two-phase scenes; compiled out otherwise, CK_PF_SOURCE=0) lives in the buffer of last step's
    # porosity, which the coupling counts (SandFluidCoupler.share_source_buffer)
    "source_term": (0, 0, 0),
    # ε, ε_prev, slip (the sand and water fractions are recomputed where they are read: SandFluidCoupler); other
    # schedulers than lockstep add the stored sand velocity and a force buffer of its own (UNFOLDED_BYTES);
    # lockstep folds Eq. 39's sand terms into the pressure update and keeps the force (and the exchange's Σ f c) in
    # the fluid velocity's buffer (SandFluidCoupler.fold_sand_velocity)
    "coupling": (F32 * (1 + 1) + 1, 0, 0),
    "drag_buoyancy": (0, 0, 0),
    "retention": (0, F32 * 3, F32 * 1),  # bound_in, bound, d_bound; moisture ratio per particle
    "odd_rate_floor": (0, 0, 0),
    "odd_rate_ramp": (F32 * 1, 0, 0),  # the weight of rate 1 per cell (fluid.odd_ramp, where the floor acts)
    "smagorinsky": (0, 0, 0),
    "cohesion": (0, 0, F32 * 1),  # saturation (sand-only scenes; coupled: the coupling's moisture, kept)
    "hardening": (0, 0, F32 * 1),  # q
    # the summed force buffer (+ the force input in a fluid-only scene) per padded cell; on the host the
    # swirl's acceleration (3 float64), radius (float64) and inside mask (bool) per cell, which the torque
    # diagnostic reads; + ρ_w a (3 float32) in the stirred cells' bounding box (:func:`_stirred_box_cells`)
    "stirring": (F32 * 3, 3 * 8 + 8 + 1, 0),
    "sand_emission": (0, 0, 0),  # the particles it emits (memory_estimate's emitted_particles)
    # fluid.storage = 'fp16': f (27) and, two-phase, h (7) in 2 B instead of 4 -- a saving, so negative
    # (the h part is added in effect_memory when the scene has a phase field)
    "fp16_storage": (-(F32 - 2) * 27, 0, 0),
}

UNFOLDED_BYTES = F32 * (3 + 3)
"""Bytes per padded cell of the fluid's stored sand velocity and its force buffer of its own, which a coupled scene
keeps unless its scheduler is lockstep (SandFluidCoupler.fold_sand_velocity); counted with the coupling."""

FP16_SAVING_H = (F32 - 2) * 7
"""Bytes per padded cell fp16 storage saves on h (two-phase scenes), besides f's 54."""

KEPT_WHEN_OFF: dict[str, str] = {}
# kept only in some scenes: the effect's field is another effect's input there
KEPT_WHEN_OFF_COUPLED = {
    "cohesion": "sand.saturation (4 B/particle): in a coupled scene it is the coupling's moisture (Eq. 59)",
}


def _stirred_box_cells(scene) -> int:
    """Cells in the bounding box of the stirred cylinder (exact for an axis along x, y or z; the whole
    domain, an upper bound, otherwise)."""
    st, dom = scene.stirring, scene.domain
    res = dom.resolution
    axis = [abs(a) for a in st.axis]
    if sorted(axis) != [0.0, 0.0, max(axis)]:
        return int(res[0] * res[1] * res[2])
    along = axis.index(max(axis))
    count = 1
    for d in range(3):
        centres = [(i + 0.5) * dom.dx - st.center[d] for i in range(res[d])]
        if d == along:
            n = res[d] if st.length is None else sum(abs(c) <= 0.5 * st.length for c in centres)
        else:
            n = sum(abs(c) < st.radius for c in centres)
        count *= n
    return int(count)


def effect_memory(scene) -> dict[str, dict[str, float]]:
    """Per effect that applies to ``scene``: whether it is on, and the bytes per cell / per particle it costs
    and in total over the scene's cells (``bytes_total``, the per-particle bytes not included: they grow with
    the particles a run holds; 0 for an effect that is off)."""
    nx, ny, nz = scene.domain.resolution
    padded, cells = (nx + 2) * (ny + 2) * (nz + 2), nx * ny * nz
    fl, eff = scene.fluid, scene.effects
    two = bool(fl is not None and fl.phases == 2)
    coupled = scene.has_fluid and scene.has_sand
    from .assembly import odd_ramp_applies, sand_retention_flags
    from .schedulers import folds_sand_velocity

    retention = coupled and True in sand_retention_flags(scene)
    on = {
        "phase_field": two,
        "surface_tension": two and eff.surface_tension and bool(fl.surface_tension),
        "volume_controller": two and eff.volume_controller and fl.controller_eta > 0,
        "source_term": coupled and two and eff.source_term,
        "coupling": coupled,
        "drag_buoyancy": coupled and (eff.drag or eff.buoyancy),
        "retention": retention,
        "odd_rate_floor": fl is not None and fl.odd_lambda > 0,
        "odd_rate_ramp": fl is not None and odd_ramp_applies(scene),
        "smagorinsky": fl is not None and fl.smagorinsky > 0,
        "cohesion": scene.has_sand and eff.cohesion and scene.sand.cohesion > 0,
        "hardening": scene.has_sand and eff.hardening,
        "stirring": fl is not None and scene.stirring is not None,
        "sand_emission": scene.emits_sand,
        "fp16_storage": fl is not None and getattr(fl, "storage", "fp32") == "fp16",
    }
    applies = {k: (scene.has_sand if k in ("cohesion", "hardening") else fl is not None) for k in on}
    applies["coupling"] = applies["drag_buoyancy"] = applies["retention"] = applies["source_term"] = coupled
    applies["sand_emission"] = scene.emits_sand
    out = {}
    for name, (per_cell, per_node, per_particle) in EFFECT_BYTES.items():
        if not applies[name]:
            continue
        kept = KEPT_WHEN_OFF.get(name, "")
        if coupled and name in KEPT_WHEN_OFF_COUPLED:
            kept, per_particle = KEPT_WHEN_OFF_COUPLED[name], 0
        elif name == "cohesion" and any(b.saturation for b in scene.bodies if b.kind == "sand"):
            kept, per_particle = "sand.saturation (4 B/particle): the bodies' seeded saturation", 0
        extra = 0.0
        if name == "fp16_storage" and two:
            per_cell -= FP16_SAVING_H
        if name == "coupling" and not folds_sand_velocity(scene.scheduler.kind):
            per_cell += UNFOLDED_BYTES
        if name == "stirring":
            if not scene.has_sand:
                per_cell += F32 * 3  # the force input a coupled scene has anyway
            extra = F32 * 3 * _stirred_box_cells(scene) if on[name] else 0.0
        per_cell_total = (per_cell * padded + extra) / cells + per_node  # per simulation cell
        out[name] = {
            "on": bool(on[name]),
            "bytes_per_cell": float(per_cell_total),
            "bytes_per_particle": float(per_particle),
            "bytes_total": float(per_cell * padded + per_node * cells + extra) if on[name] else 0.0,
            "kept_when_off": kept,
        }
    return out


def describe_effect_memory(scene, particles: float = 0.0) -> list[str]:
    """Lines for ``couplekit validate``: each effect, on/off, and what it costs."""
    lines = []
    for name, e in effect_memory(scene).items():
        parts = [f"{e['bytes_per_cell']:.3g} bytes per cell"] if e["bytes_per_cell"] else []
        if e["bytes_per_particle"]:
            parts.append(f"{e['bytes_per_particle']:.3g} bytes per particle")
        cost = " + ".join(parts)
        total = e["bytes_total"] + (e["bytes_per_particle"] * particles if e["on"] else 0.0)
        state = "on " if e["on"] else "off"
        if e["bytes_per_cell"] < 0:  # a saving (fp16 storage of the populations)
            saved = f"{-e['bytes_per_cell']:.3g} bytes per cell"
            line = f"  {name:18s} {state}  this saves {saved}" + (
                f" ({-total / 2**20:.3g} MiB here)" if e["on"] else " (fluid.storage = 'fp16')"
            )
        elif e["bytes_per_cell"] or e["bytes_per_particle"]:
            line = f"  {name:18s} {state}  this costs {cost}" + (f" ({total / 2**20:.3g} MiB here)" if e["on"] else "")
        else:
            line = f"  {name:18s} {state}  no fields of its own"
        if e["kept_when_off"]:
            line += f"; off keeps {e['kept_when_off'].split(':')[0]}"
        lines.append(line)
    return lines
