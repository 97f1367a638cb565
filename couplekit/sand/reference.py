"""NumPy reference of the sand solver's stages: the executable specification the kernels are tested against.

Written for clarity (float64, vectorised over particles / nodes, equations of paper 000 and of
notes/mpm-method.md in the comments); independent of the kernels: the SVD is LAPACK's, the scatter is
``np.add.at``.  Inputs and outputs are the solver's float32 arrays, updated in place like the kernels.

Conventions: grid node (i, j, k) sits at ((i + ½) dx, (j + ½) dx, (k + ½) dx); grid arrays (nz, ny, nx)
and (3, nz, ny, nx); particle arrays x, v (3, P), C, F (9, P) row-major (C[3a + b] = C_ab), tau (6, P)
as (xx, yy, zz, yz, xz, xy).
"""

from __future__ import annotations

import numpy as np

from .params import ConstitutiveModel, dp_alpha

__all__ = ["ReferenceOps", "bspline_weights", "signed_svd", "hencky_return_map"]

SIGMA_MIN = 1.0e-4  # |σ| clamp before ln (kernels/mpm_model.cuh)
_VOIGT = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))


def bspline_weights(X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quadratic B-spline stencil along one axis for grid coordinates X (node i at X = i).

    Returns base (int, lower node of the 3-node stencil), w (..., 3) weights and d (..., 3) = node − X in
    cells.  N(s) = 3/4 − s² for |s| < ½, ½(3/2 − |s|)² for ½ ≤ |s| < 3/2 (notes §1.1).
    """
    base = np.floor(X - 0.5).astype(np.int64)
    d = base[..., None] + np.arange(3) - X[..., None]
    s = np.abs(d)
    w = np.where(s < 0.5, 0.75 - s**2, np.where(s < 1.5, 0.5 * (1.5 - s) ** 2, 0.0))
    return base, w, d


def inside_grid(x: np.ndarray, dx: float, shape: tuple[int, int, int]) -> np.ndarray:
    """(P,) bool: the particle's 3×3×3 stencil lies inside the grid (x/dx − ½ in [½, n − 3/2) on every axis);
    False for a position that is not finite. Such a particle scatters and gathers nothing (kernels/mpm_p2g.cu,
    mpm_g2p.cu)."""
    nz, ny, nx = shape
    X = x.astype(np.float64) / dx - 0.5
    with np.errstate(invalid="ignore"):
        return np.all((X >= 0.5) & (X < np.array([nx, ny, nz], np.float64)[:, None] - 1.5), axis=0)


def _stencil(x: np.ndarray, dx: float, shape: tuple[int, int, int]):
    """Node linear indices (P, 27), weights w_ip (P, 27) and offsets x_i − x_p (P, 27, 3) of each particle.
    A particle outside the grid (:func:`inside_grid`) gets the stencil of node 1 and zero weights."""
    nz, ny, nx = shape
    ok = inside_grid(x, dx, shape)
    X = np.where(ok, x.astype(np.float64) / dx - 0.5, 1.0)  # grid coordinates (3, P)
    bases, ws, ds = zip(*(bspline_weights(X[a]) for a in range(3)), strict=True)
    a, b, c = np.meshgrid(np.arange(3), np.arange(3), np.arange(3), indexing="ij")
    a, b, c = a.ravel(), b.ravel(), c.ravel()  # 27 offsets (x, y, z)
    ix = bases[0][:, None] + a
    iy = bases[1][:, None] + b
    iz = bases[2][:, None] + c
    index = ix + nx * (iy + ny * iz)
    w = np.where(ok[:, None], ws[0][:, a] * ws[1][:, b] * ws[2][:, c], 0.0)
    offset = np.stack([ds[0][:, a], ds[1][:, b], ds[2][:, c]], axis=-1) * dx
    return index, w, offset


def _mat(a: np.ndarray) -> np.ndarray:
    """(9, P) row-major -> (P, 3, 3) float64."""
    return a.astype(np.float64).T.reshape(-1, 3, 3)


def _voigt_to_mat(t: np.ndarray) -> np.ndarray:
    out = np.empty((t.shape[1], 3, 3))
    for k, (i, j) in enumerate(_VOIGT):
        out[:, i, j] = out[:, j, i] = t[k]
    return out


def _mat_to_voigt(m: np.ndarray) -> np.ndarray:
    return np.stack([m[:, i, j] for i, j in _VOIGT])


def signed_svd(A: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A (P, 3, 3) = U diag(σ) Vᵀ with U, V rotations and σ3 carrying the sign of det A (LAPACK + sign fix)."""
    U, s, Vt = np.linalg.svd(A)
    V = np.swapaxes(Vt, -1, -2).copy()
    U = U.copy()
    s = s.copy()
    flip_u = np.linalg.det(U) < 0
    U[flip_u, :, 2] *= -1
    s[flip_u, 2] *= -1
    flip_v = np.linalg.det(V) < 0
    V[flip_v, :, 2] *= -1
    s[flip_v, 2] *= -1
    return U, s, V


def hencky_return_map(
    e: np.ndarray,
    vc: np.ndarray,
    alpha: np.ndarray,
    cohesion: np.ndarray,
    mu: float,
    lam: float,
    volume_correction: bool,
    keep: float = 1.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drucker–Prager projection of principal Hencky strains e (P, 3) (Klár et al. 2016 §7.3, Eq. 28).

    ``keep``: the fraction of the Case III return applied (Duvaut–Lions viscoplastic overstress,
    :meth:`~couplekit.sand.params.ConstitutiveModel.plastic_fraction`; 1 = rate-independent): the deviator
    is shrunk by keep·δγ, so that keep·δγ is also the plastic increment.

    Returns (e_new, dq, vc_new).  Cohesion moves the cone apex into tension by
    δ_c = c_C / (3 α (3λ + 2μ)) per principal strain; the volume correction (Tampubolon et al. 2017) adds
    v_c/3 before the projection and stores ln det F_trial − ln det F_new afterwards.
    """
    kappa3 = 3.0 * lam + 2.0 * mu
    dc = np.where((cohesion > 0) & (alpha > 0), cohesion / (3.0 * np.maximum(alpha, 1e-30) * kappa3), 0.0)
    shift = (vc / 3.0 if volume_correction else 0.0) - dc
    a = e + shift[:, None] if np.ndim(shift) else e + shift
    tr = a.sum(axis=1)
    dev = a - tr[:, None] / 3.0
    dnorm = np.linalg.norm(dev, axis=1)
    dgamma = dnorm + kappa3 / (2.0 * mu) * alpha * tr
    case2 = tr >= 0  # beyond the apex: stress-free
    case3 = ~case2 & (dgamma > 0)  # outside the cone: shrink the deviator onto it
    e_new = a.copy()
    e_new[case2] = 0.0
    k = np.where(case3, keep * dgamma / np.where(dnorm > 0, dnorm, 1.0), 0.0)
    e_new -= k[:, None] * dev * case3[:, None]
    # plastic increment (hardening): Case II removes the trial elastic strain about the apex, e − δ_c
    # (Klár's ‖ε‖_F; not ‖a‖, which also holds the stored volume-correction gain v_c/3 — no flow of this
    # step), Case III the deviatoric amount δγ
    dq = np.where(case2, np.linalg.norm(e - dc[:, None], axis=1), np.where(case3, keep * dgamma, 0.0))
    e_new += dc[:, None]
    vc_new = vc + e.sum(axis=1) - e_new.sum(axis=1) if volume_correction else vc
    return e_new, dq, vc_new


class ReferenceOps:
    """The sand stages in NumPy; same methods and arguments as :class:`couplekit.sand.kernel_ops.KernelOps`."""

    name = "numpy"
    deterministic = True

    # ------------------------------------------------------------------ P2G (Eqs. 24, 25, 27)
    def p2g(self, x, v, C, tau, mass, vol, grid_m, grid_mv, grid_vol, dx: float, dt: float) -> None:
        """Overwrite node mass, momentum (with the stress impulse) and sand volume from the particles (``grid_vol``
        None: no node volume, kernels/mpm_p2g.cu MPM_P2G_VOLUME=0)."""
        shape = grid_m.shape
        n = grid_m.size
        index, w, off = _stencil(x, dx, shape)
        m = mass.astype(np.float64)
        # A_p = m_p C_p − Δt V_p (4/dx²) τ_p  (APIC affine + MLS stress term = −Δt Σ V τ ∇w, Eq. 27)
        A = m[:, None, None] * _mat(C) - (dt * vol.astype(np.float64) * 4.0 / dx**2)[:, None, None] * _voigt_to_mat(tau)
        mv = m[:, None] * v.astype(np.float64).T  # (P, 3)
        node_mom = w[..., None] * (mv[:, None, :] + np.einsum("pab,pkb->pka", A, off))  # (P, 27, 3)
        flat = index.ravel()
        gm = np.zeros(n)
        np.add.at(gm, flat, (w * m[:, None]).ravel())  # m_i = Σ w m_p  (Eq. 24)
        gmv = np.zeros((3, n))
        for a in range(3):
            np.add.at(gmv[a], flat, node_mom[..., a].ravel())  # (mv)_i  (Eq. 24 + Δt 𝔽_e, Eq. 27)
        grid_m[...] = gm.reshape(shape)
        grid_mv[...] = gmv.reshape(grid_mv.shape)
        if grid_vol is not None:
            gvol = np.zeros(n)
            np.add.at(gvol, flat, (w * vol.astype(np.float64)[:, None]).ravel())  # Σ V_p w_ip  (Eq. 25)
            grid_vol[...] = gvol.reshape(shape)

    # ------------------------------------------------------------------ grid update (Eqs. 26, 29)
    def grid_update(
        self,
        grid_m,
        grid_mv,
        grid_v,
        dx: float,
        dt: float,
        gravity,
        bound: int,
        walls,
        colliders,
        ncolliders: int,
        sdf,
        has_sdf: int,
        sdf_params,
        sdf_friction=None,
    ) -> None:
        """v_i = (mv)_i/m_i + Δt g on nodes with mass (Eq. 29), then boundary conditions.  ``grid_v`` may be
        ``grid_mv`` itself (in place, as SandSolver does); the coupling's forces are already in ``grid_mv``.

        ``sdf_friction``: the SDF collider's Coulomb friction per node (nz, ny, nx), or None for its one friction
        ``sdf_params[1]``."""
        nz, ny, nx = grid_m.shape
        m = grid_m.astype(np.float64).ravel()
        has = m > 0
        inv = np.where(has, 1.0 / np.where(has, m, 1.0), 0.0)
        g = np.asarray(gravity, dtype=np.float64)
        mv = grid_mv.astype(np.float64).reshape(3, -1)
        vel = np.where(has, mv * inv + dt * g[:, None], 0.0).T  # (N, 3)  Eq. 29
        z, y, xx = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
        idx = {"x": xx.ravel(), "y": y.ravel(), "z": z.ravel()}
        size = {"x": nx, "y": ny, "z": nz}
        zero = np.zeros(3)
        for face, (axis, sign) in enumerate([("x", 1), ("x", -1), ("y", 1), ("y", -1), ("z", 1), ("z", -1)]):
            near = idx[axis] < bound if sign > 0 else idx[axis] >= size[axis] - bound
            sel = near & has
            normal = np.zeros(3)
            normal["xyz".index(axis)] = sign
            vel[sel] = _apply_bc(vel[sel], normal[None, :], int(walls[2 * face]), float(walls[2 * face + 1]), zero)
        pos = (np.stack([idx["x"], idx["y"], idx["z"]], axis=1) + 0.5) * dx
        table = np.asarray(colliders, dtype=np.float64).reshape(-1, 16)
        for k in range(ncolliders):
            c = table[k]
            phi, normal = _collider_sdf(c, pos)
            sel = (phi <= 0) & has
            r = pos[sel] - c[4:7]
            v_obj = c[10:13] + np.cross(c[13:16], r)
            vel[sel] = _apply_bc(vel[sel], normal[sel], int(c[1]), float(c[2]), v_obj)
        if has_sdf:
            phi = sdf.astype(np.float64)
            grads = []
            for ax, n_ax in ((2, nx), (1, ny), (0, nz)):
                hi = np.take(phi, np.minimum(np.arange(n_ax) + 1, n_ax - 1), axis=ax)
                lo = np.take(phi, np.maximum(np.arange(n_ax) - 1, 0), axis=ax)
                grads.append((hi - lo).ravel())
            gvec = np.stack(grads, axis=1)
            length = np.linalg.norm(gvec, axis=1)
            sel = (phi.ravel() <= 0) & has & (length > 0)
            normal = gvec[sel] / length[sel, None]
            p = np.asarray(sdf_params, dtype=np.float64)
            mu = float(p[1]) if sdf_friction is None else np.asarray(sdf_friction, dtype=np.float64).ravel()[sel]
            vel[sel] = _apply_bc(vel[sel], normal, int(p[0]), mu, p[2:5])
        grid_v[...] = vel.T.reshape(grid_v.shape)

    # ------------------------------------------------------------------ G2P, plasticity, advection (Eq. 30)
    def g2p(self, x, v, C, F, tau, q, vc, saturation, grid_v, dx: float, dt: float, model: ConstitutiveModel) -> None:
        """Gather v_p and C_p, update F, return-map, Kirchhoff stress, advect x_p (in place)."""
        nz, ny, nx = grid_v.shape[1:]
        index, w, off = _stencil(x, dx, (nz, ny, nx))
        gv = grid_v.astype(np.float64).reshape(3, -1)[:, index]  # (3, P, 27)
        v_new = np.einsum("pk,apk->pa", w, gv)  # v_p = Σ w_ip v_i  (Eq. 30)
        C_new = 4.0 / dx**2 * np.einsum("pk,apk,pkb->pab", w, gv, off)  # APIC: B_p D_p⁻¹, D_p = dx²/4 I
        lost = ~inside_grid(x, dx, (nz, ny, nx))  # outside the grid or not finite: stays visibly non-finite
        F_trial = np.einsum("pab,pbc->pac", np.eye(3) + dt * C_new, _mat(F))  # F_trial = (I + Δt ∇v) F
        F_trial[lost] = _mat(F)[lost]  # a lost particle's deformation is not updated (its v, C, x are NaN)
        v_new[lost] = np.nan
        C_new[lost] = np.nan
        F_new, tau_new, q_new, vc_new = _constitutive(F_trial, q, vc, saturation, model, model.plastic_fraction(dt))
        F[...] = F_new.reshape(-1, 9).T
        C[...] = C_new.reshape(-1, 9).T
        tau[...] = tau_new
        if q is not None:  # None: hardening off, no hardening state (not allocated)
            q[...] = q_new
        vc[...] = vc_new
        v[...] = v_new.T
        x_new = x.astype(np.float64) + dt * v_new.T  # x_p += Δt v_p
        for a, n_ax in enumerate((nx, ny, nz)):
            # [dx (1 + 1e-6), (n - 1) dx (1 − 1e-6)]: at x = dx itself the float32 position's x/dx − ½ falls just
            # under ½ and inside_grid took the particle for lost (kernels/mpm_g2p.cu mpm_clamp_axis)
            x_new[a] = np.clip(x_new[a], dx * (1.0 + 1e-6), (n_ax - 1.0) * dx * (1.0 - 1e-6))
        x[...] = x_new

    def sdf_project(self, x, sdf, dx: float, depth: float) -> None:
        """Particles where the trilinear interpolation d of the node SDF (nodes at (i + ½) dx) is below −``depth``
        move along its gradient to d = −depth, x_p −= (d + depth) ∇d/|∇d| (in place; positions only). Particles
        outside the nodes' hull or not finite stay. Why: kernels/mpm_sdf_project.cu."""
        nz, ny, nx = sdf.shape
        X = x.astype(np.float64)
        g = X / dx - 0.5  # grid coordinates (3, P)
        n = np.array([nx, ny, nz], np.float64)[:, None]
        with np.errstate(invalid="ignore"):
            ok = np.all((g >= 0.0) & (g <= n - 1.0), axis=0)
        g = np.where(ok, g, 0.0)
        c = np.minimum(np.floor(g), n - 2.0).astype(np.int64)  # the cell of nodes around the particle
        f = g - c
        s = sdf.astype(np.float64)
        corner = {
            (a, b, e): s[c[2] + e, c[1] + b, c[0] + a] for a in (0, 1) for b in (0, 1) for e in (0, 1)
        }  # fmt: skip
        wx = (1.0 - f[0], f[0])
        wy = (1.0 - f[1], f[1])
        wz = (1.0 - f[2], f[2])
        dwx, dwy, dwz = (-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0)
        d = sum(wx[a] * wy[b] * wz[e] * v for (a, b, e), v in corner.items())
        grad = np.stack(
            [
                sum(dwx[a] * wy[b] * wz[e] * v for (a, b, e), v in corner.items()),
                sum(wx[a] * dwy[b] * wz[e] * v for (a, b, e), v in corner.items()),
                sum(wx[a] * wy[b] * dwz[e] * v for (a, b, e), v in corner.items()),
            ]
        )
        length = np.sqrt((grad**2).sum(axis=0))
        move = ok & (d < -depth) & (length > 0.0)
        step = np.where(move, -(d + depth) / np.where(length > 0.0, length, 1.0), 0.0)
        x[...] = np.where(move, X + step * grad, x)

    # ------------------------------------------------------------------ constitutive pieces alone
    def svd3(self, A: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A (9, P) -> U (9, P), σ (3, P), V (9, P), signed SVD."""
        U, s, V = signed_svd(_mat(A))
        return (U.reshape(-1, 9).T.astype(np.float32), s.T.astype(np.float32), V.reshape(-1, 9).T.astype(np.float32))

    def constitutive(self, F, tau, q, vc, saturation, model: ConstitutiveModel, dt: float | None = None) -> None:
        """F_trial (9, P) -> elastic F after plasticity, tau (6, P), q, vc (in place); ``dt`` the step for the
        viscoplastic overstress (None: rate-independent)."""
        F_new, tau_new, q_new, vc_new = _constitutive(_mat(F), q, vc, saturation, model, model.plastic_fraction(dt))
        F[...] = F_new.reshape(-1, 9).T
        tau[...] = tau_new
        if q is not None:
            q[...] = q_new
        vc[...] = vc_new


def _constitutive(F_trial: np.ndarray, q, vc, saturation, model: ConstitutiveModel, keep: float = 1.0):
    """Hencky + Drucker–Prager on (P, 3, 3) trial F: (F_new, tau (6, P), q_new, vc_new); ``keep`` the fraction
    of the Case III return applied (:func:`hencky_return_map`).  ``q`` None (hardening
    off: φ_F = h0, the state is not kept) and ``saturation`` None (cohesion off) read as zeros."""
    U, s, V = signed_svd(F_trial)
    e = np.log(np.maximum(np.abs(s), SIGMA_MIN))  # Hencky strain in principal axes
    n = F_trial.shape[0]
    if q is None and model.hardening:
        raise ValueError("q (the hardening state) is required with hardening on")
    if saturation is None and model.cohesion:
        raise ValueError("saturation is required with cohesion on")
    q64 = np.zeros(n) if q is None else q.astype(np.float64)
    saturation = np.zeros(n) if saturation is None else saturation
    vc64 = vc.astype(np.float64)
    if model.plasticity:
        alpha = dp_alpha(model.friction_angle(q64))  # α from the hardening state before this step
        cohesion = model.cohesion_of(saturation)  # c_C(S_r,p), Eq. 28
        e, dq, vc64 = hencky_return_map(e, vc64, alpha, cohesion, model.mu, model.lam, model.volume_correction, keep)
        q64 = q64 + dq
        F_new = np.einsum("pab,pb,pcb->pac", U, np.exp(e), V)  # F = U exp(ε) Vᵀ
    else:
        F_new = F_trial
    # Kirchhoff stress τ = U (2μ ε + λ tr ε I) Uᵀ (Hencky)
    t = 2.0 * model.mu * e + model.lam * e.sum(axis=1, keepdims=True)
    tau = _mat_to_voigt(np.einsum("pab,pb,pcb->pac", U, t, U))
    return F_new, tau, q64, vc64


def _apply_bc(vel: np.ndarray, normal: np.ndarray, mode: int, mu, v_obj: np.ndarray) -> np.ndarray:
    """Sticky (0) / slip (1) / separate with Coulomb friction (2) on relative velocities (N, 3); ``mu`` one
    friction or one per row (N,)."""
    rel = vel - v_obj
    if mode == 0:
        return np.broadcast_to(v_obj, vel.shape).copy()
    vn = np.einsum("na,na->n", rel, np.broadcast_to(normal, rel.shape))
    act = np.ones_like(vn, dtype=bool) if mode == 1 else vn < 0
    t = rel - vn[:, None] * normal
    mu = np.asarray(mu, dtype=np.float64)
    if mode == 2 and np.any(mu > 0):
        vt = np.linalg.norm(t, axis=1)
        scale = np.where(vt > 0, np.maximum(0.0, 1.0 + mu * vn / np.where(vt > 0, vt, 1.0)), 0.0)
        t = t * np.where(mu > 0, scale, 1.0)[:, None]  # no friction: the kernel skips the scaling
    return v_obj + np.where(act[:, None], t, rel)


def _collider_sdf(c: np.ndarray, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance (negative inside the solid) and outward normal of a collider record at pos (N, 3)."""
    kind, inverted, centre, p = int(c[0]), c[3] != 0, c[4:7], c[7:10]
    r = pos - centre
    if kind == 0:  # half-space
        phi = r @ p
        normal = np.broadcast_to(p, r.shape).copy()
    elif kind == 1:  # sphere
        dist = np.linalg.norm(r, axis=1)
        phi = dist - p[0]
        normal = np.where(dist[:, None] > 0, r / np.where(dist > 0, dist, 1.0)[:, None], [0.0, 0.0, 1.0])
    elif kind == 2:  # axis-aligned box
        qv = np.abs(r) - p
        outside = np.maximum(qv, 0.0)
        out = np.linalg.norm(outside, axis=1)
        phi = out + np.minimum(qv.max(axis=1), 0.0)
        sign = np.where(r >= 0, 1.0, -1.0)
        face = np.zeros_like(r)
        am = np.argmax(qv, axis=1)  # first maximum, as the kernel's tie-break
        face[np.arange(len(r)), am] = sign[np.arange(len(r)), am]
        normal = np.where(out[:, None] > 0, sign * outside / np.where(out > 0, out, 1.0)[:, None], face)
    else:  # capped cylinder along y
        rr = np.hypot(r[:, 0], r[:, 2])
        qr, qh = rr - p[0], np.abs(r[:, 1]) - p[1]
        mr, mh = np.maximum(qr, 0), np.maximum(qh, 0)
        out = np.hypot(mr, mh)
        phi = out + np.minimum(np.maximum(qr, qh), 0)
        ux = np.where(rr > 0, r[:, 0] / np.where(rr > 0, rr, 1), 1.0)
        uz = np.where(rr > 0, r[:, 2] / np.where(rr > 0, rr, 1), 0.0)
        sy = np.where(r[:, 1] >= 0, 1.0, -1.0)
        safe = np.where(out > 0, out, 1.0)
        radial = qr >= qh
        normal = np.where(
            (out > 0)[:, None],
            np.stack([ux * mr / safe, sy * mh / safe, uz * mr / safe], axis=1),
            np.stack([np.where(radial, ux, 0), np.where(radial, 0, sy), np.where(radial, uz, 0)], axis=1),
        )
    if inverted:
        phi, normal = -phi, -normal
    return phi, normal
