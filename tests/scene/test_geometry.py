"""SDFs of primitives, transforms, meshes (written by meshio) and height fields against closed forms."""

from __future__ import annotations

import meshio
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from couplekit.scene import Box, Cylinder, HeightField, Sphere, Transformed, TriangleMesh, load_mesh, sdf_on_grid
from couplekit.scene.mesh import point_triangle_distance

RNG = np.random.default_rng(7)
# meshio's STL reader multiplies a 32-bit triangle count while sniffing binary vs ASCII: a harmless overflow warning
pytestmark = pytest.mark.filterwarnings("ignore:overflow encountered in scalar multiply:RuntimeWarning")


def test_box_sdf_closed_form():
    b = Box([0, 0, 0], [1, 2, 3])
    p = np.array([[0.5, 1, 1.5], [2, 1, 1.5], [2, 3, 1.5], [0.1, 1, 1.5]])
    np.testing.assert_allclose(b.sdf(p), [-0.5, 1.0, np.sqrt(2.0), -0.1])


def test_sphere_and_cylinder_sdf_closed_form():
    s = Sphere([1, 1, 1], 0.5)
    np.testing.assert_allclose(s.sdf(np.array([[1, 1, 1], [3, 1, 1]])), [-0.5, 1.5])
    c = Cylinder([0, 0, 0], 1.0, 2.0, axis="y")
    p = np.array([[0, 0, 0], [3, 0, 0], [0, 4, 0], [3, 5, 0], [0, 0.5, 0.2]])
    np.testing.assert_allclose(c.sdf(p), [-1.0, 2.0, 3.0, np.hypot(2, 4), -0.5])


def test_transform_keeps_distances_exact():
    """Scale s, rotation R, translation t: sdf(p) = s·sdf₀(Rᵀ(p − t)/s); checked against the moved analytic box."""
    base = Box([-1, -0.5, -0.25], [1, 0.5, 0.25])
    t = Transformed(base, scale=2.0, rotate=[0, 0, 90], translate=[5, 5, 5])
    moved = Box([5 - 1, 5 - 2, 5 - 0.5], [5 + 1, 5 + 2, 5 + 0.5])  # x,y swapped by the 90° turn about z, doubled
    p = RNG.uniform(2, 8, (2000, 3))
    np.testing.assert_allclose(t.sdf(p), moved.sdf(p), atol=1e-12)
    lo, hi = t.bounds()
    np.testing.assert_allclose(lo, [4, 3, 4.5], atol=1e-12)
    np.testing.assert_allclose(hi, [6, 7, 5.5], atol=1e-12)


def test_point_triangle_distance_regions():
    a, b, c = np.array([[0.0, 0, 0]]), np.array([[1.0, 0, 0]]), np.array([[0.0, 1, 0]])
    cases = {
        (0.2, 0.2, 0.5): 0.5,
        (-1, -1, 0): np.sqrt(2),
        (2, 0, 1): np.sqrt(2),
        (0.5, -1, 0): 1.0,
        (1, 1, 0): np.sqrt(0.5),
    }
    for p, want in cases.items():
        got = point_triangle_distance(np.array([p], float), a, b, c)[0]
        assert got == pytest.approx(want, abs=1e-12), p


def _cube_file(tmp_path, ext):
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    path = tmp_path / f"cube.{ext}"
    meshio.write(path, meshio.Mesh(v, [("triangle", ConvexHull(v).simplices)]))
    return path


@pytest.mark.parametrize("ext", ["obj", "stl", "ply"])
def test_cube_mesh_matches_box_sdf(tmp_path, ext):
    """A cube mesh is exactly the unit box: sign and distance agree to round-off, also at grid-aligned points
    (the rays of the inside test would otherwise run through the cube's edges)."""
    m = load_mesh(_cube_file(tmp_path, ext))
    box = Box([0, 0, 0], [1, 1, 1])
    p = np.concatenate(
        [
            RNG.uniform(-0.5, 1.5, (5000, 3)),
            np.stack(np.meshgrid(*[np.linspace(-0.25, 1.25, 7)] * 3), -1).reshape(-1, 3),
        ]
    )
    np.testing.assert_allclose(m.sdf(p), box.sdf(p), atol=1e-9)


def test_sphere_mesh_matches_sphere_within_faceting(tmp_path):
    """Sphere mesh (hull of 3000 points on the unit sphere, written and read back by meshio): the SDF equals
    the analytic one to within the faceting error max(1 − distance of a face plane from the centre)."""
    u = RNG.normal(size=(3000, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    hull = ConvexHull(u)
    meshio.write(tmp_path / "ball.obj", meshio.Mesh(u, [("triangle", hull.simplices)]))
    m = load_mesh(tmp_path / "ball.obj")
    sag = 1.0 - np.min(-hull.equations[:, 3])  # hull planes n·x + d = 0 with |n| = 1: distance |d|
    p = RNG.uniform(-2, 2, (4000, 3))
    err = np.abs(m.sdf(p) - (np.linalg.norm(p, axis=1) - 1.0))
    assert err.max() <= sag + 1e-9, (err.max(), sag)
    assert sag < 0.01


def test_transformed_mesh_and_grid_sampling(tmp_path):
    m = load_mesh(_cube_file(tmp_path, "stl"))
    t = Transformed(m, scale=0.5, rotate=[0, 0, 0], translate=[0.25, 0.25, 0.25])
    phi = sdf_on_grid(t, (10, 10, 10), 0.1)
    ref = sdf_on_grid(Box([0.25] * 3, [0.75] * 3), (10, 10, 10), 0.1)
    assert phi.shape == (10, 10, 10) and phi.dtype == np.float32
    np.testing.assert_allclose(phi, ref, atol=1e-6)


def test_heightfield_plane_and_bump():
    """A tilted plane z = 0.3 + 0.2x: the signed distance to the plane, (z − h)/√(1 + 0.04), near the surface
    and away from the side walls; sign right everywhere inside the x/y range."""
    xs = np.linspace(0, 1, 6)
    h = np.tile(0.3 + 0.2 * xs, (5, 1))
    hf = HeightField(h, [0, 1], [0, 1], base=-0.1)
    q = np.column_stack([RNG.uniform(0.2, 0.8, 3000), RNG.uniform(0.2, 0.8, 3000), RNG.uniform(0.0, 0.6, 3000)])
    plane = (q[:, 2] - (0.3 + 0.2 * q[:, 0])) / np.sqrt(1.04)
    d = hf.sdf(q)
    assert np.all(np.sign(d) == np.sign(plane))
    near = np.abs(plane) < 0.1
    np.testing.assert_allclose(d[near], plane[near], atol=1e-9)
    assert np.all(hf.sdf(np.array([[1.5, 0.5, 0.0], [0.5, 0.5, -0.5]])) > 0)  # beside and below: outside


def test_mesh_refuses_bad_faces():
    with pytest.raises(ValueError, match="vertices that do not exist"):
        TriangleMesh(np.zeros((3, 3)), np.array([[0, 1, 5]]))
