"""Triangle meshes and height fields as signed distance functions.

:class:`TriangleMesh` turns a closed triangle mesh into an SDF in two independent parts, both vectorised:

* **inside test** — a ray from each point towards +x; the point is inside when the ray crosses the surface
  an odd number of times beyond it. Parity, not the signed winding number, because it does not depend on
  the orientation of the triangles, which mesh files (STL above all) often get inconsistent; the price is
  that overlapping closed components cancel where they overlap (split such a mesh into bodies, or merge
  it). Rays are moved by a tiny
  irrational offset in (y, z) so that none runs exactly through an edge or a vertex (meshes aligned with the
  grid would otherwise be hit twice or not at all on shared edges).
* **distance** — the surface is sampled densely (spacing ``sample_spacing``); a KD-tree (scipy) finds the
  ``k`` samples nearest to each point, and the exact point–triangle distance (Ericson, *Real-Time Collision
  Detection* §5.1.5) is taken over the triangles those samples lie on. The result is never below the true
  distance and never above the distance to the nearest sample, so its error is at most the sampling
  spacing, and zero whenever the closest triangle is among the candidates (the usual case).

:func:`load_mesh` reads OBJ, STL, PLY (anything meshio reads; quads are split into triangles).
:class:`HeightField` is the solid below a surface z = h(x, y) down to a base, built as a closed triangle mesh.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from .geometry import Shape

__all__ = ["TriangleMesh", "HeightField", "load_mesh", "point_triangle_distance", "load_heights", "open_edges"]

MAX_SURFACE_SAMPLES = 2**31
"""Most surface samples a mesh SDF may take (48 bytes each with the KD-tree: ~100 GiB); a mesh that would need
more at its sample spacing (a coarse triangle far larger than the spacing) is refused before allocation."""

_RAY_SHIFT = (0.7548776662466927e-7, 0.5698402909980532e-7)  # irrational fractions of the mesh size


def point_triangle_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distance from points p (N, 3) to triangles (a, b, c) (each (N, 3)), row by row."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v_in = vb / denom
        w_in = vc / denom
        closest = a + ab * v_in[:, None] + ac * w_in[:, None]  # interior of the face
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    regions = [
        (d1 <= 0) & (d2 <= 0),  # vertex a
        (d3 >= 0) & (d4 <= d3),  # vertex b
        (d6 >= 0) & (d5 <= d6),  # vertex c
        (vc <= 0) & (d1 >= 0) & (d3 <= 0),  # edge ab
        (vb <= 0) & (d2 >= 0) & (d6 <= 0),  # edge ac
        (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0),  # edge bc
    ]
    choices = [a, b, c, a + ab * t_ab[:, None], a + ac * t_ac[:, None], b + (c - b) * t_bc[:, None]]
    done = np.zeros(p.shape[0], bool)
    for mask, point in zip(regions, choices, strict=True):
        take = mask & ~done
        closest[take] = point[take]
        done |= take
    # degenerate (zero-area) triangles: fall back to the nearest vertex
    bad = ~np.isfinite(closest).all(axis=1)
    if bad.any():
        dv = np.stack([np.linalg.norm(p[bad] - v[bad], axis=1) for v in (a, b, c)])
        closest[bad] = np.stack([a[bad], b[bad], c[bad]])[dv.argmin(axis=0), np.arange(bad.sum())]
    return np.linalg.norm(p - closest, axis=1)


def _surface_samples(v: np.ndarray, f: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Points on every triangle on a barycentric grid finer than ``spacing``; returns (points, triangle ids)."""
    tri = v[f]  # (T, 3, 3)
    edge = np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2), axis=1)
    with np.errstate(over="ignore", invalid="ignore"):
        steps = np.maximum(1.0, np.ceil(edge / spacing))
        total = float(np.sum((steps + 1.0) * (steps + 2.0) / 2.0))
    if not total <= MAX_SURFACE_SAMPLES:  # also catches inf and NaN
        raise ValueError(
            f"sampling the surface every {spacing:.3g} m would take {total:.3g} points (at most "
            f"{MAX_SURFACE_SAMPLES:.3g}): its longest edge is {float(np.max(edge)):.3g} m; use a finer mesh or a "
            "smaller shape"
        )
    nsub = steps.astype(np.int64)
    pts, ids = [], []
    for n in np.unique(nsub):
        sel = np.nonzero(nsub == n)[0]
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = (i + j) <= n
        u, w = i[keep] / n, j[keep] / n  # barycentric weights of b and c
        t = tri[sel]
        p = (
            t[:, None, 0]
            + u[None, :, None] * (t[:, None, 1] - t[:, None, 0])
            + w[None, :, None] * (t[:, None, 2] - t[:, None, 0])
        )
        pts.append(p.reshape(-1, 3))
        ids.append(np.repeat(sel, u.size))
    return np.concatenate(pts), np.concatenate(ids)


