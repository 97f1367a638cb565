"""NumPy reference of the D3Q7 conservative Allen–Cahn phase field: the executable specification.

Written for clarity from the paper (000, §4.1 and §4.4, Eqs. 21–23 and 44–52) and
``shared/notes/lbm-method.md`` §1c/§1d, independently of ``kernels/phasefield.cu``; the kernel ops are
tested against it.  Computes in float64 and stores into the caller's float32 arrays.  Storage and
streaming convention: see :mod:`couplekit.fluid.phasefield`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..lattice import C7, C27, CS2, CS2_7, W7, W27
from .phasefield_layout import as_periodic, interior_shape, padded_shape

PAIRS = (1, 3, 5)
"""First member j of each opposite pair (j, j + 1) of D3Q7: d_{j+1} = -d_j."""


class _Links:
    """Flat padded index of every interior cell and of its neighbour along each d_q, and blocked links.

    Neighbours step out of the interior onto the ghost layer, except on periodic axes where they wrap;
    a link is blocked (bounce-back) when it ends on a wall ghost or in a solid cell.
    """

    def __init__(self, shape: Sequence[int], periodic: Sequence[bool], solid: np.ndarray):
        nz, ny, nx = shape
        NZ, NY, NX = padded_shape(shape)
        z, y, x = np.meshgrid(np.arange(1, nz + 1), np.arange(1, ny + 1), np.arange(1, nx + 1), indexing="ij")
        self.cell = (x + NX * (y + NY * z)).ravel()
        flat_solid = solid.reshape(-1).astype(bool)
        self.fluid = ~flat_solid[self.cell]
        self.neighbour = np.empty((7, self.cell.size), dtype=np.int64)
        self.blocked = np.zeros((7, self.cell.size), dtype=bool)
        for q in range(7):
            coords, wall = [], np.zeros(x.shape, dtype=bool)
            for c, n, p, d in zip((x, y, z), (nx, ny, nz), periodic, C7[q], strict=True):
                moved = c + d
                if p:
                    moved = (moved - 1) % n + 1  # wrap across the periodic boundary
                else:
                    wall |= (moved == 0) | (moved == n + 1)  # left the interior through a wall
                coords.append(moved)
            nb = (coords[0] + NX * (coords[1] + NY * coords[2])).ravel()
            self.neighbour[q] = nb
            self.blocked[q] = wall.ravel() | flat_solid[nb]


class PhaseFieldReferenceOps:
    """NumPy phase-field stages; same methods and signatures as :class:`PhaseFieldKernelOps`.

    ``periodic``: (x, y, z) periodicity (a non-periodic axis has no-flux walls at both ends);
    ``surface_tension``: whether :meth:`gradients` computes the chemical potential.
    """

    def __init__(self, periodic: bool | Sequence[bool] = True, surface_tension: bool = True):
        self.periodic = as_periodic(periodic)
        self.surface_tension = bool(surface_tension)
        self.xp = np

    # -------------------------------------------------------------------------------- storage convention
    def _links(self, solid: np.ndarray) -> _Links:
        return _Links(interior_shape(solid.shape), self.periodic, solid)

    @staticmethod
    def _slots(j: int, parity: int) -> tuple[int, int]:
        """(a, b): slot read from this cell and slot read from the neighbour along d_j (esoteric pull)."""
        return (j, j + 1) if parity % 2 == 1 else (j + 1, j)

    def _load(self, h: np.ndarray, links: _Links, parity: int) -> np.ndarray:
        """Pre-collision populations f_q (7, ncells) of every interior cell at step parity ``parity``."""
        H = h.reshape(7, -1)
        c = links.cell
        f = np.empty((7, c.size), dtype=np.float64)
        f[0] = H[0, c]
        for j in PAIRS:
            a, b = self._slots(j, parity)
            m = links.neighbour[j]
            # f_j arrives from the cell behind; behind a blocked link it is this cell's own f*_{j+1}
            f[j] = np.where(links.blocked[j + 1], H[b, c], H[a, c])
            # f_{j+1} arrives from m; across a blocked link it is this cell's own f*_j left in m
            f[j + 1] = np.where(links.blocked[j], H[a, m], H[b, m])
        return f

    def _store(self, h: np.ndarray, f: np.ndarray, links: _Links, parity: int, mask: np.ndarray) -> None:
        """Write post-collision f* of the cells in ``mask``: each value where its partner was read."""
        H = h.reshape(7, -1)
        c = links.cell[mask]
        H[0, c] = f[0, mask]
        for j in PAIRS:
            a, b = self._slots(j, parity)
            H[b, links.neighbour[j][mask]] = f[j, mask]
            H[a, c] = f[j + 1, mask]

    def _unload(self, h: np.ndarray, f: np.ndarray, links: _Links, parity: int, mask: np.ndarray) -> None:
        """Inverse of :meth:`_load`: write f so that loading at ``parity`` returns it."""
        H = h.reshape(7, -1)
        c = links.cell[mask]
        H[0, c] = f[0, mask]
        for j in PAIRS:
            a, b = self._slots(j, parity)
            own = np.where(links.blocked[j + 1][mask], b, a)
            H[own, c] = f[j, mask]
            other = np.where(links.blocked[j][mask], a, b)
            H[other, links.neighbour[j][mask]] = f[j + 1, mask]

    # ------------------------------------------------------------------------------------------- physics
    @staticmethod
    def _equilibrium(phi: np.ndarray, u: np.ndarray) -> np.ndarray:
        """h_k^eq = w_k phi (1 + d_k . u / cs^2), cs^2 = 1/4 (notes §1c); phi (n,), u (3, n) -> (7, n)."""
        return W7[:, None] * phi[None, :] * (1.0 + (C7.astype(np.float64) @ u) / CS2_7)

    def set_equilibrium(self, h, phi, u, solid, parity: int) -> None:
        """Fill h so that the populations of step ``parity`` are h^eq(phi, u) in every interior fluid cell."""
        links = self._links(solid)
        c = links.cell
        feq = self._equilibrium(phi.reshape(-1)[c].astype(np.float64), u.reshape(3, -1)[:, c].astype(np.float64))
        self._unload(h, feq.astype(np.float32), links, parity, links.fluid)

    def macroscopic(self, h, phi, solid, parity: int) -> None:
        """phi = sum_k h_k (Eq. 47) in the interior; ghost cells copy their image; solid cells get 0."""
        links = self._links(solid)
        f = self._load(h, links, parity)
        nz, ny, nx = interior_shape(solid.shape)
        values = np.where(links.fluid, f.sum(axis=0), 0.0).reshape(nz, ny, nx)
        # ghost layer: wrap on periodic axes, the nearest interior value on wall axes
        px, py, pz = self.periodic
        modes = ["wrap" if pz else "edge", "wrap" if py else "edge", "wrap" if px else "edge"]
        for axis, mode in enumerate(modes):
            width = [(0, 0)] * 3
            width[axis] = (1, 1)
            values = np.pad(values, width, mode=mode)
        phi[...] = values

    def gradients(self, phi, solid, grad, mu, beta: float, kappa: float) -> None:
        """grad phi (Eq. 21) and, with surface tension, the chemical potential mu (Eqs. 22–23).

        grad phi = sum_j 3 w_j c_j phi(x + c_j); lap phi = 6 sum_j w_j (phi(x + c_j) - phi(x));
        mu = 4 beta phi (phi - 1)(phi - 1/2) - kappa lap phi.  A solid neighbour takes the centre value.
        Interior cells; solid cells get 0.  ``mu`` must be None when surface tension is off.
        """
        if self.surface_tension == (mu is None):
            raise ValueError("mu must be an array exactly when the ops were built with surface_tension=True")
        p = phi.astype(np.float64)
        wall = solid.astype(bool)
        centre = p[1:-1, 1:-1, 1:-1]
        g = np.zeros((3, *centre.shape))
        lap = np.zeros(centre.shape)
        for cj, wj in zip(C27, W27, strict=True):
            dx, dy, dz = (int(v) for v in cj)
            sl = (
                slice(1 + dz, p.shape[0] - 1 + dz),
                slice(1 + dy, p.shape[1] - 1 + dy),
                slice(1 + dx, p.shape[2] - 1 + dx),
            )
            neighbour = np.where(wall[sl], centre, p[sl])
            g += (wj / CS2) * cj.astype(np.float64)[:, None, None, None] * neighbour  # Eq. 21
            lap += (2.0 / CS2) * wj * (neighbour - centre)  # Eq. 23
        inner_solid = wall[1:-1, 1:-1, 1:-1]
        grad[:, 1:-1, 1:-1, 1:-1] = np.where(inner_solid, 0.0, g)
        if mu is not None:
            chem = 4.0 * beta * centre * (centre - 1.0) * (centre - 0.5) - kappa * lap  # Eq. 22
            mu[1:-1, 1:-1, 1:-1] = np.where(inner_solid, 0.0, chem)

    def collide_stream(
        self, h, grad, u, source, solid, parity: int, mobility: float, width: float, source_scale: float = 1.0
    ) -> None:
        """One step of Eq. 48 with in-place (esoteric-pull) streaming and no-flux bounce-back.

        h*_k = h_k - omega (h_k - h_k^eq) + (1 - omega/2) H_k + S_k, omega = 1/(M/cs^2 + 1/2),
        H_k = w_k d_k . H, H = (4/W) phi (1 - phi) grad phi / |grad phi| (Eqs. 49–50),
        S_k = w_k gamma S_phi (Eq. 51, gamma = ``source_scale`` from Eq. 52).
        """
        links = self._links(solid)
        c = links.cell
        f = self._load(h, links, parity)
        phi = f.sum(axis=0)  # Eq. 47
        g = grad.reshape(3, -1)[:, c].astype(np.float64)
        norm = np.sqrt((g * g).sum(axis=0))
        # grad phi / |grad phi|, zero in the bulk (the kernel's threshold is |grad phi|^2 > 1e-12)
        normal = np.where(norm * norm > 1e-12, g / np.where(norm > 0, norm, 1.0), 0.0)
        H = (4.0 / width) * phi * (1.0 - phi) * normal  # Eq. 49
        H_k = W7[:, None] * (C7.astype(np.float64) @ H)  # Eq. 50
        S_k = W7[:, None] * (source_scale * source.reshape(-1)[c].astype(np.float64))[None, :]  # Eq. 51
        omega = 1.0 / (mobility / CS2_7 + 0.5)
        feq = self._equilibrium(phi, u.reshape(3, -1)[:, c].astype(np.float64))
        post = f - omega * (f - feq) + (1.0 - 0.5 * omega) * H_k + S_k  # Eq. 48
        self._store(h, post.astype(np.float32), links, parity, links.fluid)

    def volume_sums(self, phi, source, solid, eps=None) -> tuple[float, float]:
        """(V, sum S_phi) over interior fluid cells in float64: V = sum phi, or sum eps phi with ``eps``."""
        fluid = ~solid[1:-1, 1:-1, 1:-1].astype(bool)
        p = phi[1:-1, 1:-1, 1:-1].astype(np.float64)
        if eps is not None:
            p = p * eps[1:-1, 1:-1, 1:-1].astype(np.float64)
        s = source[1:-1, 1:-1, 1:-1].astype(np.float64)
        return float(p[fluid].sum()), float(s[fluid].sum())
