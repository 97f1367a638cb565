"""Phase-field kernels (kernels/phasefield.cu) against the NumPy reference, and their GPU builds.

Tolerances: the kernels compute in float32, the reference in float64 from the same float32 inputs and
stores float32.  Each stored value is a short chain (<= ~10 operations for h, 27 terms for the stencils)
of float32 roundings of 6e-8 relative each, on values of order 1 (h <= 0.3, phi in [0, 1], |grad| <= 1.5,
|mu| <= 3), so the kernel/reference difference is a few 1e-7; we allow 2e-6 absolute (about 30 ulp of
1.0), far below any error of the scheme (a wrong weight, slot or sign changes values by >= 1e-3).
Pure data movement (which slot is read or written) would show up as O(0.1) differences.
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.backend import get_backend
from couplekit.fluid.phasefield import (
    FLUID,
    INFLOW,
    OUTFLOW,
    WALL,
    PhaseFieldKernelOps,
    PhaseFieldReferenceOps,
    pad_flags,
    padded_shape,
)

ATOL = 2e-6
SHAPE = (6, 7, 9)  # (nz, ny, nx): different extents catch swapped axes
PERIODIC_CASES = [(True, True, True), (False, True, False), (True, False, True), (False, False, False)]


@pytest.fixture(scope="module")
def cpu(kernel_backend):
    """cpu and cpu-device in turn (skipped without a host compiler): the host and the CUDA code paths."""
    return kernel_backend


def random_state(seed: int, periodic, boundary_kinds=(WALL, INFLOW, OUTFLOW), shape=SHAPE, solid=0.12, inner=0.03):
    """A random but valid state: h > 0 with phi in (0, 1.4), |u| < 0.05, a small source, and flags with
    interior obstacles (fraction ``solid``) plus random WALL / INFLOW / OUTFLOW cells on the ghost layer of
    non-periodic axes (and a fraction ``inner`` inside), so every boundary rule of the AA pattern is exercised."""
    rng = np.random.default_rng(seed)
    p = padded_shape(shape)
    flags = pad_flags(rng.random(shape) < solid, shape, periodic)
    kinds = np.asarray(boundary_kinds, dtype=np.uint8)
    ghost = flags == WALL
    ghost[1:-1, 1:-1, 1:-1] = False
    flags[ghost] = rng.choice(kinds, size=int(ghost.sum()))
    cells = flags[1:-1, 1:-1, 1:-1]
    cells[(rng.random(shape) < inner) & (cells == FLUID)] = rng.choice(kinds)
    h = (rng.random((7, *p)) * 0.2).astype(np.float32)
    phi = rng.random(p).astype(np.float32)
    phi[1:5, 1:5, 1:5] = 0.3  # cells whose 27 neighbours share phi: no interface normal (the bulk's threshold)
    u = ((rng.random((3, *p)) - 0.5) * 0.1).astype(np.float32)
    source = ((rng.random(p) - 0.5) * 0.02).astype(np.float32)
    eps = (0.4 + 0.6 * rng.random(p)).astype(np.float32)
    return dict(h=h, phi=phi, u=u, source=source, flags=flags, eps=eps)


def test_random_states_use_every_flag_kind():
    s = random_state(1, (False, True, False))
    assert {FLUID, WALL, INFLOW, OUTFLOW} <= set(np.unique(s["flags"]).tolist())


def _collide_stream_both(cpu, periodic, s: dict, parity: int):
    """One phase-field collide-stream of state ``s`` by the kernel and by the reference: (kernel ops, reference ops, h_k, h_r)."""
    kernel, ref = PhaseFieldKernelOps(cpu, periodic), PhaseFieldReferenceOps(periodic)
    h_k, h_r = s["h"].copy(), s["h"].copy()
    args = (s["phi"], s["u"], s["source"], s["flags"], parity, 0.04, 4.5, 0.6)
    kernel.collide_stream(h_k, *args)
    ref.collide_stream(h_r, *args)
    return kernel, ref, h_k, h_r


@pytest.mark.parametrize("periodic", PERIODIC_CASES)
@pytest.mark.parametrize("parity", [0, 1, 7])
def test_collide_stream_matches_reference(cpu, periodic, parity):
    s = random_state(10 + parity, periodic)
    kernel, ref, h_k, h_r = _collide_stream_both(cpu, periodic, s, parity)
    assert np.abs(h_k - h_r).max() < ATOL
    # the step really changed h (the comparison is not between two untouched copies)
    assert np.abs(h_k - s["h"]).max() > 1e-2


@pytest.mark.parametrize("parity", [0, 1])
def test_collide_stream_trt_matches_reference_and_conserves(cpu, parity):
    """The two-relaxation-time collision (trt_lambda = 1/6): kernel = reference, it differs from the single rate,
    and a closed box (walls only, no source) keeps Σφ to float32 round-off."""
    periodic = PERIODIC_CASES[1]
    s = random_state(40 + parity, periodic)
    kernel, ref = PhaseFieldKernelOps(cpu, periodic), PhaseFieldReferenceOps(periodic)
    h_k, h_r, h_bgk = s["h"].copy(), s["h"].copy(), s["h"].copy()
    args = (s["phi"], s["u"], s["source"], s["flags"], parity, 0.02, 4.0, 0.6)
    kernel.collide_stream(h_k, *args, trt_lambda=1.0 / 6.0)
    ref.collide_stream(h_r, *args, trt_lambda=1.0 / 6.0)
    kernel.collide_stream(h_bgk, *args)
    assert np.abs(h_k - h_r).max() < ATOL
    assert np.abs(h_k - h_bgk).max() > 1e-3
    walls = random_state(50 + parity, periodic, boundary_kinds=(WALL,))
    zero = np.zeros_like(walls["source"])
    h = walls["h"].copy()
    phi0 = np.zeros(padded_shape(SHAPE), np.float32)
    kernel.macroscopic(h, phi0, walls["u"], walls["flags"], parity)
    kernel.collide_stream(h, walls["phi"], walls["u"], zero, walls["flags"], parity, 0.02, 4.0, 1.0, trt_lambda=0.25)
    phi1 = np.zeros(padded_shape(SHAPE), np.float32)
    kernel.macroscopic(h, phi1, walls["u"], walls["flags"], parity + 1)
    fluid = walls["flags"][1:-1, 1:-1, 1:-1] == FLUID
    v0, v1 = (float(p[1:-1, 1:-1, 1:-1][fluid].astype(np.float64).sum()) for p in (phi0, phi1))
    assert abs(v1 - v0) < 1e-4 * max(1.0, abs(v0)), (v0, v1)


@pytest.mark.parametrize("parity", [0, 1])
def test_inflow_link_lets_in_exactly_phi_b_u_b(cpu, parity):
    """An inflow face (x-) carrying φ_b = 0.7 at u = (0.05, 0, 0) into a box of φ = 0.2 at rest, every other face a
    wall: one step changes Σφ by exactly φ_b u_x × (face cells), whatever the cells' phase values (no diffusive
    or interface exchange across an inflow), kernel and reference alike."""
    periodic = (False, False, False)
    nz, ny, nx = SHAPE
    flags = pad_flags(None, SHAPE, periodic)
    flags[1:-1, 1:-1, 0] = INFLOW
    pshape = padded_shape(SHAPE)
    phi = np.zeros(pshape, np.float32)
    # a ramp in x: grad phi (computed in the collide) gives an interface normal, so the counter flux H is not zero
    phi[1:-1, 1:-1, 1:-1] = 0.2 + 0.03 * np.arange(nx, dtype=np.float32)
    phi[flags == INFLOW] = 0.7
    u = np.zeros((3, *pshape), np.float32)
    u[0][flags == INFLOW] = 0.05
    for ops in (PhaseFieldKernelOps(cpu, periodic), PhaseFieldReferenceOps(periodic)):
        h = np.zeros((7, *pshape), np.float32)
        ops.set_equilibrium(h, phi, u, flags, parity)
        p0, p1 = phi.copy(), phi.copy()
        ops.macroscopic(h, p0, u, flags, parity)
        ops.collide_stream(h, p0, u, np.zeros(pshape, np.float32), flags, parity, 0.02, 4.0)
        ops.macroscopic(h, p1, u, flags, parity + 1)
        dv = float(p1[1:-1, 1:-1, 1:-1].astype(np.float64).sum() - p0[1:-1, 1:-1, 1:-1].astype(np.float64).sum())
        assert abs(dv - 0.7 * 0.05 * ny * nz) < 1e-5, (type(ops).__name__, dv, 0.7 * 0.05 * ny * nz)


@pytest.mark.parametrize("parity", [0, 1])
@pytest.mark.parametrize("u_x", [0.05, 0.0, -0.05])
def test_outflow_link_passes_only_the_advective_flux(cpu, parity, u_x):
    """An outflow face (x+) of a box whose φ rises towards it (0.2 + 0.03 x: an interface normal, so the sharpening
    flux H points out through the face), every other face a wall, the fluid at u = (u_x, 0, 0): one step changes
    Σφ by exactly −u_x Σ φ over the face's cells where the fluid leaves (u_x > 0; φ the cell's own sum when the
    link is loaded: after the step at parity 0, before it at parity 1), and by 0 where it is at rest or comes in.
    The former rule (the cell's equilibrium fed back, session 28) let H and the non-equilibrium part leave too:
    Σφ changed at rest."""
    periodic = (False, False, False)
    nz, ny, nx = SHAPE
    flags = pad_flags(None, SHAPE, periodic)
    flags[1:-1, 1:-1, -1] = OUTFLOW
    pshape = padded_shape(SHAPE)
    phi = np.zeros(pshape, np.float32)
    phi[1:-1, 1:-1, 1:-1] = 0.2 + 0.03 * np.arange(nx, dtype=np.float32)
    u = np.zeros((3, *pshape), np.float32)
    u[0] = u_x
    for ops in (PhaseFieldKernelOps(cpu, periodic), PhaseFieldReferenceOps(periodic)):
        h = np.zeros((7, *pshape), np.float32)
        ops.set_equilibrium(h, phi, u, flags, parity)
        p0, p1 = phi.copy(), phi.copy()
        ops.macroscopic(h, p0, u, flags, parity)
        np.testing.assert_allclose(p0[1:-1, 1:-1, 1:-1], phi[1:-1, 1:-1, 1:-1], atol=2e-7)  # loads back as set
        ops.collide_stream(h, p0, u, np.zeros(pshape, np.float32), flags, parity, 0.02, 4.0)
        ops.macroscopic(h, p1, u, flags, parity + 1)
        dv = float(p1[1:-1, 1:-1, 1:-1].astype(np.float64).sum() - p0[1:-1, 1:-1, 1:-1].astype(np.float64).sum())
        face = (p1 if parity == 0 else p0)[1:-1, 1:-1, nx].astype(np.float64).sum()
        expect = -max(u_x, 0.0) * face
        assert abs(dv - expect) < 2e-6, (type(ops).__name__, dv, expect)


@pytest.mark.parametrize("periodic", PERIODIC_CASES)
@pytest.mark.parametrize("parity", [0, 1])
def test_macroscopic_matches_reference(cpu, periodic, parity):
    s = random_state(20 + parity, periodic)
    kernel, ref = PhaseFieldKernelOps(cpu, periodic), PhaseFieldReferenceOps(periodic)
    phi_k = np.full(padded_shape(SHAPE), -9.0, dtype=np.float32)
    phi_r = phi_k.copy()
    inflow = s["flags"] == INFLOW
    phi_k[inflow] = phi_r[inflow] = s["phi"][inflow]  # the phase value inflow cells carry
    kernel.macroscopic(s["h"], phi_k, s["u"], s["flags"], parity)
    ref.macroscopic(s["h"], phi_r, s["u"], s["flags"], parity)
    assert np.abs(phi_k - phi_r).max() < ATOL
    assert phi_k.min() >= 0.0  # every cell, ghosts included, was written
    assert np.array_equal(phi_k[inflow], s["phi"][inflow])  # inflow values are kept


@pytest.mark.parametrize("periodic", PERIODIC_CASES[:2])
@pytest.mark.parametrize("parity", [0, 1])
@pytest.mark.parametrize("kinds", [(WALL,), (WALL, INFLOW)], ids=["walls", "inflow"])
def test_set_equilibrium_matches_reference_and_loads_back(cpu, periodic, parity, kinds):
    s = random_state(30 + parity, periodic, boundary_kinds=kinds)
    kernel, ref = PhaseFieldKernelOps(cpu, periodic), PhaseFieldReferenceOps(periodic)
    h_k = np.zeros((7, *padded_shape(SHAPE)), dtype=np.float32)
    h_r = h_k.copy()
    kernel.set_equilibrium(h_k, s["phi"], s["u"], s["flags"], parity)
    ref.set_equilibrium(h_r, s["phi"], s["u"], s["flags"], parity)
    assert np.abs(h_k - h_r).max() < ATOL
    # loading at the same parity gives back phi = sum_k h_k^eq in fluid cells (inflow cells keep the phase
    # value they carry, which their links' flux part reads)
    phi = np.zeros(padded_shape(SHAPE), dtype=np.float32)
    phi[s["flags"] == INFLOW] = s["phi"][s["flags"] == INFLOW]
    kernel.macroscopic(h_k, phi, s["u"], s["flags"], parity)
    fluid = s["flags"][1:-1, 1:-1, 1:-1] == FLUID
    assert np.abs(phi[1:-1, 1:-1, 1:-1] - s["phi"][1:-1, 1:-1, 1:-1])[fluid].max() < ATOL


@pytest.mark.parametrize("surface_tension", [True, False])
@pytest.mark.parametrize("periodic", PERIODIC_CASES[:2])
def test_gradients_match_reference(cpu, periodic, surface_tension):
    s = random_state(40, periodic)
    kernel = PhaseFieldKernelOps(cpu, periodic, surface_tension=surface_tension)
    ref = PhaseFieldReferenceOps(periodic, surface_tension=surface_tension)
    p = padded_shape(SHAPE)
    g_k, g_r = np.zeros((3, *p), np.float32), np.zeros((3, *p), np.float32)
    mu_k = np.zeros(p, np.float32) if surface_tension else None
    mu_r = np.zeros(p, np.float32) if surface_tension else None
    kernel.gradients(s["phi"], s["flags"], g_k, mu_k, 0.9, 0.7)
    ref.gradients(s["phi"], s["flags"], g_r, mu_r, 0.9, 0.7)
    assert np.abs(g_k - g_r).max() < ATOL
    assert np.abs(g_k).max() > 0.1
    if surface_tension:
        assert np.abs(mu_k - mu_r).max() < ATOL
        assert np.abs(mu_k).max() > 0.1


def test_gradients_refuse_mu_mismatch(cpu):
    s = random_state(41, True)
    grad = np.zeros((3, *padded_shape(SHAPE)), np.float32)
    for ops in (PhaseFieldKernelOps(cpu, True, surface_tension=False), PhaseFieldReferenceOps(True, False)):
        with pytest.raises(ValueError, match="surface_tension"):
            ops.gradients(s["phi"], s["flags"], grad, s["phi"].copy(), 1.0, 1.0)


@pytest.mark.parametrize("with_eps", [False, True])
def test_volume_sums_match_reference(cpu, with_eps):
    s = random_state(50, (False, True, False))
    kernel, ref = PhaseFieldKernelOps(cpu, (False, True, False)), PhaseFieldReferenceOps((False, True, False))
    eps = s["eps"] if with_eps else None
    vk, sk = kernel.volume_sums(s["phi"], s["source"], s["flags"], eps)
    vr, sr = ref.volume_sums(s["phi"], s["source"], s["flags"], eps)
    # float64 sums of ~400 float32 values in different orders: agree to ~1e-15 relative
    assert vk == pytest.approx(vr, rel=1e-12, abs=1e-12)
    assert sk == pytest.approx(sr, rel=1e-12, abs=1e-12)
    # ghost and solid cells are excluded: a huge value there must not show up
    phi = s["phi"].copy()
    phi[0, 0, 0] = 1e6
    phi[s["flags"] != FLUID] = 1e6
    assert kernel.volume_sums(phi, s["source"], s["flags"], eps)[0] == pytest.approx(vk, rel=1e-12)


def test_mixture_sums_are_the_two_volume_sums(kernel_backend):
    """The volume controller's one-pass (Σ ε φ, Σ ε S_φ) of a mixture: bitwise the two ε-weighted volume sums
    it replaced (φ, then S_φ in φ's place) on the kernel backends, to float64 round-off on the reference; ghost
    and solid cells excluded."""
    s = random_state(51, (False, True, False))
    kernel, ref = (
        PhaseFieldKernelOps(kernel_backend, (False, True, False)),
        PhaseFieldReferenceOps((False, True, False)),
    )
    phi, eps, src, flags = s["phi"], s["eps"], s["source"], s["flags"]
    v, w = kernel.mixture_sums(phi, eps, src, flags)
    assert v == kernel.volume_sums(phi, src, flags, eps)[0]
    assert w == kernel.volume_sums(src, src, flags, eps)[0]
    vr, wr = ref.mixture_sums(phi, eps, src, flags)
    assert v == pytest.approx(vr, rel=1e-12) and w == pytest.approx(wr, rel=1e-12, abs=1e-15)
    assert abs(w) > 0 and v > 0
    masked = [a.copy() for a in (phi, eps, src)]
    for a in masked:
        a[flags != FLUID] = 1e6
    assert kernel.mixture_sums(*masked, flags) == (v, w)


@pytest.mark.parametrize("parity", [0, 1])
def test_source_compiled_out_matches_the_reference_and_a_zero_source(cpu, parity):
    """CK_PF_SOURCE=0 (no S_φ: fluid-only scenes, the Fig. 14 ablation): collide_stream and the volume sums
    take source=None, match the reference, and equal the source variant given zeros (the same arithmetic:
    bitwise); the source-built ops refuse None."""
    periodic = (False, True, False)
    s = random_state(70 + parity, periodic)
    off_k, off_r = PhaseFieldKernelOps(cpu, periodic, source=False), PhaseFieldReferenceOps(periodic, source=False)
    on_k = PhaseFieldKernelOps(cpu, periodic)
    h_off, h_ref, h_zero = s["h"].copy(), s["h"].copy(), s["h"].copy()
    rest = (s["flags"], parity, 0.04, 4.5, 0.6)
    off_k.collide_stream(h_off, s["phi"], s["u"], None, *rest)
    off_r.collide_stream(h_ref, s["phi"], s["u"], None, *rest)
    on_k.collide_stream(h_zero, s["phi"], s["u"], np.zeros_like(s["source"]), *rest)
    assert np.abs(h_off - h_ref).max() < ATOL
    assert np.array_equal(h_off, h_zero)
    assert np.abs(h_off - s["h"]).max() > 1e-2
    for eps in (None, s["eps"]):
        vk, sk = off_k.volume_sums(s["phi"], None, s["flags"], eps)
        vr, sr = off_r.volume_sums(s["phi"], None, s["flags"], eps)
        assert sk == 0.0 and sr == 0.0
        assert vk == pytest.approx(vr, rel=1e-12) and vk == pytest.approx(
            on_k.volume_sums(s["phi"], s["source"], s["flags"], eps)[0], rel=1e-12
        )
    for ops in (on_k, PhaseFieldReferenceOps(periodic)):
        with pytest.raises(ValueError, match="source term"):
            ops.volume_sums(s["phi"], None, s["flags"])


@pytest.mark.parametrize("periodic", [(True, True, False), (False, True, True)])
@pytest.mark.parametrize("parity", [0, 1])
def test_kernels_match_reference_on_rows_wider_than_a_vector(cpu, periodic, parity):
    """The host kernels run flag-free vector loops over x for rows whose neighbourhood is all fluid (with the
    row's constant neighbour offsets; the wrapping end cells and every other row take the per-cell code):
    40-cell rows with few obstacles reach both paths, every boundary kind on the non-periodic ghosts."""
    shape = (6, 7, 40)
    s = random_state(60 + parity, periodic, shape=shape, solid=0.004, inner=0.002)
    kernel, ref, h_k, h_r = _collide_stream_both(cpu, periodic, s, parity)
    assert np.abs(h_k - h_r).max() < ATOL
    assert np.abs(h_k - s["h"]).max() > 1e-2
    pshape = padded_shape(shape)
    phi_k = np.full(pshape, -9.0, dtype=np.float32)
    inflow = s["flags"] == INFLOW
    phi_k[inflow] = s["phi"][inflow]
    phi_r = phi_k.copy()
    kernel.macroscopic(h_k, phi_k, s["u"], s["flags"], parity + 1)
    ref.macroscopic(h_k, phi_r, s["u"], s["flags"], parity + 1)
    assert np.abs(phi_k - phi_r).max() < ATOL and phi_k.min() >= 0.0
    g_k, g_r = np.zeros((3, *pshape), np.float32), np.zeros((3, *pshape), np.float32)
    mu_k, mu_r = np.zeros(pshape, np.float32), np.zeros(pshape, np.float32)
    kernel.gradients(phi_k, s["flags"], g_k, mu_k, 0.9, 0.7)
    ref.gradients(phi_k, s["flags"], g_r, mu_r, 0.9, 0.7)
    assert np.abs(g_k - g_r).max() < ATOL and np.abs(mu_k - mu_r).max() < ATOL
    assert np.abs(g_k).max() > 0.1


# GPU builds (nvcc sm_80/sm_90 without spills, NVRTC with the backend's options) for both values of
# CK_PF_SURFACE_TENSION and CK_PF_SOURCE are covered by tests/test_kernel_builds.py through the `// variants:` lines.


def test_full_step_sequence_matches_reference_with_every_boundary(cpu):
    """Kernel and reference runners (set_equilibrium, then macroscopic -> gradients -> collide_stream per
    step) with walls, an obstacle, an inflow face carrying phi = 1 and an outflow face, 12 steps.
    Tolerance 2e-5: the per-step float32 differences of ATOL accumulate over 12 steps."""
    from couplekit.fluid.phasefield import PhaseFieldRunner, make_phase_field_ops

    periodic = (False, True, False)
    shape = (5, 6, 10)
    solid = np.zeros(shape, bool)
    solid[2, 2:4, 5] = True
    flags = pad_flags(solid, shape, periodic)
    flags[:, :, 0] = INFLOW
    flags[:, :, -1] = OUTFLOW
    u = np.zeros((3, *padded_shape(shape)), np.float32)
    u[0] = 0.04
    u[2, 1:-1, 1:-1, 1:-1] = 0.01
    rng = np.random.default_rng(5)
    phi0 = np.where(solid, 0.0, rng.random(shape) * 0.3)
    ref_ops = make_phase_field_ops(get_backend("numpy"), periodic, True)
    assert isinstance(ref_ops, PhaseFieldReferenceOps)
    runs = [
        PhaseFieldRunner(ops, phi0, mobility=0.05, width=3.0, sigma=1e-3, flags=flags, u=u)
        for ops in (make_phase_field_ops(cpu, periodic, True), ref_ops)
    ]
    for run in runs:
        run.phi[flags == INFLOW] = 1.0
        run.step(12)
    k, r = (run.to_host(run.phi) for run in runs)
    assert np.abs(k - r).max() < 2e-5
    mu_k, mu_r = (run.to_host(run.gradients()[1]) for run in runs)
    assert np.abs(mu_k - mu_r).max() < 2e-5
    assert k[1:-1, 1:-1, 1].max() > 0.5  # the inflow phase has entered


@pytest.mark.parametrize("periodic", [(False, True, False), (True, False, True)])
def test_full_step_sequence_matches_reference_on_rows_cut_by_solids(cpu, periodic):
    """The host collide-stream and macroscopic run a row with non-fluid cells from its first to its last fluid
    cell, and there the runs of cells whose six neighbours are fluid by the bulk loop (pf_odd_run_cell): rows
    with no fluid, one fluid cell, a span inside solid ends, two runs around a solid middle, beside solids in
    the neighbouring rows, with an inflow and an outflow face; 12 steps against the reference (tolerance of
    the test above)."""
    from couplekit.fluid.phasefield import PhaseFieldRunner, make_phase_field_ops

    shape = (6, 7, 40)
    solid = np.zeros(shape, bool)
    solid[1, 2, :] = True  # no fluid
    solid[2, 3, :15] = solid[2, 3, 30:] = True  # a span 15..29
    solid[3, 4, :] = True
    solid[3, 4, 20] = False  # one fluid cell
    solid[4, 1, 10:30] = True  # two runs around a solid middle
    solid[2, 5, :5] = solid[1, 5, 35:] = True  # a solid end on one side
    flags = pad_flags(solid, shape, periodic)
    if not periodic[2]:
        flags[0, :, :] = np.where(flags[0] == 0, flags[0], INFLOW)  # the z- ghost layer: an inflow face
        flags[-1, :, :] = np.where(flags[-1] == 0, flags[-1], OUTFLOW)
    u = np.zeros((3, *padded_shape(shape)), np.float32)
    u[0] = 0.03
    u[2, 1:-1, 1:-1, 1:-1] = 0.01
    rng = np.random.default_rng(9)
    phi0 = np.where(solid, 0.0, rng.random(shape) * 0.6)
    runs = [
        PhaseFieldRunner(ops, phi0, mobility=0.05, width=3.0, sigma=1e-3, flags=flags, u=u)
        for ops in (
            make_phase_field_ops(cpu, periodic, True),
            make_phase_field_ops(get_backend("numpy"), periodic, True),
        )
    ]
    for run in runs:
        run.phi[flags == INFLOW] = 1.0
        run.step(12)
    k, r = (run.to_host(run.phi) for run in runs)
    assert np.abs(k - r).max() < 2e-5
    fluid = flags == 0
    assert np.abs(k[fluid] - np.pad(phi0, 1)[fluid]).max() > 1e-3  # the field moved
