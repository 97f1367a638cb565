"""Bounds of transformed shapes: never smaller than the solid (sdf < 0), and tight (not the box of a rotated box).

A rotated sphere, cylinder or mesh used to get the box of its rotated bounding box, up to √3 times too large, so
validation refused rotated sand bodies that fit the domain (a tilted column, a ball mesh turned 45° about z).
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest

from couplekit.scene import Box, Cylinder, HeightField, Scene, SceneError, Sphere, Transformed, TriangleMesh, Union
from couplekit.scene.geometry import Difference, _moved_corners, rotation_matrix


def _icosphere(radius: float, subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """A closed icosphere about the origin (outward faces): vertices, faces."""
    t = (1 + 5**0.5) / 2
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t]]
    v += [[0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6]]
    f += [[7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10]]
    f += [[8, 6, 7], [9, 8, 1]]
    v = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(subdivisions):
        cache: dict[tuple[int, int], int] = {}
        new = []
        for a, b, c in f:
            mids = []
            for p, q in ((a, b), (b, c), (c, a)):
                key = (min(p, q), max(p, q))
                if key not in cache:
                    m = v[p] + v[q]
                    v.append(m / np.linalg.norm(m))
                    cache[key] = len(v) - 1
                mids.append(cache[key])
            ab, bc, ca = mids
            new += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        f = new
    return radius * np.array(v), np.array(f)


def _tetra() -> TriangleMesh:
    v = np.array([[0.0, 0, 0], [0.04, 0, 0], [0, 0.03, 0], [0.01, 0.01, 0.05]])
    return TriangleMesh(v, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))


def _shapes() -> dict[str, object]:
    v, f = _icosphere(0.02, 2)
    return {
        "box": Box([-0.02, -0.01, -0.005], [0.01, 0.015, 0.02]),
        "sphere": Sphere([0.004, -0.003, 0.002], 0.018),
        "cylinder_x": Cylinder([0.003, 0, -0.002], 0.012, 0.04, axis="x"),
        "cylinder_z": Cylinder([0, 0.002, 0], 0.02, 0.01, axis="z"),
        "mesh_ball": TriangleMesh(v + [0.003, 0.0, -0.002], f),
        "mesh_tetra": _tetra(),
        "heightfield": HeightField([[0.01, 0.02, 0.015], [0.025, 0.012, 0.02]], (-0.02, 0.02), (-0.01, 0.015), -0.01),
        "nested_cylinder": Transformed(
            Cylinder([0.002, 0, 0], 0.01, 0.03, axis="y"), 1.3, [20, -35, 50], [0.004, 0, 0]
        ),
        "union": Union([Sphere([-0.01, 0, 0], 0.01), Cylinder([0.01, 0, 0], 0.006, 0.03, axis="z")]),
        "difference": Difference(Sphere([0, 0, 0], 0.02), [Box([0.0, -0.03, -0.03], [0.03, 0.03, 0.03])]),
    }


ROTATIONS = [([0, 0, 45], 1.0), ([30, 0, 45], 0.7), ([-70, 25, 110], 1.6), ([13, 81, -37], 1.2)]
CELLS = 40  # grid cells across the widest side of the new bounds
SHARP = {"mesh_tetra", "heightfield"}  # tips thinner than a cell: the inside grid points may stop short of them
LOOSE = {"difference"}  # bounds of the uncut shape


@pytest.mark.parametrize("name", list(_shapes()))
@pytest.mark.parametrize(("rotate", "scale"), ROTATIONS, ids=[str(r[0]) for r in ROTATIONS])
def test_transformed_bounds_hold_the_solid_and_are_tight(name, rotate, scale):
    """Sample the SDF on a grid over the old (rotated-corner, always large enough) box: every inside point lies in
    the new bounds (conservative), and the new bounds reach no further than ~1 cell beyond the inside points (tight).

    Tight is checked two ways: the grid points within one cell of the solid (sdf < h, the SDFs being distances)
    reach within h of every face of the bounds, for every shape whose bounds are its own (not a difference, whose
    box is that of the shape before the cut); and for the shapes without sharp tips, where an extreme point of the
    solid always has grid points inside it nearby, the inside points themselves reach within 1.5 h."""
    shape = _shapes()[name]
    moved = Transformed(shape, scale, rotate, [0.1, -0.2, 0.3])
    lo, hi = moved.bounds()
    old_lo, old_hi = _moved_corners(shape.bounds(), moved.scale, moved.rotation, moved.translation)
    tol = 1e-12
    assert np.all(lo >= old_lo - tol) and np.all(hi <= old_hi + tol)  # never looser than before
    h = float(np.max(hi - lo)) / CELLS
    offset = np.random.default_rng(zlib.crc32(name.encode())).uniform(0, h, 3)  # no grid plane on a face
    axes = [np.arange(old_lo[a] - 2 * h + offset[a], old_hi[a] + 2 * h, h) for a in range(3)]
    p = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    d = moved.sdf(p)
    inside = p[d < 0]
    assert inside.shape[0] > 100
    assert np.all(inside >= lo - tol) and np.all(inside <= hi + tol), (name, inside.min(0) - lo, hi - inside.max(0))
    if name in LOOSE:
        return
    near = p[d < h]  # a ball of radius h about any extreme point of the solid holds a grid point
    assert np.all(near.min(axis=0) <= lo + h + tol) and np.all(near.max(axis=0) >= hi - h - tol), name
    if name not in SHARP:
        slack_lo, slack_hi = inside.min(axis=0) - lo, hi - inside.max(axis=0)
        assert np.all(slack_lo <= 1.5 * h) and np.all(slack_hi <= 1.5 * h), (name, slack_lo / h, slack_hi / h)


def test_sphere_bounds_ignore_the_rotation():
    lo, hi = Transformed(Sphere([0.01, 0.0, 0.0], 0.02), 2.0, [10, 20, 30], [1.0, 2.0, 3.0]).bounds()
    c = 2.0 * rotation_matrix([10, 20, 30]) @ [0.01, 0.0, 0.0] + [1.0, 2.0, 3.0]
    np.testing.assert_allclose(lo, c - 0.04, atol=1e-15)
    np.testing.assert_allclose(hi, c + 0.04, atol=1e-15)


def test_cylinder_bounds_match_its_rim():
    """The exact box of a tilted cylinder: that of dense points on its two end rims."""
    cyl = Cylinder([0.0, 0.0, 0.01], 0.02, 0.06, axis="z")
    moved = Transformed(cyl, 1.5, [30, 0, 45], [0.04, 0.06, 0.06])
    th = np.linspace(0, 2 * np.pi, 20001)
    rim = np.concatenate(
        [np.stack([0.02 * np.cos(th), 0.02 * np.sin(th), np.full_like(th, z)], axis=1) for z in (-0.02, 0.04)]
    )
    world = 1.5 * rim @ moved.rotation.T + moved.translation
    lo, hi = moved.bounds()
    np.testing.assert_allclose(lo, world.min(axis=0), atol=1e-9)
    np.testing.assert_allclose(hi, world.max(axis=0), atol=1e-9)


def test_nested_transforms_compose():
    """A Transformed of a Transformed gets the bounds of the one equivalent transform (tight, not the rotated box
    of a rotated box)."""
    v, f = _icosphere(0.02, 2)
    for inner in (Cylinder([0.01, 0, 0], 0.01, 0.04, axis="x"), TriangleMesh(v, f), Sphere([0.0, 0.01, 0], 0.01)):
        nested = Transformed(Transformed(inner, 1.5, [0, 30, 0], [0.01, 0.02, 0]), 0.5, [45, 0, 20], [1.0, 0, -1.0])
        r = rotation_matrix([45, 0, 20]) @ rotation_matrix([0, 30, 0])
        t = 0.5 * rotation_matrix([45, 0, 20]) @ [0.01, 0.02, 0] + [1.0, 0, -1.0]
        want = inner.transformed_bounds(0.75, r, t)
        got = nested.bounds()
        np.testing.assert_allclose(got[0], want[0], atol=1e-14)
        np.testing.assert_allclose(got[1], want[1], atol=1e-14)
        p = np.random.default_rng(3).uniform(got[0] - 0.01, got[1] + 0.01, (4000, 3))
        np.testing.assert_allclose(nested.sdf(p), 0.75 * inner.sdf((p - t) @ r / 0.75), atol=1e-12)


def _sand_scene(geometry: dict) -> dict:
    return {
        "domain": {"size": [0.12, 0.12, 0.12], "dx": 0.005},
        "time": {"dt": 1e-4},
        "bodies": [{"kind": "sand", "geometry": geometry}],
    }


def test_tilted_cylinder_that_fits_validates():
    """r = 2 cm, h = 6 cm column turned [30, 0, 45]: its x extent 0.0120 .. 0.0706 m keeps the 0.01 m sand margin
    (it was refused with the rotated box's 0.0043 .. 0.0783 m)."""
    geo = {"type": "cylinder", "center": [0.0, 0.0, 0.0], "radius": 0.02, "height": 0.06}
    geo |= {"rotate": [30, 0, 45], "translate": [0.0413, 0.06, 0.06]}
    scene = Scene.from_dict(_sand_scene(geo))
    lo, hi = scene.bodies[0].geometry.bounds(scene.domain)
    assert lo[0] == pytest.approx(0.01203, abs=1e-4) and hi[0] == pytest.approx(0.07057, abs=1e-4)
    too_far = dict(geo, translate=[0.0373, 0.06, 0.06])  # 4 mm further: x from 0.0080, inside the margin
    with pytest.raises(SceneError, match="reaches outside the domain along x"):
        Scene.from_dict(_sand_scene(too_far))


@pytest.mark.parametrize("turn", [0, 45])
def test_ball_mesh_turned_about_z_validates(tmp_path, turn):
    """A 4.5 cm ball mesh at the centre of a 12 cm box fits, turned 45° about z or not (it was refused turned)."""
    v, f = _icosphere(0.045, 3)
    with open(tmp_path / "ball_origin.obj", "w") as fh:
        fh.writelines(f"v {x} {y} {z}\n" for x, y, z in v)
        fh.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f)
    (tmp_path / "scene.toml").write_text(
        "[domain]\nsize = [0.12, 0.12, 0.12]\ndx = 0.005\n[time]\ndt = 1e-4\n"
        '[[bodies]]\nkind = "sand"\n[bodies.geometry]\ntype = "mesh"\nfile = "ball_origin.obj"\n'
        f"rotate = [0, 0, {turn}]\ntranslate = [0.06, 0.06, 0.06]\n"
    )
    scene = Scene.load(tmp_path / "scene.toml")
    lo, hi = scene.bodies[0].geometry.bounds(scene.domain)
    np.testing.assert_allclose(lo, 0.015, atol=2e-4)
    np.testing.assert_allclose(hi, 0.105, atol=2e-4)
