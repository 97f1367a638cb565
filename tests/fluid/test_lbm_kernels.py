"""Every flow kernel against its NumPy reference (couplekit.fluid.reference) on random but valid states.

Tolerances: the kernels compute in float32, the reference in float64 from the same float32 inputs. A
population (≤ 0.3) passes through ~30 multiply-adds (moments, forces, chimera back-transform), so the
float32 round-off bound is ~30 · 2⁻²⁴ · 0.3 ≈ 5e-7; we allow 2e-6 absolute (4× margin), far below any
modelling error we could introduce (a wrong sign or weight shows up at ≥ 1e-4 with these states).
Pure copies (halo, fold, outflow) must be bitwise equal.

Slots of wall / inflow / solid cells hold no state: the kernels use them as scratch for the bounce-back links
(lbm_wall_prefill / lbm_wall_bounce), so f is compared on fluid cells and fluid / outflow ghosts only.
"""

from __future__ import annotations

import numpy as np
import pytest
from fluid_states import BOUNDARY_SETS, chem_of, random_state

from couplekit.fluid import KernelOps, ReferenceOps, from_stored, to_stored
from couplekit.fluid.grid import Boundaries, Face

EFFECTS = {
    "single": {},
    "two_phase_st": {"two_phase": True, "surface_tension": True},
    "all": {"two_phase": True, "surface_tension": True, "mixture": True, "external_force": True},
}
PARAMS = (1.0, 0.00125, 0.01, 0.05)  # rho_h, rho_l, nu_h, nu_l
GRAVITY = (1e-5, -2e-5, 3e-5)
ATOL = 2e-6


@pytest.fixture(scope="module")
def cpu(kernel_backend):
    """cpu and cpu-device in turn: the host and the CUDA code paths of the flow kernels."""
    return kernel_backend


def _pair(seed, boundaries):
    a = random_state(seed, boundaries)
    return a, {k: v.copy() for k, v in a.items()}


def _collide_both(ko, ro, sk, sr, parity, extra=()):
    """One collide-stream of ``sk`` on the kernels and of ``sr`` on the reference; f (fluid cells and fluid /
    outflow ghosts) and the velocity agree to ATOL."""
    for ops, s in ((ko, sk), (ro, sr)):
        ops.collide_stream(
            s["f"], s["flags"], s["velocity"], s["phi"], s["eps"], s["force"], s["pbar"], parity,
            *PARAMS, *GRAVITY, *extra, chemical_potential=chem_of(ops, s),
        )  # fmt: skip
    state = (sk["flags"] == 0) | (sk["flags"] == 3)
    np.testing.assert_allclose(sk["f"][:, state], sr["f"][:, state], rtol=0, atol=ATOL)
    np.testing.assert_allclose(sk["velocity"], sr["velocity"], rtol=0, atol=ATOL)
    return state


@pytest.mark.parametrize("effects", list(EFFECTS))
@pytest.mark.parametrize("boundaries", list(BOUNDARY_SETS))
@pytest.mark.parametrize("parity", [0, 1])
def test_collide_stream_matches_reference(cpu, effects, boundaries, parity):
    ko, ro = KernelOps(cpu, **EFFECTS[effects]), ReferenceOps(**EFFECTS[effects])
    sk, sr = _pair(11 + parity, BOUNDARY_SETS[boundaries])
    _collide_both(ko, ro, sk, sr, parity)
    # the state really changed (the test cannot pass by doing nothing)
    assert np.abs(sk["f"] - random_state(11 + parity, BOUNDARY_SETS[boundaries])["f"]).max() > 1e-3