class TriangleMesh(Shape):
    """A closed triangle mesh (vertices (V, 3) m, faces (T, 3) int) as an SDF.

    sample_spacing: surface sampling of the distance search (default: 1/100 of the bounding-box diagonal);
    candidates: samples (and so at most as many triangles) examined per point.
    """

    def __init__(
        self, vertices: np.ndarray, faces: np.ndarray, sample_spacing: float | None = None, candidates: int = 16
    ):
        self.vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        self.faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        if self.faces.size == 0:
            raise ValueError("the mesh has no triangles")
        if not np.all(np.isfinite(self.vertices)):
            raise ValueError(f"{int(np.sum(~np.isfinite(self.vertices).all(axis=1)))} mesh vertices are not finite")
        if self.faces.min() < 0 or self.faces.max() >= len(self.vertices):
            raise ValueError("mesh faces index vertices that do not exist")
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        self._lo, self._hi = lo, hi
        self.size = float(np.linalg.norm(hi - lo)) or 1.0
        if not math.isfinite(self.size):
            raise ValueError(f"the mesh's extent {lo.tolist()} .. {hi.tolist()} is too large to measure")
        self.sample_spacing = float(sample_spacing) if sample_spacing else self.size / 100.0
        self.candidates = int(candidates)
        self._samples, self._sample_tri = _surface_samples(self.vertices, self.faces, self.sample_spacing)
        self._tree = cKDTree(self._samples)
        # inside test: triangles projected on (y, z)
        tri = self.vertices[self.faces]
        self._tri = tri
        self._yz_lo, self._yz_hi = tri[:, :, 1:].min(axis=1), tri[:, :, 1:].max(axis=1)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self._lo.copy(), self._hi.copy()

    # -------------------------------------------------------------------------------------- inside
    def crossings(self, points: np.ndarray) -> np.ndarray:
        """Number (N,) of surface crossings of the +x ray from each point (odd inside a closed mesh)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        shift = np.array(_RAY_SHIFT) * self.size
        rays, ray_of = np.unique(p[:, 1:] + shift, axis=0, return_inverse=True)
        ray_of = ray_of.reshape(-1)
        tree = cKDTree(rays)
        centre = 0.5 * (self._yz_lo + self._yz_hi)
        radius = 0.5 * np.linalg.norm(self._yz_hi - self._yz_lo, axis=1) * (1 + 1e-9) + 1e-300
        lists = tree.query_ball_point(centre, radius)
        counts = np.fromiter((len(x) for x in lists), dtype=np.int64, count=len(lists))
        if counts.sum() == 0:
            return np.zeros(p.shape[0], np.int64)
        pair_tri = np.repeat(np.arange(len(lists)), counts)
        pair_ray = np.fromiter((r for x in lists for r in x), dtype=np.int64, count=int(counts.sum()))
        t = self._tri[pair_tri]
        q = rays[pair_ray]
        a, b, c = t[:, 0], t[:, 1], t[:, 2]

        def edge(u, v):  # 2-D cross (v - u) x (q - u) in (y, z)
            return (v[:, 1] - u[:, 1]) * (q[:, 1] - u[:, 2]) - (v[:, 2] - u[:, 2]) * (q[:, 0] - u[:, 1])

        w0, w1, w2 = edge(a, b), edge(b, c), edge(c, a)
        pos = (w0 > 0) & (w1 > 0) & (w2 > 0)
        neg = (w0 < 0) & (w1 < 0) & (w2 < 0)
        hit = pos | neg
        area = (w0 + w1 + w2)[hit]
        x_hit = (a[hit, 0] * w1[hit] + b[hit, 0] * w2[hit] + c[hit, 0] * w0[hit]) / area
        sign = np.ones(int(hit.sum()), np.int64)
        hray = pair_ray[hit]
        # per ray, number of hits beyond each point: sort hits by (ray, x), suffix sums
        span = max(float(np.ptp(np.concatenate([x_hit, p[:, 0]]))), 1e-300)
        x0 = min(x_hit.min(), p[:, 0].min())
        key = hray + 0.25 + 0.5 * (x_hit - x0) / span
        order = np.argsort(key, kind="stable")
        key, sign = key[order], sign[order]
        suffix = np.concatenate([np.cumsum(sign[::-1])[::-1], [0]])
        pkey = ray_of + 0.25 + 0.5 * (p[:, 0] - x0) / span
        start = np.searchsorted(key, pkey, side="right")
        end = np.searchsorted(key, ray_of + 1.0, side="left")
        return suffix[start] - suffix[end]

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Boolean (N,): points enclosed by the mesh."""
        return (self.crossings(points) % 2) == 1

    # -------------------------------------------------------------------------------------- distance
    def distance(self, points: np.ndarray, chunk: int = 200_000) -> np.ndarray:
        """Unsigned distance (N,) to the surface."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.empty(p.shape[0])
        k = min(self.candidates, len(self._samples))
        for s in range(0, p.shape[0], chunk):
            q = p[s : s + chunk]
            _, idx = self._tree.query(q, k=k)
            idx = idx.reshape(q.shape[0], -1)
            tri = self._sample_tri[idx]  # (n, k) candidate triangles (with repeats)
            best = np.full(q.shape[0], np.inf)
            for j in range(tri.shape[1]):
                t = self._tri[tri[:, j]]
                best = np.minimum(best, point_triangle_distance(q, t[:, 0], t[:, 1], t[:, 2]))
            out[s : s + chunk] = best
        return out

    def sdf(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        d = self.distance(p)
        return np.where(self.inside(p), -d, d)


def open_edges(vertices: np.ndarray, faces: np.ndarray) -> int:
    """Edges of a triangle mesh that do not close: those used by an odd number of triangles, vertices welded
    where their coordinates are equal (STL and some OBJ exports repeat a vertex per triangle). 0 for a closed
    (watertight) surface, whose inside the parity test of :meth:`TriangleMesh.inside` is defined for."""
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    _, weld = np.unique(v, axis=0, return_inverse=True)
    f = weld.reshape(-1)[np.asarray(faces, dtype=np.int64).reshape(-1, 3)]
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    edges = np.sort(edges[edges[:, 0] != edges[:, 1]], axis=1)  # a degenerate triangle's collapsed edge closes
    if edges.size == 0:
        return 0
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return int(np.count_nonzero(counts % 2))


def load_mesh(path: str | Path, sample_spacing: float | None = None) -> TriangleMesh:
    """Read a closed triangle mesh (OBJ, STL, PLY, or any format meshio reads) as a :class:`TriangleMesh`.

    Raises ValueError for a file meshio cannot read (whatever meshio raised is in the message), a mesh without
    triangles or quads, non-finite vertices, or an open surface (:func:`open_edges`)."""
    import contextlib
    import io

    import meshio

    said = io.StringIO()  # meshio prints what it tries and fails; that belongs in the message, not the output
    try:
        with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
            mesh = meshio.read(str(path))
    except (Exception, SystemExit) as exc:  # ReadError, a format reader's error, or meshio's own sys.exit(1)
        why = " ".join(said.getvalue().split()) or f"{type(exc).__name__}: {exc}"
        raise ValueError(f"{path}: not a mesh meshio can read ({why[-300:]})") from None
    faces = []
    for block in mesh.cells:
        if block.type == "triangle":
            faces.append(np.asarray(block.data))
        elif block.type == "quad":
            q = np.asarray(block.data)
            faces += [q[:, [0, 1, 2]], q[:, [0, 2, 3]]]
    if not faces:
        raise ValueError(f"{path}: no triangles or quads in the mesh (cell types: {[b.type for b in mesh.cells]})")
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] < 3:
        raise ValueError(f"{path}: the mesh's points are not 3-D (shape {points.shape})")
    points, faces = points[:, :3], np.concatenate(faces).astype(np.int64)
    if faces.size and (faces.min() < 0 or faces.max() >= len(points)):
        raise ValueError(f"{path}: mesh faces index vertices that do not exist")
    if not np.all(np.isfinite(points)):
        raise ValueError(f"{path}: {int(np.sum(~np.isfinite(points).all(axis=1)))} mesh vertices are not finite")
    holes = open_edges(points, faces)
    if holes:
        raise ValueError(
            f"{path}: the mesh is not closed (watertight): {holes} edges belong to one triangle only (or an odd "
            "number), so its inside is undefined; close the holes (e.g. Blender's 'Fill Holes' or MeshLab's "
            "'Close Holes')"
        )
    return TriangleMesh(points, faces, sample_spacing)


def load_heights(path: str | Path) -> np.ndarray:
    """A 2-D height grid from a .npy file or a whitespace/comma separated text file."""
    path = Path(path)
    try:
        if path.suffix == ".npy":
            h = np.load(path)  # allow_pickle is off: a pickled object is refused, not run
        else:
            h = np.loadtxt(path, delimiter="," if path.suffix == ".csv" else None)
        h = np.asarray(h, dtype=np.float64)
    except OSError:
        raise
    except Exception as exc:  # not an array file, not numbers, ragged rows, ...
        raise ValueError(f"{path}: not a grid of numbers ({type(exc).__name__}: {exc})") from None
    if h.ndim != 2 or min(h.shape) < 2:
        raise ValueError(f"{path}: a height grid must be 2-D with at least 2 rows and columns, got shape {h.shape}")
    if not np.all(np.isfinite(h)):
        raise ValueError(f"{path}: {int(np.count_nonzero(~np.isfinite(h)))} heights are not finite (NaN or inf)")
    return h


class HeightField(TriangleMesh):
    """The solid between ``base`` and the surface z = h(x, y).

    heights: (ny, nx) grid, row j at y = y_range[0] + j Δy, column i at x = x_range[0] + i Δx (bilinear
    between samples, i.e. two triangles per quad). The solid is closed by vertical side walls and a flat
    bottom at ``base``, so outside the x/y range there is no solid.
    """

    def __init__(
        self,
        heights: np.ndarray,
        x_range: Sequence[float],
        y_range: Sequence[float],
        base: float,
        sample_spacing: float | None = None,
    ):
        h = np.asarray(heights, dtype=np.float64)
        if h.ndim != 2 or min(h.shape) < 2:
            raise ValueError(f"heights must be a 2-D grid with at least 2 rows and columns, got shape {h.shape}")
        if not np.all(np.isfinite(h)):
            raise ValueError(f"{int(np.count_nonzero(~np.isfinite(h)))} heights are not finite (NaN or inf)")
        if not np.all(np.isfinite([*x_range, *y_range, base])):
            raise ValueError("height field x_range, y_range and base must be finite")
        if not x_range[1] > x_range[0] or not y_range[1] > y_range[0]:
            raise ValueError("height field x_range and y_range must be increasing")
        if np.any(h <= base):
            raise ValueError(f"every height must lie above the base {base}, the lowest is {h.min()}")
        ny, nx = h.shape
        xs, ys = np.linspace(x_range[0], x_range[1], nx), np.linspace(y_range[0], y_range[1], ny)
        X, Y = np.meshgrid(xs, ys)  # (ny, nx)
        top = np.stack([X, Y, h], axis=-1).reshape(-1, 3)
        bottom = np.stack([X, Y, np.full_like(h, base)], axis=-1).reshape(-1, 3)
        n = nx * ny
        T = np.arange(n).reshape(ny, nx)
        B = T + n
        a, b, c, d = T[:-1, :-1], T[:-1, 1:], T[1:, 1:], T[1:, :-1]  # counter-clockwise seen from +z
        faces = [np.stack([a, b, c], -1), np.stack([a, c, d], -1)]
        a, b, c, d = B[:-1, :-1], B[:-1, 1:], B[1:, 1:], B[1:, :-1]
        faces += [np.stack([a, c, b], -1), np.stack([a, d, c], -1)]  # bottom faces -z
        for t, bb, outward_first in (
            (T[0, :], B[0, :], True),  # y = y0, normal -y
            (T[-1, :], B[-1, :], False),  # y = y1, normal +y
            (T[:, 0], B[:, 0], False),  # x = x0, normal -x
            (T[:, -1], B[:, -1], True),  # x = x1, normal +x
        ):
            A0, A1, t0, t1 = bb[:-1], bb[1:], t[:-1], t[1:]
            if outward_first:
                faces += [np.stack([A0, A1, t1], -1), np.stack([A0, t1, t0], -1)]
            else:
                faces += [np.stack([A1, A0, t0], -1), np.stack([A1, t0, t1], -1)]
        faces = np.concatenate([f.reshape(-1, 3) for f in faces])
        self.heights, self.x_range, self.y_range, self.base = h, tuple(x_range), tuple(y_range), float(base)
        spacing = sample_spacing or 0.5 * min(xs[1] - xs[0], ys[1] - ys[0])
        super().__init__(np.concatenate([top, bottom]), faces, spacing)
