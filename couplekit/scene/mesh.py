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
  spacing, and zero whenever the closest triangle is among the candidates (the usual case). A mesh whose
  whole surface would take more than :data:`EAGER_SURFACE_SAMPLES` samples (one far larger than the domain)
  is sampled lazily, near the box of the points asked for only (:meth:`TriangleMesh.distance`): the cost is
  the surface near the domain, not the whole mesh's.

:func:`load_mesh` reads OBJ, STL, PLY (anything meshio reads; quads are split into triangles).
:class:`HeightField` is the solid below a surface z = h(x, y) down to a base, built as a closed triangle mesh.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from .geometry import Shape

__all__ = ["TriangleMesh", "HeightField", "load_mesh", "point_triangle_distance", "load_heights", "open_edges"]

MAX_SURFACE_SAMPLES = 2**24
"""Most surface samples a mesh SDF keeps (about 130 bytes each at the peak of building them and their KD-tree: ~2 GiB).
The count is worked out before anything is allocated; a mesh that needs more where its SDF is asked for is refused
with what to change (a coarser dx, or the mesh clipped to the domain)."""

EAGER_SURFACE_SAMPLES = 2**21
"""A mesh whose whole surface takes at most this many samples (~250 MB at peak) is sampled when it is built, all of
it. A larger one (a mesh far larger than the domain, or a fine dx) is sampled where its SDF is asked for only:
finely near the box of the points queried, ever more coarsely away from it (:meth:`TriangleMesh.distance`)."""

MAX_EDGE_SPACINGS = 2**24
"""Longest triangle edge, in sample spacings, a mesh may have (4 million cells at the solvers' spacing dx / 4, more
than any domain holds): a longer one is refused when the mesh is built, as far larger than any domain it could
serve (heights of 1e6 m, a mesh in millimetres read as metres)."""

REGION_MARGIN = 16
"""Margin, in sample spacings (4 cells at the solvers' spacing dx / 4), around the box of the points queried, within
which a lazily sampled mesh is sampled exactly as the whole mesh would be."""

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