@pytest.mark.parametrize("effects", ["single", "all"])
@pytest.mark.parametrize("parity", [0, 1])
def test_wall_links_carry_the_face_velocity_where_they_cross(cpu, effects, parity):
    """Bounce-back links from a face ghost carry the mean of that ghost's velocity and the receiving cell's own
    ghost's across the face (kernels/lbm_halo.cu lbm_link_wall_cu, reference.link_wall_velocity): with a
    random velocity on every wall and inflow ghost (an outlet's face is not uniform) kernel and reference agree,
    and the mean differs from the sending ghost's velocity on the diagonal links (so the state tests it)."""
    from couplekit.fluid.reference import link_wall_velocity, shifted

    ko, ro = KernelOps(cpu, **EFFECTS[effects]), ReferenceOps(**EFFECTS[effects])
    sk, sr = _pair(21 + parity, BOUNDARY_SETS["mixed"])
    ghost_u = np.random.default_rng(9).uniform(-0.04, 0.04, sk["velocity"].shape).astype(np.float32)
    walls = (sk["flags"] == 1) | (sk["flags"] == 2)
    for s in (sk, sr):
        s["velocity"] = np.where(walls[None], ghost_u, s["velocity"])
    before = sk["f"].copy()
    _collide_both(ko, ro, sk, sr, parity)
    assert np.abs(sk["f"] - before).max() > 1e-3
    diagonal = (1, 0, 1)  # a link from the z- face's ghosts, x-shifted: w and c's own ghost differ
    mean, own = link_wall_velocity(sk["velocity"], diagonal), shifted(sk["velocity"], (-1, 0, -1))
    assert np.abs(mean - own)[:, 0, :, 1:].max() > 1e-3  # first layer, away from the x- edge ghosts
    straight = (0, 0, 1)
    np.testing.assert_array_equal(link_wall_velocity(sk["velocity"], straight), shifted(sk["velocity"], (0, 0, -1)))


def test_wall_link_mates_follow_the_face_rule():
    """grid.wall_link_mates, the second velocity cell of each wall link that the list kernels read: c's own ghost
    across the face for a link from a ghost of one face, the sending cell itself for straight links, edge and
    corner ghosts and interior solids (checked link by link against the rule written out in (x, y, z))."""
    from couplekit.fluid.grid import wall_link_mates, wall_links
    from couplekit.lattice import C27

    flags = random_state(5, BOUNDARY_SETS["mixed"])["flags"]
    pz, py, px = flags.shape
    cell, d = wall_links(flags)
    mate = wall_link_mates(cell, d, flags.shape)
    kinds = set()
    for c, j, m in zip(cell.tolist(), d.tolist(), mate.tolist(), strict=True):
        z, y, x = c // (px * py), (c // px) % py, c % px
        cx, cy, cz = (int(v) for v in C27[j])
        w = (x - cx, y - cy, z - cz)
        ghost = [w[0] in (0, px - 1), w[1] in (0, py - 1), w[2] in (0, pz - 1)]
        if sum(ghost) == 1:
            axis = ghost.index(True)
            v = [x, y, z]
            v[axis] = w[axis]
            kinds.add("straight" if (cx, cy, cz)[axis] != 0 and sum(map(abs, (cx, cy, cz))) == 1 else "face")
        else:
            v = list(w)
            kinds.add("edge or solid")
        assert m == v[0] + px * (v[1] + py * v[2]), (c, j)
    assert kinds == {"straight", "face", "edge or solid"}


# rows long enough for the host loops' vector tail (kernels/lbm_core.cuh lbm_row_tail): spans of 16 + r cells
# (r = 5, 6, 0, 1), whose last r cells run as one more vector over cells the loop has done; rows cut by the
# state's obstacle (a span with solid cells inside) and bulk rows (periodic x)
TAIL_SHAPES = [(5, 6, 21), (4, 5, 38), (4, 5, 16), (4, 5, 17)]


@pytest.mark.parametrize("shape", TAIL_SHAPES, ids=lambda s: "x".join(map(str, s)))
@pytest.mark.parametrize("boundaries", list(BOUNDARY_SETS))
@pytest.mark.parametrize("parity", [0, 1])
def test_collide_stream_rows_with_a_vector_tail(cpu, shape, boundaries, parity):
    ko, ro = KernelOps(cpu, **EFFECTS["all"]), ReferenceOps(**EFFECTS["all"])
    sk = random_state(41 + parity, BOUNDARY_SETS[boundaries], shape=shape)
    sr = {k: v.copy() for k, v in sk.items()}
    before = sk["f"].copy()
    _collide_both(ko, ro, sk, sr, parity)
    inner = (slice(1, -1),) * 3  # every interior fluid cell ran (a cell left out would also differ from sr)
    changed = np.abs(sk["f"] - before).max(axis=0)[inner][sk["flags"][inner] == 0]
    assert (changed > 0).all(), "a fluid cell was left out of the collide"


# (smagorinsky C, odd_lambda): the subgrid viscosity alone, the odd-moment rate floor alone (with nu_h = 0.01 and
# nu_l = 0.05 in PARAMS a floor of 0.25 gives r_o = 0.11 / 0.38: far from 1, so a wrong odd moment shows), both.
CLOSURES = {"smagorinsky": (0.17, 0.0), "odd_rate": (0.0, 0.25), "both": (0.1, 0.25)}


