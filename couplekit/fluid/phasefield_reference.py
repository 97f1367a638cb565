"""NumPy reference of the D3Q7 conservative Allen–Cahn phase field: the executable specification.

Written for clarity from the paper (000, §4.1 and §4.4, Eqs. 21–23 and 44–52) and
``shared/notes/lbm-method.md`` §1c/§1d, independently of ``kernels/phasefield.cu``; the kernel ops are
tested against it.  Computes in float64 and stores into the caller's float32 arrays.  Storage and
streaming convention: see :mod:`couplekit.fluid.phasefield`.  An fp16-stored h (float16 array,
:mod:`couplekit.fluid.storage`) is decoded exactly to float64 for reading and written through a float64 copy
encoded once (round to nearest even), as the kernels' ``CK_STORAGE_FP16`` does.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..lattice import C7, C27, CS2, CS2_7, W7, W27
from .phasefield_layout import FLUID, INFLOW, OUTFLOW, WALL, as_periodic, interior_shape, padded_shape
from .storage import check_storage, decode_h, encode_h, round_h

OPP7 = np.array([0, 2, 1, 4, 3, 6, 5])
"""Opposite direction of each D3Q7 direction."""


class _Grid:
    """Flat padded index of every interior cell, of its wrapped neighbours c + d_q, and the cell flags."""

    def __init__(self, shape: Sequence[int], periodic: Sequence[bool], flags: np.ndarray):
        nz, ny, nx = shape
        NZ, NY, NX = padded_shape(shape)
        z, y, x = np.meshgrid(np.arange(1, nz + 1), np.arange(1, ny + 1), np.arange(1, nx + 1), indexing="ij")
        self.cell = (x + NX * (y + NY * z)).ravel()
        self.flags = flags.reshape(-1)
        self.fluid = self.flags[self.cell] == FLUID
        self.neighbour = np.empty((7, self.cell.size), dtype=np.int64)
        for q in range(7):
            moved = []
            for coord, size, per, d in zip((x, y, z), (nx, ny, nz), periodic, C7[q], strict=True):
                m = coord + d
                moved.append((m - 1) % size + 1 if per else m)  # wrap on periodic axes, else a ghost
            self.neighbour[q] = (moved[0] + NX * (moved[1] + NY * moved[2])).ravel()


def _feq(q, phi, u):
    """h_q^eq = w_q phi (1 + d_q . u / cs^2) for one direction q (arrays over cells)."""
    return W7[q] * phi * (1.0 + (C7[q].astype(np.float64) @ u) / CS2_7)


def _outflux(q, phi, u):
    """The advective flux 2 w_q φ max(d_q·u, 0) / c_s² = φ max(d_q·u, 0) an outflow link passes out along q (from
    the cell into the outflow ghost): the population the ghost returns along −q is the cell's own f*_q bounced
    back less this, so the link's net flux is φ d_q·u where the fluid leaves and 0 where it comes in (backflow), and
    none of the phase field's sharpening or diffusive flux crosses the face.

        Why (session 29): the former rule fed back the equilibrium w_q φ (1 − |d_q·u|/c_s²) of the cell, which let
        the sharpening term (1 − ω/2) w_q d_q·H and the non-equilibrium part of f*_q leave, but not return: where the
        air at an outflow face holds a little φ, H points from it towards the water and the face drew φ in from the
        ghost (a slab's ceiling +0.081 of 1440 units of water in 200 steps while only air left), and a water outlet
        in an outflow face delivered 1.08× its flux (docs/fluid-stability.md, 'The volume target at open faces')."""
    return 2.0 * W7[q] * phi * np.maximum(C7[q].astype(np.float64) @ u, 0.0) / CS2_7


def _inflow(q, phi_b, u_b):
    """The flux part 2 w_q phi_b d_q . u_b / cs^2 of an inflow link (q: from the inflow cell into the fluid): the
    entering population is the bounced-back one plus this, so the link's net flux is phi_b d_q . u_b."""
    return 2.0 * W7[q] * phi_b * (C7[q].astype(np.float64) @ u_b) / CS2_7


def _gradient_laplacian(phi: np.ndarray, flags: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """grad phi (Eq. 21), lap phi (Eq. 23) and phi itself on the interior, float64: only FLUID neighbours
    contribute their value, others the centre value (the kernels' pf_gradient_sums)."""
    p = phi.astype(np.float64)
    fluid = flags == FLUID
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
        neighbour = np.where(fluid[sl], p[sl], centre)
        g += (wj / CS2) * cj.astype(np.float64)[:, None, None, None] * neighbour  # Eq. 21
        lap += (2.0 / CS2) * wj * (neighbour - centre)  # Eq. 23
    return g, lap, centre


def trt_omega_plus(omega: float, trt_lambda: float) -> float:
    """Rate of the symmetric non-equilibrium of the two-relaxation-time collision: (1/omega - 1/2)(1/omega_plus
    - 1/2) = trt_lambda; omega itself (Eq. 48's single rate) when trt_lambda is 0."""
    if trt_lambda <= 0.0:
        return omega
    return 1.0 / (0.5 + trt_lambda / (1.0 / omega - 0.5))


class PhaseFieldReferenceOps:
    """NumPy phase-field stages; same methods and signatures as :class:`PhaseFieldKernelOps`.

    ``periodic``: (x, y, z) periodicity (the other faces are given by the ghost cells' flags); ``storage``:
    the storage the owner allocates h in (the stages follow the dtype of the h they are given);
    ``surface_tension``: whether :meth:`gradients` computes the chemical potential; ``source``: whether
    there is a source term S_φ (False: ``source`` is ``None`` and counts as 0).
    """

    def __init__(
        self,
        periodic: bool | Sequence[bool] = True,
        surface_tension: bool = True,
        source: bool = True,
        storage: str = "fp32",
    ):
        self.storage = check_storage(storage)  # what h arrays to allocate; the stages follow h's dtype
        self.periodic = as_periodic(periodic)
        self.surface_tension = bool(surface_tension)
        self.source = bool(source)
        self.xp = np

    def _source(self, source, flags) -> np.ndarray:
        if source is None:
            if self.source:
                raise ValueError("these phase-field ops were built with the source term: pass the S_phi array")
            return np.zeros(flags.shape, np.float32)
        return source

    # -------------------------------------------------------------------------------- storage convention
    def _grid(self, flags: np.ndarray) -> _Grid:
        return _Grid(interior_shape(flags.shape), self.periodic, flags)

    def _load(self, h, phi, u, grid: _Grid, parity: int) -> np.ndarray:
        """Pre-collision populations f_q (7, ncells) of every interior cell under the AA read rule."""
        H = decode_h(h).reshape(7, -1)
        P = phi.reshape(-1).astype(np.float64)
        U = u.reshape(3, -1).astype(np.float64)
        c = grid.cell
        if parity % 2 == 0:
            return H[:, c]  # even: natural order, purely local
        f = np.zeros((7, c.size))
        f[0] = H[0, c]
        outflow_rate = np.zeros(c.size)
        for q in range(1, 7):
            p = grid.neighbour[OPP7[q]]  # the upstream cell c - d_q
            kind = grid.flags[p]
            pulled = H[OPP7[q], p]  # AA pull
            bounced = H[q, c]  # own f*_{opp q} of the even step: bounce-back from a wall
            inflow = bounced + _inflow(q, P[p], U[:, p])  # bounce-back plus phi_b d_q . u_b of the inflow cell
            f[q] = np.select([kind == FLUID, kind == INFLOW], [pulled, inflow], bounced)  # WALL, OUTFLOW: bounced
            outflow_rate += np.where(kind == OUTFLOW, _outflux(OPP7[q], 1.0, U[:, c]), 0.0)
        # outflow links: bounced back less phi_c times their rates, phi_c the cell's own sum (phi_c = known - phi_c
        # rate), so that the load reads no stored phi
        phi_c = f.sum(axis=0) / (1.0 + outflow_rate)
        for q in range(1, 7):
            out = grid.flags[grid.neighbour[OPP7[q]]] == OUTFLOW
            f[q] = np.where(out, f[q] - _outflux(OPP7[q], phi_c, U[:, c]), f[q])
        return f

    def _store(self, h, phi, u, fstar: np.ndarray, grid: _Grid, parity: int) -> None:
        """Write post-collision f* (7, ncells) of the interior fluid cells under the AA write rule."""
        if h.dtype == np.float16:
            work = decode_h(h)
            self._store(work, phi, u, fstar, grid, parity)
            h[...] = encode_h(work, "fp16")
            return
        H = h.reshape(7, -1)
        P = phi.reshape(-1).astype(np.float64)
        U = u.reshape(3, -1).astype(np.float64)
        fluid = grid.fluid
        c = grid.cell[fluid]
        fs = fstar[:, fluid]
        if parity % 2 == 0:
            H[OPP7[:, None], c[None, :]] = fs  # even: reversed slots, local
            return
        H[0, c] = fs[0]
        phi_post = fs.sum(axis=0)
        for q in range(1, 7):
            m = grid.neighbour[q][fluid]  # the downstream cell c + d_q
            kind = grid.flags[m]
            qo = OPP7[q]
            push = kind == FLUID
            H[q, m[push]] = fs[q, push]  # AA push
            wall = kind == WALL
            H[qo, c[wall]] = fs[q, wall]  # bounce-back, read at the next even step
            inflow = kind == INFLOW
            H[qo, c[inflow]] = fs[q, inflow] + _inflow(qo, P[m[inflow]], U[:, m[inflow]])
            out = kind == OUTFLOW
            H[qo, c[out]] = fs[q, out] - _outflux(q, phi_post[out], U[:, c[out]])

    def _unload(self, h, feq: np.ndarray, grid: _Grid, parity: int, phi=None, u=None) -> None:
        """Write f (7, ncells) so that loading at ``parity`` returns it in every interior fluid cell (``phi``,
        ``u``: the inflow cells' and the fluid cells' values, needed at odd parity for the inflow and outflow
        links)."""
        if h.dtype == np.float16:
            work = decode_h(h)
            self._unload(work, feq, grid, parity, phi, u)
            h[...] = encode_h(work, "fp16")
            return
        H = h.reshape(7, -1)
        fluid = grid.fluid
        c = grid.cell[fluid]
        f = feq[:, fluid]
        if parity % 2 == 0:
            H[:, c] = f
            return
        H[0, c] = f[0]
        for q in range(1, 7):
            p = grid.neighbour[OPP7[q]][fluid]
            kind = grid.flags[p]
            H[OPP7[q], p[kind == FLUID]] = f[q, kind == FLUID]
            H[q, c[kind == WALL]] = f[q, kind == WALL]
            out = kind == OUTFLOW
            if out.any():
                H[q, c[out]] = f[q, out] + _outflux(OPP7[q], phi.reshape(-1)[c[out]], u.reshape(3, -1)[:, c[out]])
            inflow = kind == INFLOW
            if inflow.any():
                pb = phi.reshape(-1)[p[inflow]].astype(np.float64)
                ub = u.reshape(3, -1)[:, p[inflow]].astype(np.float64)
                H[q, c[inflow]] = f[q, inflow] - _inflow(q, pb, ub)

    # ------------------------------------------------------------------------------------------- physics
    def set_equilibrium(self, h, phi, u, flags, parity: int) -> None:
        """Fill h so that the populations of step ``parity`` are h^eq(phi, u) in every interior fluid cell."""
        grid = self._grid(flags)
        c = grid.cell
        P = phi.reshape(-1)[c].astype(np.float64)
        U = u.reshape(3, -1)[:, c].astype(np.float64)
        feq = np.stack([_feq(q, P, U) for q in range(7)])
        self._unload(h, feq.astype(np.float32), grid, parity, phi, u)

    def macroscopic(self, h, phi, u, flags, parity: int) -> None:
        """phi = sum_k h_k (Eq. 47) in interior fluid cells; see the kernel for ghost, wall and inflow cells.

        A ghost cell takes the value of its image (wrap on periodic axes, nearest interior cell otherwise);
        an interior WALL / OUTFLOW cell (or a ghost whose image is one) gets 0; INFLOW cells keep the phase
        value they carry.
        """
        grid = self._grid(flags)
        f = self._load(h, phi, u, grid, parity)
        nz, ny, nx = interior_shape(flags.shape)
        own = flags[1:-1, 1:-1, 1:-1]
        values = np.where(own == FLUID, f.sum(axis=0).reshape(nz, ny, nx), 0.0)
        values = np.where(own == INFLOW, phi[1:-1, 1:-1, 1:-1], values)
        # every padded cell takes the value of its image
        px, py, pz = self.periodic
        image = [
            (np.arange(n + 2) - 1) % n + 1 if per else np.clip(np.arange(n + 2), 1, n)
            for n, per in ((nz, pz), (ny, py), (nx, px))
        ]
        padded = values[np.ix_(image[0] - 1, image[1] - 1, image[2] - 1)]
        phi[...] = np.where(flags == INFLOW, phi, padded)

    def gradients(self, phi, flags, grad, mu, beta: float, kappa: float) -> None:
        """grad phi (Eq. 21) and, with surface tension, the chemical potential mu (Eqs. 22–23).

        grad phi = sum_j 3 w_j c_j phi(x + c_j); lap phi = 6 sum_j w_j (phi(x + c_j) - phi(x));
        mu = 4 beta phi (phi - 1)(phi - 1/2) - kappa lap phi.  Only FLUID neighbours contribute their
        value, others the centre value.  Interior cells; non-fluid cells get 0.  ``mu`` must be None
        when surface tension is off.
        """
        if self.surface_tension == (mu is None):
            raise ValueError("mu must be an array exactly when the ops were built with surface_tension=True")
        g, lap, centre = _gradient_laplacian(phi, flags)
        fluid = flags == FLUID
        not_fluid = ~fluid[1:-1, 1:-1, 1:-1]
        grad[:, 1:-1, 1:-1, 1:-1] = np.where(not_fluid, 0.0, g)
        if mu is not None:
            chem = 4.0 * beta * centre * (centre - 1.0) * (centre - 0.5) - kappa * lap  # Eq. 22
            mu[1:-1, 1:-1, 1:-1] = np.where(not_fluid, 0.0, chem)

    def collide_stream(
        self,
        h,
        phi,
        u,
        source,
        flags,
        parity: int,
        mobility: float,
        width: float,
        source_scale: float = 1.0,
        trt_lambda: float = 0.0,
    ) -> None:
        """One step of Eq. 48 with in-place (AA) streaming and the boundary rules of the flags.

        h*_k = h_k - omega (h_k - h_k^eq) + (1 - omega/2) H_k + S_k, omega = 1/(M/cs^2 + 1/2),
        H_k = w_k d_k . H, H = (4/W) phi (1 - phi) grad phi / |grad phi| (Eqs. 49–50),
        S_k = w_k gamma S_phi (Eq. 51, gamma = ``source_scale`` from Eq. 52).
        ``trt_lambda`` > 0: two relaxation times (TRT, Ginzburg 2005): of the non-equilibrium n = h - h^eq, the
        symmetric part (n_k + n_opp k)/2 of each pair relaxes at omega_plus (:func:`trt_omega_plus`), the
        antisymmetric part (which carries the flux, so M) at omega; 0 is Eq. 48's single rate.
        grad phi is that of ``phi`` (Eq. 21, as :meth:`gradients`), which is also the phase value of INFLOW cells.
        """
        grid = self._grid(flags)
        c = grid.cell
        source = self._source(source, flags)
        f = self._load(h, phi, u, grid, parity)
        phi_c = f.sum(axis=0)  # Eq. 47
        g = np.zeros((3,) + phi.shape)
        g[:, 1:-1, 1:-1, 1:-1] = _gradient_laplacian(phi, flags)[0]
        g = g.reshape(3, -1)[:, c]
        norm = np.sqrt((g * g).sum(axis=0))
        # grad phi / |grad phi|, zero in the bulk (the kernel's threshold is |grad phi|^2 > 1e-12)
        normal = np.where(norm * norm > 1e-12, g / np.where(norm > 0, norm, 1.0), 0.0)
        H = (4.0 / width) * phi_c * (1.0 - phi_c) * normal  # Eq. 49
        H_k = W7[:, None] * (C7.astype(np.float64) @ H)  # Eq. 50
        S_k = W7[:, None] * (source_scale * source.reshape(-1)[c].astype(np.float64))[None, :]  # Eq. 51
        omega = 1.0 / (mobility / CS2_7 + 0.5)
        U = u.reshape(3, -1)[:, c].astype(np.float64)
        feq = np.stack([_feq(q, phi_c, U) for q in range(7)])
        post = f - omega * (f - feq) + (1.0 - 0.5 * omega) * H_k + S_k  # Eq. 48
        if trt_lambda > 0.0:
            n = f - feq
            sym = 0.5 * (n + n[OPP7])
            sym[0] = n[0]  # the rest population is its own pair
            post -= (trt_omega_plus(omega, trt_lambda) - omega) * sym
        post = post.astype(np.float32).astype(np.float64)
        if h.dtype == np.float16:
            # as the kernel: the moving populations rounded to the storage first and the rest population from
            # the exact balance sum_k h*_k = sum_k h_k + S_phi, so that it takes their rounding
            post[1:] = round_h(post, "fp16")[1:]
            post[0] = f.sum(axis=0) + S_k.sum(axis=0) - post[1:].sum(axis=0)
        self._store(h, phi, u, post, grid, parity)

    def volume_sums(self, phi, source, flags, eps=None) -> tuple[float, float]:
        """(V, sum S_phi) over interior FLUID cells in float64: V = sum phi, or sum eps phi with ``eps``."""
        fluid = flags[1:-1, 1:-1, 1:-1] == FLUID
        p = phi[1:-1, 1:-1, 1:-1].astype(np.float64)
        if eps is not None:
            p = p * eps[1:-1, 1:-1, 1:-1].astype(np.float64)
        s = self._source(source, flags)[1:-1, 1:-1, 1:-1].astype(np.float64)
        return float(p[fluid].sum()), float(s[fluid].sum())

    def mixture_sums(self, phi, eps, source, flags) -> tuple[float, float]:
        """(Σ ε φ, Σ ε S_φ) over interior FLUID cells in float64 (Eq. 52's two sums in a mixture)."""
        return self.volume_sums(phi, source, flags, eps)[0], self.volume_sums(source, source, flags, eps)[0]