def _steps(tri: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Per triangle (T, 3, 3): longest edge, lattice steps (float, >= 1) finer than ``spacing``, and the total
    number of lattice points (inf or NaN where they overflow)."""
    edge = np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2), axis=1)
    with np.errstate(over="ignore", invalid="ignore"):
        steps = np.maximum(1.0, np.ceil(edge / spacing))
        total = float(np.sum((steps + 1.0) * (steps + 2.0) / 2.0))
    return edge, steps, total


def _lattice(tri: np.ndarray, nsub: np.ndarray, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every point of the barycentric lattice (``nsub`` steps) of the triangles ``sel``: (points, triangle ids)."""
    pts, ids = [np.zeros((0, 3))], [np.zeros(0, np.int64)]
    for n in np.unique(nsub[sel]):
        s = sel[nsub[sel] == n]
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = (i + j) <= n
        u, w = i[keep] / n, j[keep] / n  # barycentric weights of b and c
        t = tri[s]
        p = (
            t[:, None, 0]
            + u[None, :, None] * (t[:, None, 1] - t[:, None, 0])
            + w[None, :, None] * (t[:, None, 2] - t[:, None, 0])
        )
        pts.append(p.reshape(-1, 3))
        ids.append(np.repeat(s, u.size))
    return np.concatenate(pts), np.concatenate(ids)


def _in_box(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.all((p >= lo) & (p <= hi), axis=1)


def _u_range(a: np.ndarray, e1: np.ndarray, e2: np.ndarray, lo, hi, chunk: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """Least and greatest u over the points a + u e1 + w e2 (u, w >= 0, u + w <= 1) of each triangle that lie in
    the box [lo, hi] (least > greatest where none does). The extremes of u over that convex polygon lie at its
    vertices, which are pairwise intersections of its 9 constraint lines; each is checked against all 9 with a
    relative slack of 1e-9 (the lattice rows are padded and their points filtered exactly afterwards)."""
    c1, c2 = np.triu_indices(9, 1)
    umin, umax = np.empty(a.shape[0]), np.empty(a.shape[0])
    for s in range(0, a.shape[0], chunk):
        sa, s1, s2 = a[s : s + chunk], e1[s : s + chunk], e2[s : s + chunk]
        g = np.zeros((sa.shape[0], 9, 2))
        h = np.zeros((sa.shape[0], 9))
        g[:, 0, 0] = g[:, 1, 1] = -1.0  # u >= 0, w >= 0
        g[:, 2] = h[:, 2] = 1.0  # u + w <= 1
        g[:, 3:6, 0], g[:, 3:6, 1], h[:, 3:6] = s1, s2, hi - sa  # a + u e1 + w e2 <= hi
        g[:, 6:9], h[:, 6:9] = -g[:, 3:6], sa - lo  # ... >= lo
        g1, g2, h1, h2 = g[:, c1], g[:, c2], h[:, c1], h[:, c2]
        det = g1[..., 0] * g2[..., 1] - g1[..., 1] * g2[..., 0]
        ok = np.abs(det) > 1e-12 * np.linalg.norm(g1, axis=-1) * np.linalg.norm(g2, axis=-1)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            u = (h1 * g2[..., 1] - h2 * g1[..., 1]) / det
            w = (g1[..., 0] * h2 - g2[..., 0] * h1) / det
            resid = g[:, None, :, 0] * u[..., None] + g[:, None, :, 1] * w[..., None] - h[:, None, :]
        slack = 1e-9 * (np.abs(g).sum(axis=-1) + np.abs(h))
        ok &= np.all(resid <= slack[:, None, :], axis=-1)
        umin[s : s + chunk] = np.where(ok, u, np.inf).min(axis=1)
        umax[s : s + chunk] = np.where(ok, u, -np.inf).max(axis=1)
    return umin, umax


class _TooMany(Exception):
    """More surface samples than MAX_SURFACE_SAMPLES (args: the count reached)."""


def _box_rows(tri: np.ndarray, sel: np.ndarray, nsub: np.ndarray, lo, hi, budget: float):
    """The rows (constant i) of the lattices (``nsub`` steps) of triangles ``sel`` that may hold points in the box
    [lo, hi], each row's j range padded by one: (triangle ids, i, first j, count), int64. Raises _TooMany before
    allocating more than ``budget`` rows or points."""
    a = tri[sel, 0]
    e1, e2 = tri[sel, 1] - a, tri[sel, 2] - a
    nf = nsub[sel]
    umin, umax = _u_range(a, e1, e2, lo, hi)
    with np.errstate(invalid="ignore", over="ignore"):
        i0 = np.clip(np.floor(umin * nf) - 1.0, 0.0, nf + 1.0)
        i1 = np.clip(np.ceil(umax * nf) + 1.0, -1.0, nf)
    nrows = np.where(umin <= umax, np.maximum(i1 - i0 + 1.0, 0.0), 0.0)
    if float(nrows.sum()) > budget:
        raise _TooMany(float(nrows.sum()))
    nrows = nrows.astype(np.int64)
    r = np.repeat(np.arange(sel.size), nrows)
    i = i0.astype(np.int64)[r] + (np.arange(r.size) - np.repeat(np.cumsum(nrows) - nrows, nrows))
    n = nsub[sel].astype(np.int64)[r]
    u = i / n
    # each row's w range: lo <= a + u e1 + w e2 <= hi on every axis, 0 <= w <= 1 - u
    blo = lo - a[r] - u[:, None] * e1[r]
    bhi = hi - a[r] - u[:, None] * e1[r]
    d = e2[r]
    slack = 1e-9 * (np.abs(lo) + np.abs(hi) + np.abs(a[r]) + np.abs(e1[r]))
    flat_ok = (blo <= slack) & (bhi >= -slack)  # rows along which an axis does not change (e2 = 0 there)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        q1, q2 = blo / d, bhi / d
        wlo = np.where(d > 0, q1, np.where(d < 0, q2, np.where(flat_ok, -np.inf, np.inf))).max(axis=1)
        whi = np.where(d > 0, q2, np.where(d < 0, q1, np.where(flat_ok, np.inf, -np.inf))).min(axis=1)
        j0 = np.clip(np.floor(np.maximum(wlo, 0.0) * n) - 1.0, 0.0, n + 1.0)
        j1 = np.clip(np.ceil(np.minimum(whi, 1.0 - u) * n) + 1.0, -1.0, n - i)
    count = np.maximum(j1 - j0 + 1.0, 0.0)
    if float(count.sum()) > budget:
        raise _TooMany(float(count.sum()))
    keep = count > 0
    return sel[r[keep]], i[keep], j0[keep].astype(np.int64), count[keep].astype(np.int64)


def _row_points(tri: np.ndarray, nsub: np.ndarray, rows, chunk: int = 1 << 20):
    """The lattice points of ``rows`` (:func:`_box_rows`), in blocks of about ``chunk``: (points, triangle ids),
    computed as :func:`_lattice` computes them (the same floating-point operations, so the same points)."""
    tid, i, j0, count = rows
    ends = np.cumsum(count)
    cuts = np.concatenate(
        [[0], np.searchsorted(ends, np.arange(chunk, int(ends[-1]) if ends.size else 0, chunk)), [tid.size]]
    )
    for b0, b1 in zip(cuts[:-1], cuts[1:], strict=True):
        if b1 <= b0:
            continue
        c = count[b0:b1]
        r = np.repeat(np.arange(b1 - b0), c)
        t = tid[b0:b1][r]
        j = j0[b0:b1][r] + (np.arange(r.size) - np.repeat(np.cumsum(c) - c, c))
        n = nsub[t].astype(np.int64)
        u, w = i[b0:b1][r] / n, j / n
        a = tri[t, 0]
        yield a + u[:, None] * (tri[t, 1] - a) + w[:, None] * (tri[t, 2] - a), t


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
        if not self.sample_spacing > 0:
            raise ValueError(f"the mesh's sample spacing must be > 0, got {sample_spacing}")
        self.candidates = int(candidates)
        self.source = None
        """The file the mesh was read from (:func:`load_mesh`), named in messages."""
        tri = self.vertices[self.faces]
        self._tri = tri
        edge, self._nsub, total = _steps(tri, self.sample_spacing)
        if not float(np.max(self._nsub)) <= MAX_EDGE_SPACINGS:  # also catches inf and NaN
            raise ValueError(
                f"sampling the surface every {self.sample_spacing:.3g} m (dx/4 in a scene): its longest edge, "
                f"{float(np.max(edge)):.3g} m, is more than {MAX_EDGE_SPACINGS:.3g} spacings, far larger than any "
                "domain at this dx (a mistake of units?); use a coarser dx, or a mesh clipped to the domain"
            )
        self._lazy = None  # (lo, hi, KD-tree, triangle of each sample): the samples for the box lo..hi
        self._samples = self._sample_tri = self._tree = None
        if total <= EAGER_SURFACE_SAMPLES:  # the whole surface, now
            self._samples, self._sample_tri = _lattice(tri, self._nsub.astype(np.int64), np.arange(len(tri)))
            self._tree = cKDTree(self._samples)
        # inside test: triangles projected on (y, z)
        self._yz_lo, self._yz_hi = tri[:, :, 1:].min(axis=1), tri[:, :, 1:].max(axis=1)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self._lo.copy(), self._hi.copy()

    def transformed_bounds(
        self, scale: float, rotation: np.ndarray, translation: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The box of the moved vertices (exact: the solid lies in their convex hull, which reaches them), not
        of the moved corners of :meth:`bounds`, which is up to √3 times larger (a ball turned 45°)."""
        rot = np.asarray(rotation, dtype=np.float64)
        lo, hi = np.empty(3), np.empty(3)
        for i in range(3):  # one axis at a time: no (V, 3) copy of a large mesh
            w = self.vertices @ (scale * rot[i])
            lo[i], hi[i] = w.min() + translation[i], w.max() + translation[i]
        return lo, hi

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
        if not hit.any():  # candidate triangles near the rays, none crossed (points beside or above a height field)
            return np.zeros(p.shape[0], np.int64)
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
        """Unsigned distance (N,) to the surface.

        A mesh sampled lazily (more than :data:`EAGER_SURFACE_SAMPLES` samples in all) is sampled here, for the
        box of the points (kept, and grown by half its size along an axis the points leave it by): within
        :data:`REGION_MARGIN` spacings of the box at the sample spacing, exactly as the whole surface would be,
        then in shells of twice the margin and twice the spacing each. So a point whose candidate samples lie
        within the margin (one within about 4 cells of the surface in a scene) gets what the whole surface
        would give, and any other, at a distance d > m·2**(k-1) with its closest point in shell k, a distance
        too large by at most a sample lattice's covering radius there and the finer ones', 1.16 spacings·2**k
        < 0.15 d (zero when the closest triangle is a candidate, as usual); the samples cost the surface near
        the box, not the whole mesh."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.empty(p.shape[0])
        if p.shape[0] == 0:
            return out
        tree, sample_tri = self._search(p)
        k = min(self.candidates, tree.n)
        for s in range(0, p.shape[0], chunk):
            q = p[s : s + chunk]
            _, idx = tree.query(q, k=k)
            idx = idx.reshape(q.shape[0], -1)
            tri = sample_tri[idx]  # (n, k) candidate triangles (with repeats)
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

    # -------------------------------------------------------------------------------------- lazy sampling
    def _search(self, p: np.ndarray) -> tuple[cKDTree, np.ndarray]:
        """The KD-tree of samples (and their triangles) that serves the points p: the whole surface's, or the
        samples for a box holding p's finite points (built, or rebuilt grown, when p leaves the last one)."""
        if self._tree is not None:
            return self._tree, self._sample_tri
        state = self._lazy
        q = p[np.isfinite(p).all(axis=1)]
        if q.shape[0] == 0:
            if state is not None:
                return state[2], state[3]
            qlo = qhi = 0.5 * (self._lo + self._hi)
        else:
            qlo, qhi = q.min(axis=0), q.max(axis=0)
        if state is not None:
            lo, hi = state[0], state[1]
            if np.all(qlo >= lo) and np.all(qhi <= hi):
                return state[2], state[3]
            ulo, uhi = np.minimum(lo, qlo), np.maximum(hi, qhi)
            grow = np.maximum(0.5 * (uhi - ulo), REGION_MARGIN * self.sample_spacing)
            qlo, qhi = np.where(qlo < lo, ulo - grow, ulo), np.where(qhi > hi, uhi + grow, uhi)
        points, ids = self._region_samples(qlo, qhi)
        tree = cKDTree(points)
        self._lazy = (qlo, qhi, tree, ids)
        return tree, ids

    def _region_samples(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Samples for points in the box [lo, hi]: level 0 covers the box grown by the margin m (REGION_MARGIN
        spacings) with the whole surface's lattice (the same points); level k >= 1 covers the box grown by
        m 2**k less level k-1's box, on lattices of spacing 2**k times the sample spacing; the last level holds
        the whole mesh. Every count is summed before any point is made; more than MAX_SURFACE_SAMPLES is refused
        (ValueError saying what to change)."""
        tri, s = self._tri, self.sample_spacing
        margin = REGION_MARGIN * s
        tlo, thi = tri.min(axis=1), tri.max(axis=1)
        pending = np.arange(len(tri))  # triangles not yet sampled to their last point
        plan, total, k = [], 0.0, 0
        inner = None
        try:
            while pending.size:
                blo, bhi = lo - margin * 2.0**k, hi + margin * 2.0**k
                meets = np.all((thi[pending] >= blo) & (tlo[pending] <= bhi), axis=1)
                if not meets.any():  # no surface in this shell
                    inner, k = (blo, bhi), k + 1
                    continue
                whole = np.all((tlo[pending] >= blo) & (thi[pending] <= bhi), axis=1)
                nsub = self._nsub if k == 0 else _steps(tri, s * 2.0**k)[1]
                if k == 0:  # the triangles within the box: all their lattice, as the whole surface has it
                    inside = pending[whole]
                    total += float(np.sum((nsub[inside] + 1.0) * (nsub[inside] + 2.0) / 2.0))
                    cut = pending[meets & ~whole]
                else:
                    inside, cut = pending[:0], pending[meets]
                if total > MAX_SURFACE_SAMPLES:
                    raise _TooMany(total)
                rows = _box_rows(tri, cut, nsub, blo, bhi, MAX_SURFACE_SAMPLES - total)
                total += float(np.sum(rows[3]))
                if total > MAX_SURFACE_SAMPLES:
                    raise _TooMany(total)
                done = np.zeros(len(tri), bool)  # triangles whose last points this level holds
                done[pending[whole]] = True
                plan.append((nsub, inside, rows, blo, bhi, inner, done))
                inner = (blo, bhi)
                pending = pending[~whole]
                k += 1
        except _TooMany as exc:
            name = f"{Path(self.source).name}: " if self.source else ""
            raise ValueError(
                f"{name}the mesh needs about {exc.args[0]:.3g} surface samples (at most {MAX_SURFACE_SAMPLES:.3g}) "
                f"every {s:.3g} m (dx/4 in a scene) near the points asked for: use a coarser dx, or a mesh clipped to "
                f"the domain (points in {np.round(lo, 4).tolist()} .. {np.round(hi, 4).tolist()} m)"
            ) from None
        points, ids = [np.zeros((0, 3))], [np.zeros(0, np.int64)]
        for nsub, inside, rows, blo, bhi, prev, done in plan:
            if inside.size:
                p, t = _lattice(tri, nsub.astype(np.int64), inside)
                points.append(p)
                ids.append(t)
            for p, t in _row_points(tri, nsub, rows):
                # a triangle's points in this box (all of them on its last level); not those a finer level holds
                keep = _in_box(p, blo, bhi) | done[t]
                if prev is not None:
                    keep &= ~_in_box(p, *prev)
                points.append(p[keep])
                ids.append(t[keep])
        points, ids = np.concatenate(points), np.concatenate(ids)
        if points.shape[0] == 0:  # not expected (every vertex is a lattice point); the centroids then
            points, ids = tri.mean(axis=1), np.arange(len(tri))
        return points, ids


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


def repeated_triangles(vertices: np.ndarray, faces: np.ndarray) -> int:
    """Triangles given more than once (the same three vertices, in any order or orientation, vertices welded as
    in :func:`open_edges`): a closed surface with its faces repeated still has every edge used an even number of
    times, but the parity test of :meth:`TriangleMesh.inside` then counts every crossing twice and finds no
    inside at all. The number of surplus copies."""
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    _, weld = np.unique(v, axis=0, return_inverse=True)
    f = np.sort(weld.reshape(-1)[np.asarray(faces, dtype=np.int64).reshape(-1, 3)], axis=1)
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2])]  # degenerate triangles enclose nothing
    if f.size == 0:
        return 0
    return int(len(f) - len(np.unique(f, axis=0)))


def load_mesh(path: str | Path, sample_spacing: float | None = None) -> TriangleMesh:
    """Read a closed triangle mesh (OBJ, STL, PLY, or any format meshio reads) as a :class:`TriangleMesh`.

    Raises ValueError for a file meshio cannot read (whatever meshio raised is in the message), a mesh without
    triangles or quads, non-finite vertices, an open surface (:func:`open_edges`) or repeated triangles
    (:func:`repeated_triangles`)."""
    import contextlib
    import io

    import meshio

    said = io.StringIO()  # meshio prints what it tries and fails; that belongs in the message, not the output
    try:
        with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
            mesh = meshio.read(str(path))
    except (Exception, SystemExit) as exc:  # ReadError, a format reader's error, or meshio's own sys.exit(1)
        why = " ".join(said.getvalue().split()) or f"{type(exc).__name__}: {exc}"
        obj = _read_obj(path) if Path(path).suffix.lower() == ".obj" else None
        if obj is None:
            raise ValueError(f"{path}: not a mesh meshio can read ({why[-300:]})") from None
        mesh = obj
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
    twice = repeated_triangles(points, faces)  # first: a repeated face also leaves edges of odd count
    if twice:
        raise ValueError(
            f"{path}: {twice} triangles are given more than once (the same three vertices): the inside test counts "
            "each crossing of a repeated face twice, so the solid would vanish; remove the duplicate faces (e.g. "
            "Blender's 'Merge by Distance' and 'Delete Loose', MeshLab's 'Remove Duplicate Faces')"
        )
    holes = open_edges(points, faces)
    if holes:
        raise ValueError(
            f"{path}: the mesh is not closed (watertight): {holes} edges belong to one triangle only (or an odd "
            "number), so its inside is undefined; close the holes (e.g. Blender's 'Fill Holes' or MeshLab's "
            "'Close Holes')"
        )
    mesh = TriangleMesh(points, faces, sample_spacing)
    mesh.source = str(path)
    return mesh


def _read_obj(path: str | Path):
    """A Wavefront OBJ's vertices and faces (as meshio's cell blocks) when meshio refuses the file: meshio 5
    refuses an OBJ with fewer texture coordinates (``vt``) than vertices, which is how Blender exports one (a
    probe, session 25). Reads ``v`` and ``f`` lines only; face entries ``i``, ``i/t``, ``i//n``, ``i/t/n``, with
    negative (relative) indices; polygons as fans. None when it finds no faces (the caller names meshio's error)."""
    from types import SimpleNamespace

    points: list[list[float]] = []
    tris: list[tuple[int, int, int]] = []
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            for line in fh:
                parts = line.split()
                if not parts:
                    continue
                if parts[0] == "v" and len(parts) >= 4:
                    points.append([float(v) for v in parts[1:4]])
                elif parts[0] == "f" and len(parts) >= 4:
                    idx = []
                    for entry in parts[1:]:
                        i = int(entry.split("/")[0])
                        idx.append(i - 1 if i > 0 else len(points) + i)
                    tris += [(idx[0], idx[k], idx[k + 1]) for k in range(1, len(idx) - 1)]
    except (OSError, ValueError):
        return None
    if not tris:
        return None
    return SimpleNamespace(
        points=np.asarray(points, np.float64).reshape(-1, 3),
        cells=[SimpleNamespace(type="triangle", data=np.asarray(tris, np.int64))],
    )


def load_heights(path: str | Path) -> np.ndarray:
    """A 2-D height grid from a .npy file or a whitespace/comma separated text file."""
    path = Path(path)
    try:
        if path.suffix.lower() == ".npy":
            h = np.load(path)  # allow_pickle is off: a pickled object is refused, not run
            if np.iscomplexobj(h):  # the cast below would drop the imaginary parts silently
                raise ValueError(f"complex numbers ({h.dtype}); heights are real")
            if h.dtype == bool:  # True/False read as 1 m and 0 m (a probe: taken, then a build that hung)
                raise ValueError("booleans (a mask?); heights are numbers in metres")
        else:
            with warnings.catch_warnings():  # an empty file: numpy's warning before our refusal below
                warnings.simplefilter("ignore", UserWarning)
                h = np.loadtxt(path, delimiter="," if path.suffix.lower() == ".csv" else None)
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