@pytest.mark.parametrize("closure", list(CLOSURES))
@pytest.mark.parametrize("effects", ["single", "all"])
@pytest.mark.parametrize("parity", [0, 1])
def test_collide_stream_closures_match_reference(cpu, closure, effects, parity):
    les, odd = (v > 0 for v in CLOSURES[closure])
    flags = {**EFFECTS[effects], "les": les, "odd_rate": odd}
    ko, ro = KernelOps(cpu, **flags), ReferenceOps(**flags)
    boundaries = BOUNDARY_SETS["mixed"]
    sk, sr = _pair(31 + parity, boundaries)
    # 5 % non-equilibrium (the shared states carry 0.1 %), so the strain-dependent viscosity matters
    noise = 1.0 + 0.05 * np.random.default_rng(5).standard_normal(sk["f"].shape)
    for s in (sk, sr):
        s["f"] = to_stored(from_stored(s["f"]) * noise)  # noise on the full f (the arrays hold f - w)
        s["eps"][: s["eps"].shape[0] // 2] = 1.0  # sand-free cells: the odd-rate floor acts only there
    state = _collide_both(ko, ro, sk, sr, parity, CLOSURES[closure])
    # the closure changes the result (the test would catch a kernel that ignores it)
    plain = _pair(31 + parity, boundaries)[0]
    plain["f"] = to_stored(from_stored(plain["f"]) * noise)
    plain["eps"][: plain["eps"].shape[0] // 2] = 1.0
    ro.collide_stream(
        plain["f"], plain["flags"], plain["velocity"], plain["phi"], plain["eps"], plain["force"],
        plain["pbar"], parity, *PARAMS, *GRAVITY, chemical_potential=chem_of(ro, plain),
    )  # fmt: skip
    assert np.abs(plain["f"][:, state] - sr["f"][:, state]).max() > 1e-4


@pytest.mark.parametrize("ops_class", ["kernel", "reference"])
def test_closure_values_need_their_build(cpu, ops_class):
    """A closure value passed to ops built without it is refused, not silently ignored."""
    ops = KernelOps(cpu) if ops_class == "kernel" else ReferenceOps()
    s = random_state(3, BOUNDARY_SETS["periodic"])
    args = (s["f"], s["flags"], s["velocity"], None, None, None, s["pbar"], 0, *PARAMS, *GRAVITY)
    with pytest.raises(ValueError, match="les=True"):
        ops.collide_stream(*args, 0.1, 0.0)
    with pytest.raises(ValueError, match="odd_rate=True"):
        ops.collide_stream(*args, 0.0, 0.015)


@pytest.mark.parametrize("ops_class", ["kernel", "reference"])
def test_chemical_potential_is_required_exactly_with_surface_tension(cpu, ops_class):
    """The collide computes mu_phi from phi with (beta, kappa): refused without them when built with surface
    tension, and refused when given to ops built without it (it would be silently ignored)."""
    make = (lambda **k: KernelOps(cpu, **k)) if ops_class == "kernel" else (lambda **k: ReferenceOps(**k))
    s = random_state(3, BOUNDARY_SETS["periodic"])
    args = (s["f"], s["flags"], s["velocity"], s["phi"], s["eps"], s["force"], s["pbar"], 0, *PARAMS, *GRAVITY)
    with pytest.raises(ValueError, match="chemical_potential"):
        make(**EFFECTS["two_phase_st"]).collide_stream(*args)
    with pytest.raises(ValueError, match="chemical_potential"):
        make(two_phase=True).collide_stream(*args, chemical_potential=(3e-3, 6e-3))


@pytest.mark.parametrize("effects", ["single", "all"])
@pytest.mark.parametrize("boundaries", list(BOUNDARY_SETS))
@pytest.mark.parametrize("parity", [0, 1])
def test_pressure_and_filter_match_reference(cpu, effects, boundaries, parity):
    ko, ro = KernelOps(cpu, **EFFECTS[effects]), ReferenceOps(**EFFECTS[effects])
    sk, sr = _pair(21 + parity, BOUNDARY_SETS[boundaries])
    p0 = sk["p"].copy()
    for ops, s in ((ko, sk), (ro, sr)):
        ops.macro_pressure(
            s["f"],
            s["flags"],
            s["velocity"],
            s["phi"],
            s["eps"],
            s["sand_v"],
            s["slip"],
            s["p"],
            parity,
            *PARAMS[:2],
        )
        ops.pressure_filter(s["p"], s["flags"], s["pbar"])
    # p ~ 1e-3 plus cs² ρ (1 − Σf) ~ 1e-3: float32 round-off of the 27-term sum ~ 27 · 6e-8
    np.testing.assert_allclose(sk["p"], sr["p"], rtol=0, atol=5e-7)
    np.testing.assert_allclose(sk["pbar"], sr["pbar"], rtol=0, atol=5e-7)
    assert np.abs(sk["p"] - p0).max() > 1e-5


@pytest.mark.parametrize("boundaries", list(BOUNDARY_SETS))
def test_halo_fold_outflow_copies_are_exact(cpu, boundaries):
    ko, ro = KernelOps(cpu), ReferenceOps()
    sk, sr = _pair(31, BOUNDARY_SETS[boundaries])
    for ops, s in ((ko, sk), (ro, sr)):
        ops.halo_pull(s["f"], s["ghost"], s["image"], s["links"])
        ops.halo_copy(s["velocity"], s["ghost"], s["image"])
        ops.halo_copy(s["p"], s["ghost"], s["image"])
        ops.fold(s["f"], s["ghost"], s["image"], s["links"])
    for key in ("f", "velocity", "p"):  # the outflow ghosts: tests/fluid/test_outflow_backflow.py
        np.testing.assert_array_equal(sk[key], sr[key])


def test_bandwidth_probe_kernels(cpu):
    """The benchmark's bandwidth probes compute what their docstrings say (exact float32 arithmetic here)."""
    mod = cpu.module("lbm_bandwidth.cu")
    rng = np.random.default_rng(7)
    a, b = rng.random(1000, dtype=np.float32), rng.random(1000, dtype=np.float32)
    c = np.zeros_like(a)
    mod.function("lbm_bw_triad")(a.size, a, b, c, np.float32(0.5))
    np.testing.assert_array_equal(c, a + np.float32(0.5) * b)
    expect = np.float32(2.0) * a + np.float32(1.0)
    mod.function("lbm_bw_update")(a.size, a, np.float32(2.0), np.float32(1.0))
    np.testing.assert_allclose(a, expect, rtol=1e-7)


@pytest.mark.parametrize("boundaries", list(BOUNDARY_SETS))
@pytest.mark.parametrize("parity", [0, 1])
def test_momentum_matches_reference(cpu, boundaries, parity):
    """Σ f c of the current populations: 26-term float32 sums of values ≤ 0.3, tolerance 1e-6."""
    ko, ro = KernelOps(cpu), ReferenceOps()
    sk, sr = _pair(41 + parity, BOUNDARY_SETS[boundaries])
    out_k, out_r = np.zeros_like(sk["velocity"]), np.zeros_like(sk["velocity"])
    ko.momentum(sk["f"], sk["flags"], sk["velocity"], out_k, parity)
    ro.momentum(sr["f"], sr["flags"], sr["velocity"], out_r, parity)
    np.testing.assert_allclose(out_k, out_r, rtol=0, atol=1e-6)
    assert np.abs(out_r).max() > 1e-2


@pytest.mark.parametrize("effects", ["single", "all"])
@pytest.mark.parametrize("shape", ["default", "wide"])
@pytest.mark.parametrize("parity", [0, 1])
def test_kept_population_sum_matches_reference_and_rereading(cpu, effects, shape, parity):
    """momentum(fsum=...) keeps Σ_j (f_j − w_j) of the populations it reads (the reference's Σ f − 1 within
    27 · 6e-8 of float32 round-off on sums ≤ 1), and a pressure update that takes it gives bitwise the p of one
    that reads f (the host's vector rows and the 9-cell grid's short tails; cells outside the fluid keep their
    values in ``fsum``)."""
    b = {"default": BOUNDARY_SETS["mixed"], "wide": WIDE_X_WALLS}[shape]
    kw = {"shape": (6, 7, 40)} if shape == "wide" else {}
    ko, ro = KernelOps(cpu, **EFFECTS[effects]), ReferenceOps(**EFFECTS[effects])
    sk = random_state(71 + parity, b, **kw)
    sr = {k: v.copy() for k, v in sk.items()}
    fsum_k = np.full(sk["p"].shape, 7.0, np.float32)
    fsum_r = fsum_k.copy()
    out = np.zeros_like(sk["velocity"])
    ko.momentum(sk["f"], sk["flags"], sk["velocity"], out, parity, fsum=fsum_k)
    ro.momentum(sr["f"], sr["flags"], sr["velocity"], out.copy(), parity, fsum=fsum_r)
    fluid = sk["flags"] == 0
    np.testing.assert_allclose(fsum_k[fluid], fsum_r[fluid], rtol=0, atol=2e-6)
    assert np.all(fsum_k[~fluid] == 7.0) and np.abs(fsum_r[fluid]).max() > 1e-3
    args = lambda s: (s["f"], s["flags"], s["velocity"], s["phi"], s["eps"], s["sand_v"], s["slip"])  # noqa: E731
    p_read, p_kept, p_ref = sk["p"].copy(), sk["p"].copy(), sr["p"].copy()
    ko.macro_pressure(*args(sk), p_read, parity, *PARAMS[:2])
    ko.macro_pressure(*args(sk), p_kept, parity, *PARAMS[:2], fsum=fsum_k)
    ro.macro_pressure(*args(sr), p_ref, parity, *PARAMS[:2], fsum=fsum_r)
    assert p_kept.tobytes() == p_read.tobytes()
    np.testing.assert_allclose(p_kept, p_ref, rtol=0, atol=5e-7)
    assert np.abs(p_kept - sk["p"]).max() > 1e-5


@pytest.mark.parametrize("parity", [0, 1])
@pytest.mark.parametrize("shape", ["default", "wide"])
def test_kept_population_sum_subtracts_the_held_slip_part_into_the_velocity_buffer(cpu, shape, parity):
    """momentum(fsum=..., held=True) keeps Σ_j (f_j − w_j) minus what ``fsum`` held in each fluid cell (the slip
    term's fluid part, coupling_pressure_slip_fluid), bitwise the plain sum minus it in float32, with ``out`` the
    velocity buffer itself (the lockstep's shared buffer): the same Σ f c in the fluid cells as into a separate
    array, the walls' velocities (the odd step's prefill reads them) left as they are; the reference likewise."""
    b = {"default": BOUNDARY_SETS["mixed"], "wide": WIDE_X_WALLS}[shape]
    kw = {"shape": (6, 7, 40)} if shape == "wide" else {}
    ko, ro = KernelOps(cpu, **EFFECTS["all"]), ReferenceOps(**EFFECTS["all"])
    s = random_state(91 + parity, b, **kw)
    rng = np.random.default_rng(5)
    held = rng.uniform(-1e-3, 1e-3, s["p"].shape).astype(np.float32)
    fluid = np.zeros(s["flags"].shape, bool)  # the interior fluid cells (periodic ghosts are flagged fluid too)
    fluid[1:-1, 1:-1, 1:-1] = s["flags"][1:-1, 1:-1, 1:-1] == 0
    # plain sum into a separate output
    fsum = np.full_like(s["p"], 7.0)
    out = np.zeros_like(s["velocity"])
    ko.momentum(s["f"].copy(), s["flags"], s["velocity"].copy(), out, parity, fsum=fsum)
    # held, into the velocity buffer
    vel = s["velocity"].copy()
    kept = held.copy()
    ko.momentum(s["f"].copy(), s["flags"], vel, vel, parity, fsum=kept, held=True)
    assert kept[fluid].tobytes() == (fsum[fluid] - held[fluid]).tobytes()
    assert kept[~fluid].tobytes() == held[~fluid].tobytes()
    assert vel[:, fluid].tobytes() == out[:, fluid].tobytes()
    assert vel[:, ~fluid].tobytes() == s["velocity"][:, ~fluid].tobytes()
    vr, kr = s["velocity"].copy(), held.copy()
    ro.momentum(s["f"].copy(), s["flags"], vr, vr, parity, fsum=kr, held=True)
    np.testing.assert_allclose(kr[fluid], kept[fluid], rtol=0, atol=2e-6)
    np.testing.assert_allclose(vr, vel, rtol=0, atol=2e-6)


def test_collide_with_the_force_in_the_velocity_buffer_is_the_separate_one(cpu):
    """The flow collide with ``force`` and ``velocity`` one array (lockstep's shared buffer: each cell reads its
    force before it writes its u): bitwise the collide with the force in an array of its own holding the same
    values, on both parities and the host's bulk, masked and tail rows."""
    ko = KernelOps(cpu, **EFFECTS["all"])
    for parity in (0, 1):
        s = random_state(101 + parity, WIDE_X_WALLS, shape=(6, 7, 40))
        rng = np.random.default_rng(parity)
        force = s["velocity"].copy()  # the walls' velocities in the wall cells, forces in the fluid cells
        fluid = s["flags"] == 0
        force[:, fluid] = rng.uniform(-1e-4, 1e-4, (3, int(fluid.sum())))
        runs = []
        for shared in (True, False):
            f, vel = s["f"].copy(), force.copy()
            frc = vel if shared else force.copy()
            ko.collide_stream(
                f, s["flags"], vel, s["phi"], s["eps"], frc, s["pbar"], parity, *PARAMS, *GRAVITY,
                chemical_potential=chem_of(ko, s),
            )  # fmt: skip
            runs.append((f, vel))
        assert runs[0][0].tobytes() == runs[1][0].tobytes()
        assert runs[0][1].tobytes() == runs[1][1].tobytes()


def test_kept_population_sum_with_fp16_storage_is_the_re_read_one(cpu):
    """fp16 storage: the kept Σ (f − w) decodes the populations as the pressure update does (bitwise p)."""
    ko = KernelOps(cpu, storage="fp16", **EFFECTS["all"])
    for parity in (0, 1):
        s = random_state(81 + parity, WIDE_X_WALLS, shape=(6, 7, 40))
        s["f"] = to_stored(from_stored(s["f"]), "fp16")
        fsum = np.zeros_like(s["p"])
        ko.momentum(s["f"], s["flags"], s["velocity"], np.zeros_like(s["velocity"]), parity, fsum=fsum)
        a, b = s["p"].copy(), s["p"].copy()
        rest = (s["f"], s["flags"], s["velocity"], s["phi"], s["eps"], s["sand_v"], s["slip"])
        ko.macro_pressure(*rest, a, parity, *PARAMS[:2])
        ko.macro_pressure(*rest, b, parity, *PARAMS[:2], fsum=fsum)
        assert a.tobytes() == b.tobytes()


WIDE_X_WALLS = Boundaries({"x-": Face("wall"), "x+": Face("wall", velocity=(0.0, 0.02, 0.0))})


@pytest.mark.parametrize("boundaries", ["periodic", "x_walls"])
@pytest.mark.parametrize("parity", [0, 1])
def test_momentum_on_rows_wider_than_a_vector_keeps_non_fluid_cells(cpu, boundaries, parity):
    """The host momentum loop runs every cell of a row (vector bodies on 40-cell rows) and blends: the
    obstacle's and the ghosts' values given in `out` must come back unchanged, the fluid cells' match the
    reference (tolerance as above)."""
    b = {"periodic": Boundaries(), "x_walls": WIDE_X_WALLS}[boundaries]
    ko, ro = KernelOps(cpu), ReferenceOps()
    sk = random_state(61 + parity, b, shape=(6, 7, 40))
    sr = {k: v.copy() for k, v in sk.items()}
    rng = np.random.default_rng(5)
    out_k = rng.uniform(-1.0, 1.0, sk["velocity"].shape).astype(np.float32)
    out_r = out_k.copy()
    ko.momentum(sk["f"], sk["flags"], sk["velocity"], out_k, parity)
    ro.momentum(sr["f"], sr["flags"], sr["velocity"], out_r, parity)
    np.testing.assert_allclose(out_k, out_r, rtol=0, atol=1e-6)
    fluid = sk["flags"] == 0
    assert (~fluid).sum() > 0 and np.array_equal(out_k[:, ~fluid], out_r[:, ~fluid])
    assert np.abs(out_k[:, fluid] - out_r[:, fluid]).max() < 1e-6 and np.abs(out_r[:, fluid]).max() > 1e-2


@pytest.mark.parametrize("effects", ["single", "all"])
@pytest.mark.parametrize("boundaries", ["periodic", "x_walls"])
@pytest.mark.parametrize("parity", [0, 1])
def test_collide_stream_matches_reference_on_rows_wider_than_a_vector(cpu, effects, boundaries, parity):
    """The host collide runs vector loops over x (16 float lanes with AVX-512) with a flag-free path for rows
    whose neighbourhood is all fluid; on the 9-cell-wide default grid only their short tails run. A 40-cell
    row reaches the vector bodies, both row paths and (with x walls) masked rows. Tolerance as above."""
    b = {"periodic": Boundaries(), "x_walls": WIDE_X_WALLS}[boundaries]
    ko, ro = KernelOps(cpu, **EFFECTS[effects]), ReferenceOps(**EFFECTS[effects])
    sk = random_state(31 + parity, b, shape=(6, 7, 40))
    sr = {k: v.copy() for k, v in sk.items()}
    for ops, s in ((ko, sk), (ro, sr)):
        ops.collide_stream(
            s["f"], s["flags"], s["velocity"], s["phi"], s["eps"], s["force"], s["pbar"], parity,
            *PARAMS, *GRAVITY, chemical_potential=chem_of(ops, s),
        )  # fmt: skip
    state = (sk["flags"] == 0) | (sk["flags"] == 3)
    np.testing.assert_allclose(sk["f"][:, state], sr["f"][:, state], rtol=0, atol=ATOL)
    np.testing.assert_allclose(sk["velocity"], sr["velocity"], rtol=0, atol=ATOL)
    assert np.abs(sk["f"] - random_state(31 + parity, b, shape=(6, 7, 40))["f"]).max() > 1e-3


@pytest.mark.parametrize("effects", ["single", "two_phase_st", "all"])
@pytest.mark.parametrize("boundaries", ["periodic", "x_walls"])
@pytest.mark.parametrize("parity", [0, 1])
def test_pressure_and_filter_match_reference_on_rows_wider_than_a_vector(cpu, effects, boundaries, parity):
    """The host pressure update and filter take the row scheme of the collide (flag-free loops for rows whose
    neighbourhood is all fluid, link masks elsewhere): a 40-cell row reaches the vector bodies of both row
    paths. Tolerances as in test_pressure_and_filter_match_reference."""
    b = {"periodic": Boundaries(), "x_walls": WIDE_X_WALLS}[boundaries]
    ko, ro = KernelOps(cpu, **EFFECTS[effects]), ReferenceOps(**EFFECTS[effects])
    sk = random_state(41 + parity, b, shape=(6, 7, 40))
    sr = {k: v.copy() for k, v in sk.items()}
    p0 = sk["p"].copy()
    for ops, s in ((ko, sk), (ro, sr)):
        ops.macro_pressure(
            s["f"], s["flags"], s["velocity"], s["phi"], s["eps"], s["sand_v"], s["slip"], s["p"], parity, *PARAMS[:2]
        )
        ops.pressure_filter(s["p"], s["flags"], s["pbar"])
    np.testing.assert_allclose(sk["p"], sr["p"], rtol=0, atol=5e-7)
    np.testing.assert_allclose(sk["pbar"], sr["pbar"], rtol=0, atol=5e-7)
    assert np.abs(sk["p"] - p0).max() > 1e-5


def _span_solid(shape=(6, 7, 40)) -> np.ndarray:
    """Rows whose fluid is one span inside solid ends (as a round obstacle cuts them), none, one cell, two runs
    around a solid middle, and a solid end on one side: the host stages loop over each masked row's fluid span
    only (lbm_row_fluid_span), so these are its edge cases."""
    solid = np.zeros(shape, bool)
    solid[1, 2, :] = True  # no fluid at all
    solid[2, 3, :15] = solid[2, 3, 30:] = True  # a span 15..29
    solid[3, 4, :] = True
    solid[3, 4, 20] = False  # one fluid cell
    solid[4, 1, 10:30] = True  # two runs: the span covers the solid middle
    solid[2, 5, :5] = True  # solid at one end only
    solid[1, 5, 35:] = True  # ... and at the other
    return solid


@pytest.mark.parametrize("effects", ["single", "all"])
@pytest.mark.parametrize("parity", [0, 1])
def test_stages_on_rows_with_solid_ends_match_reference_and_keep_non_fluid_cells(cpu, effects, parity):
    """Collide-stream, pressure update, filter and momentum on rows cut by solids (_span_solid), against the
    reference (tolerances as above); every non-fluid cell's velocity, p, p-bar and momentum output comes back
    exactly as it was given."""
    ko, ro = KernelOps(cpu, **EFFECTS[effects]), ReferenceOps(**EFFECTS[effects])
    sk = random_state(71 + parity, WIDE_X_WALLS, shape=(6, 7, 40), solid=_span_solid())
    sr = {k: v.copy() for k, v in sk.items()}
    fluid = sk["flags"] == 0
    before = {k: sk[k].copy() for k in ("velocity", "p", "pbar")}
    rng = np.random.default_rng(3)
    out = {"k": rng.uniform(-1, 1, sk["velocity"].shape).astype(np.float32)}
    out["r"] = out["k"].copy()
    out0 = out["k"].copy()
    for ops, s, o in ((ko, sk, out["k"]), (ro, sr, out["r"])):
        ops.macro_pressure(
            s["f"], s["flags"], s["velocity"], s["phi"], s["eps"], s["sand_v"], s["slip"], s["p"], parity, *PARAMS[:2]
        )
        ops.pressure_filter(s["p"], s["flags"], s["pbar"])
        ops.collide_stream(
            s["f"], s["flags"], s["velocity"], s["phi"], s["eps"], s["force"], s["pbar"], parity,
            *PARAMS, *GRAVITY, chemical_potential=chem_of(ops, s),
        )  # fmt: skip
        ops.momentum(s["f"], s["flags"], s["velocity"], o, parity)
    np.testing.assert_allclose(sk["p"], sr["p"], rtol=0, atol=5e-7)
    np.testing.assert_allclose(sk["pbar"], sr["pbar"], rtol=0, atol=5e-7)
    state = fluid | (sk["flags"] == 3)
    np.testing.assert_allclose(sk["f"][:, state], sr["f"][:, state], rtol=0, atol=ATOL)
    np.testing.assert_allclose(sk["velocity"], sr["velocity"], rtol=0, atol=ATOL)
    np.testing.assert_allclose(out["k"], out["r"], rtol=0, atol=1e-6)
    for key in ("p", "pbar"):
        assert np.array_equal(sk[key][~fluid], before[key][~fluid]), key
    assert np.array_equal(sk["velocity"][:, ~fluid], before["velocity"][:, ~fluid])
    assert np.array_equal(out["k"][:, ~fluid], out0[:, ~fluid])
    assert np.abs(sk["velocity"][:, fluid] - before["velocity"][:, fluid]).max() > 1e-3  # the fluid moved


@pytest.mark.parametrize("shape", [(5, 6, 7), (3, 9, 2), (8, 2, 4)])
@pytest.mark.parametrize(
    "walls", [(), ("z",), ("x", "y"), ("x", "y", "z")], ids=["periodic", "z-walls", "xy-walls", "closed"]
)
def test_link_boxes_are_the_odd_steps_ghost_links(shape, walls):
    """The boxes the kernels copy and fold by (periodic_link_boxes) hold exactly the (ghost, image, direction)
    triples of the reference's rule, each once: ghost g of periodic_lists and direction j with g − c_j interior
    (a face ghost 9 directions, an edge 3, a corner 1); extents of 2 and 3 cells, the ghost of one face is the
    image's neighbour there."""
    from couplekit.fluid.grid import link_box_arrays, periodic_link_boxes, periodic_lists
    from couplekit.lattice import C27

    faces = {a + s: Face("wall") for a in walls for s in "-+"}
    b = Boundaries(faces)
    ghost, image = periodic_lists(shape, b)
    pz, py, px = (n + 2 for n in shape)
    gz, rem = np.divmod(ghost, px * py)
    gy, gx = np.divmod(rem, px)
    expect = []
    for j in range(1, 27):
        sx, sy, sz = gx - C27[j, 0], gy - C27[j, 1], gz - C27[j, 2]
        inside = (sx >= 1) & (sx <= px - 2) & (sy >= 1) & (sy <= py - 2) & (sz >= 1) & (sz <= pz - 2)
        expect += [(int(g), int(i), j) for g, i in zip(ghost[inside], image[inside], strict=True)]
    boxes = periodic_link_boxes(shape, b)
    got = []
    for x0, x1, y0, y1, z0, z1, ox, oy, oz, q in boxes.tolist():
        for z in range(z0, z1 + 1):
            for y in range(y0, y1 + 1):
                for x in range(x0, x1 + 1):
                    g = x + px * (y + py * z)
                    got.append((g, g + ox + px * (oy + py * oz), q))
    assert sorted(got) == sorted(expect) and len(set(got)) == len(got)
    assert link_box_arrays(boxes).total == len(expect)
