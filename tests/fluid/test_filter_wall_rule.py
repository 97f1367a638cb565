"""The pressure filter's three-point wall rule (Eq. 40 in flat wall layers): where it applies, what it does.

Geometry (couplekit.fluid.grid.flat_wall_cells / three_point_links) is checked on closed boxes at two sizes,
the kernel (lbm_filter_wall_rule after lbm_pressure_filter) against the NumPy reference, and the rule's two
properties: a linear (hydrostatic) profile passes the filter unchanged (as with the two-point rule), and the
wall-normal period-2 mode a(−1)^k is filtered to a/3 in the flat wall layer as in the interior (the two-point
rule leaves it at a there; Fig. 4's colander diverged from it, docs/fluid-stability.md).

Tolerances: float32 kernel sums of 27 terms of |p| ≤ 1e-3 against float64: 5e-7 absolute, as
tests/fluid/test_lbm_kernels.py; the closed-form checks on the reference hold to float64 round-off (1e-12).
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.fluid import KernelOps, ReferenceOps
from couplekit.fluid.grid import (
    INTERIOR,
    Boundaries,
    Face,
    build_flags,
    flat_wall_cells,
    three_point_links,
    wall_rule_axes,
)
from couplekit.fluid.reference import interior, local_average


@pytest.fixture(scope="module")
def cpu(kernel_backend):
    return kernel_backend


def _box(n: int, solid=None, walls: str = "xyz"):
    flags, _, _ = build_flags((n, n, n), Boundaries.channel(walls), solid)
    return flags


@pytest.mark.parametrize("n", [8, 11])
def test_flat_wall_cells_of_a_closed_box_are_the_face_cells_two_from_every_edge(n):
    flat = flat_wall_cells(_box(n))
    assert flat.dtype == bool and not flat[0].any() and not flat[-1].any()
    assert int(flat.sum()) == 6 * (n - 4) ** 2
    z, y, x = np.nonzero(interior(flat))
    on_face = np.minimum.reduce([z, y, x, n - 1 - z, n - 1 - y, n - 1 - x]) == 0
    assert on_face.all()
    # on the bottom face: the in-plane coordinates run over [2, n - 3]
    bottom = interior(flat)[0]
    assert bottom[2 : n - 2, 2 : n - 2].all() and bottom.sum() == (n - 4) ** 2


@pytest.mark.parametrize("n", [8, 11])
def test_flat_wall_cells_of_the_chosen_axes_only(n):
    flags = _box(n)
    only_z = interior(flat_wall_cells(flags, (False, False, True)))
    assert int(only_z.sum()) == 2 * (n - 4) ** 2
    assert only_z[0].sum() == only_z[-1].sum() == (n - 4) ** 2 and not only_z[1:-1].any()
    links = interior(three_point_links(flags, (False, False, True)))
    assert links[0].any() and links[-1].any() and not links[1:-1].any()


def test_wall_rule_axes_follow_gravity():
    assert wall_rule_axes((0.0, 0.0, -1e-5)) == (False, False, True)
    assert wall_rule_axes((1e-6, 0.0, -1e-5)) == (True, False, True)
    assert wall_rule_axes((0.0, 0.0, 0.0)) == (True, True, True)


@pytest.mark.parametrize("n", [8, 11])
def test_three_point_links_point_into_the_wall_and_keep_two_cells_of_fluid_behind(n):
    flags = _box(n)
    links = interior(three_point_links(flags))
    bottom = links[0]
    # a bottom-face cell in the middle of the face: the 9 links with c_z = -1 (its wall neighbours)
    from couplekit.lattice import C27

    down = sum(1 << j for j in range(1, 27) if C27[j, 2] == -1)
    assert bottom[n // 2, n // 2] == down
    # two cells from the side walls: the links whose x - 2c lands beside the side wall are left out
    assert bottom[2, n // 2] != 0 and bottom[2, n // 2] & down == bottom[2, n // 2] and bottom[2, n // 2] != down
    assert not links[1:-1, 1:-1, 1:-1].any()  # nothing off the wall layers


def _two_point(p, flags):
    return local_average(p, flags, np.zeros(flags.shape, np.uint32))


@pytest.mark.parametrize("axes", [(True, True, True), (False, False, True)], ids=["all_walls", "floor_ceiling"])
@pytest.mark.parametrize("n", [8, 11])
def test_kernel_filter_matches_reference_with_the_rule_active(cpu, n, axes):
    solid = np.zeros((n, n, n), bool)
    solid[n // 2 :, 2:4, n // 2 - 1 : n // 2 + 2] = True  # a post hanging from the ceiling
    flags = _box(n, solid)
    rng = np.random.default_rng(n)
    p = rng.uniform(-1e-3, 1e-3, flags.shape).astype(np.float32)
    pbar_k = cpu.asarray(np.zeros_like(p))
    pbar_r = np.zeros_like(p)
    KernelOps(cpu).pressure_filter(cpu.asarray(p), cpu.asarray(flags), pbar_k, axes)
    ReferenceOps().pressure_filter(p, flags, pbar_r, axes)
    pbar_k = cpu.to_host(pbar_k)
    fluid = flags == 0
    fluid[~np.pad(np.ones((n, n, n), bool), 1)] = False
    np.testing.assert_allclose(pbar_k[fluid], pbar_r[fluid], rtol=0, atol=5e-7)
    two = _two_point(p, flags)[interior(fluid)]
    assert np.abs(interior(pbar_r)[interior(fluid)] - two).max() > 1e-5  # the rule changed the wall layer


@pytest.mark.parametrize(
    "faces",
    [
        {
            "y-": Face("wall"),
            "y+": Face("wall", velocity=(0.03, 0.0, 0.0)),
            "z-": Face("inflow", velocity=(0, 0, 0.02)),
            "z+": Face("outflow"),
        },
        {"x-": Face("wall"), "x+": Face("outflow"), "z-": Face("wall"), "z+": Face("wall")},
    ],
    ids=["walls_inflow_outflow", "walls_outflow_x"],
)
def test_kernel_filter_matches_reference_beside_inflow_outflow_and_obstacles(cpu, faces):
    shape = (10, 12, 9)
    solid = np.zeros(shape, bool)
    solid[3:6, 0:2, 3:5] = True  # a block on the y- wall
    solid[7, 5:7, 6] = True  # and a small one inside
    flags, _, _ = build_flags(shape, Boundaries(faces), solid)
    links = three_point_links(flags)
    assert links.any() and not links[flags != 0].any()  # only fluid cells take the rule
    rng = np.random.default_rng(7)
    p = rng.uniform(-1e-3, 1e-3, flags.shape).astype(np.float32)
    pbar_k = cpu.asarray(np.zeros_like(p))
    pbar_r = np.zeros_like(p)
    KernelOps(cpu).pressure_filter(cpu.asarray(p), cpu.asarray(flags), pbar_k)
    ReferenceOps().pressure_filter(p, flags, pbar_r)
    fluid = np.zeros(flags.shape, bool)
    fluid[INTERIOR] = flags[INTERIOR] == 0
    np.testing.assert_allclose(cpu.to_host(pbar_k)[fluid], pbar_r[fluid], rtol=0, atol=5e-7)


@pytest.mark.parametrize("n", [8, 11])
def test_linear_profile_passes_and_wall_normal_checkerboard_is_filtered_as_inside(n):
    flags = _box(n, walls="z")  # walls below and above, periodic x, y
    k = np.arange(n + 2) - 1.0  # interior z index of each padded layer
    lin = np.broadcast_to((1e-3 + 2e-5 * k)[:, None, None], flags.shape).copy()
    np.testing.assert_allclose(local_average(lin, flags), interior(lin), rtol=0, atol=1e-12)
    a = 1e-3
    checker = np.broadcast_to((a * (-1.0) ** k)[:, None, None], flags.shape).copy()
    out = local_average(checker, flags)
    # inside: a/3 with the mode's sign; the flat wall layers (every face cell: x, y periodic) the same
    expect = interior(checker) / 3.0
    inner = np.s_[:, 2 : n - 2, 2 : n - 2]  # away from the periodic seams, where x - 2c leaves the padded grid
    np.testing.assert_allclose(out[inner], expect[inner], rtol=0, atol=1e-12)
    # the two-point rule: the wall layers keep the full amplitude
    two = _two_point(checker, flags)
    np.testing.assert_allclose(two[0][2 : n - 2, 2 : n - 2], a, rtol=0, atol=1e-12)
    np.testing.assert_allclose(two[-1][2 : n - 2, 2 : n - 2], a * (-1.0) ** (n - 1), rtol=0, atol=1e-12)


def test_forget_links_rebuilds_the_rule_cells(cpu):
    ops = KernelOps(cpu)
    flags = cpu.asarray(_box(8))
    first = ops._three_point_cells(flags)
    assert ops._three_point_cells(flags) is first
    ops.forget_links()
    assert ops._three_point_cells(flags) is not first
    assert int(first[0].size) == int(np.count_nonzero(three_point_links(cpu.to_host(flags))))
