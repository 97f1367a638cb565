// Periodic and outflow ghost layers of the padded LBM grid.
// Spec: couplekit/fluid/reference.py halo_copy / fold / outflow_fix.
// The populations are ck_store_t (common.cuh, CK_STORAGE_FP16): the copies move stored values unchanged; the
// wall links convert (CK_LOAD / CK_STORE) to add the moving wall's term in float32.
// variants: CK_STORAGE_FP16=0,1
#include "common.cuh"
#include "lattice.cuh"
#include "lbm_core.cuh"

// a[k*N + ghost[i]] = a[k*N + image[i]] for every component k < ncomp   (n = number of ghosts)
KERNEL void lbm_halo_copy(const long long n, float* RESTRICT a, const long long* RESTRICT ghost /* size: n */,
                          const long long* RESTRICT image /* size: n */, const int ncomp, const long long N) {
    FOR_EACH(i, n) {
        const long long g = ghost[i], s = image[i];
        for (int k = 0; k < ncomp; ++k) a[k * N + g] = a[k * N + s];
    }
}

// the same copy for a population array (f: ck_store_t, which is float unless CK_STORAGE_FP16)
KERNEL void lbm_halo_copy_pop(const long long n, ck_store_t* RESTRICT a, const long long* RESTRICT ghost /* size: n */,
                              const long long* RESTRICT image /* size: n */, const int ncomp, const long long N) {
    FOR_EACH(i, n) {
        const long long g = ghost[i], s = image[i];
        for (int k = 0; k < ncomp; ++k) a[k * N + g] = a[k * N + s];
    }
}

// out[i] = in[i] in the storage type (round to nearest even), back[i] = out[i] as float: the conversions of
// CK_STORE / CK_LOAD at scale 1 (tests/fluid/test_fp16_storage.py checks them against NumPy on every binary16)
KERNEL void lbm_store_convert(const long long n, const float* RESTRICT in /* size: n */,
                              ck_store_t* RESTRICT out /* size: n */, float* RESTRICT back /* size: n */) {
    FOR_EACH(i, n) {
        CK_STORE(out, i, in[i], 1.f);
        back[i] = CK_LOAD(out, i, 1.f);
    }
}

// the same through CK_STORE_SCALAR / CK_LOAD_SCALAR (the conversions of the loops the host runs scalar)
KERNEL void lbm_store_convert_scalar(const long long n, const float* RESTRICT in /* size: n */,
                                     ck_store_t* RESTRICT out /* size: n */, float* RESTRICT back /* size: n */) {
    FOR_EACH(i, n) {
        CK_STORE_SCALAR(out, i, in[i], 1.f);
        back[i] = CK_LOAD_SCALAR(out, i, 1.f);
    }
}

// after an odd (push) step: F[j][image] = F[j][ghost] when ghost - c_j is an interior cell
KERNEL void lbm_fold(const long long n, ck_store_t* RESTRICT f /* size: 27 * (nx + 2) * (ny + 2) * (nz + 2) */,
                     const long long* RESTRICT ghost /* size: n */, const long long* RESTRICT image /* size: n */, const int nx, const int ny, const int nz) {
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
    const long long N = pxy * (nz + 2);
    FOR_EACH(i, n) {
        const long long g = ghost[i], s = image[i];
        const int gz = (int)(g / pxy), gy = (int)((g / px) % (ny + 2)), gx = (int)(g % px);
        for (int q = 1; q < 27; ++q) {
            const int sx = gx - CX27[q], sy = gy - CY27[q], sz = gz - CZ27[q];
            if (sx >= 1 && sx <= nx && sy >= 1 && sy <= ny && sz >= 1 && sz <= nz) f[q * N + s] = f[q * N + g];
        }
    }
}

// after an odd (push) step, outflow ghosts: F[j][ghost + c_j] = F[j][src + c_j] for every direction j with
// ghost + c_j and src + c_j interior (the ghost "pushes" what its interior neighbour src pushed: zero gradient)
KERNEL void lbm_outflow_fix(const long long n, ck_store_t* RESTRICT f /* size: 27 * (nx + 2) * (ny + 2) * (nz + 2) */,
                            const long long* RESTRICT ghost /* size: n */, const long long* RESTRICT src /* size: n */, const int nx, const int ny, const int nz) {
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
    const long long N = pxy * (nz + 2);
    FOR_EACH(i, n) {
        const long long g = ghost[i], s = src[i];
        const int gz = (int)(g / pxy), gy = (int)((g / px) % (ny + 2)), gx = (int)(g % px);
        const int sz = (int)(s / pxy), sy = (int)((s / px) % (ny + 2)), sx = (int)(s % px);
        for (int q = 1; q < 27; ++q) {
            const int tx = gx + CX27[q], ty = gy + CY27[q], tz = gz + CZ27[q];
            const int ux = sx + CX27[q], uy = sy + CY27[q], uz = sz + CZ27[q];
            if (tx >= 1 && tx <= nx && ty >= 1 && ty <= ny && tz >= 1 && tz <= nz && ux >= 1 && ux <= nx &&
                uy >= 1 && uy <= ny && uz >= 1 && uz <= nz)
                f[q * N + tx + px * (long long)ty + pxy * tz] = f[q * N + ux + px * (long long)uy + pxy * uz];
        }
    }
}

// c_q.u_w of a bounce-back link (fluid cell c, wall / inflow cell w = c - c_q): the wall's velocity where the link
// crosses the wall.  A link from a ghost of one face (w in exactly one of the domain's ghost layers) crosses that
// face half-way between w and w', c's own ghost across the face (w' = w for the straight link), and takes the
// mean u_w = (u(w) + u(w')) / 2: a face's velocity is linear between ghost centres.  With the sending ghost's
// velocity alone a narrow outlet put part of its volume flux into the cells beside it through its diagonal links
// (a 2 x 2 outlet ~31 %, while the phase field's D3Q7 inflow puts all its water into the outlet's cells), and a
// water jet from a 2-cell outlet into air at 800:1 diverged at lattice speed 0.06 (docs/fluid-stability.md,
// "Water outlets at 800:1").  Where the face's velocity is uniform, u(w') = u(w) and the mean is exactly u(w);
// ghosts of two faces (edges, corners) and interior solid cells keep their own velocity (w' = w).  w' comes with
// the link list (`mate`, couplekit.fluid.grid.wall_link_mates, built once per flags array): decoding w into
// (x, y, z) here took three 64-bit divisions per link and call.
LBM_INLINE float lbm_link_wall_cu(const int q, const long long w, const long long v, const float* RESTRICT vel,
                                  const long long N) {
    const float cu_w = CX27[q] * vel[w] + CY27[q] * vel[N + w] + CZ27[q] * vel[2 * N + w];
    const float cu_v = CX27[q] * vel[v] + CY27[q] * vel[N + v] + CZ27[q] * vel[2 * N + v];
    return 0.5f * (cu_w + cu_v);
}

// before an odd step: for every wall link (fluid cell c, direction j, wall / inflow cell w = c - c_j) park the
// bounced population where the pull of c reads it: F[opp j][w] = F[j][c] + 6 w_j c_j.u_w  (n = link count)
KERNEL void lbm_wall_prefill(const long long n, ck_store_t* RESTRICT f /* size: 27 * (nx + 2) * (ny + 2) * (nz + 2) */,
                             const float* RESTRICT vel /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
                             const long long* RESTRICT cell /* size: n */, const int* RESTRICT dir /* size: n */,
                             const long long* RESTRICT mate /* size: n */, const int nx, const int ny,
                             const int nz) {
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
    const long long N = pxy * (nz + 2);
    FOR_EACH(i, n) {
        const long long c = cell[i];
        const int q = dir[i];
        const long long w = c - LBM_OFFSET(q, px, pxy);
        const float cu = lbm_link_wall_cu(q, w, mate[i], vel, N);
        CK_STORE(f, opposite_dir(q) * N + w, CK_LOAD(f, q * N + c, CK_F_SCALE) + 6.f * W27[q] * cu, CK_F_SCALE);
    }
}

// after an odd step: the population c pushed into the wall cell w = c - c_j (direction opp j) bounces back:
// F[j][c] = F[opp j][w] + 6 w_j c_j.u_w
KERNEL void lbm_wall_bounce(const long long n, ck_store_t* RESTRICT f /* size: 27 * (nx + 2) * (ny + 2) * (nz + 2) */,
                            const float* RESTRICT vel /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
                            const long long* RESTRICT cell /* size: n */, const int* RESTRICT dir /* size: n */,
                            const long long* RESTRICT mate /* size: n */, const int nx, const int ny,
                            const int nz) {
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
    const long long N = pxy * (nz + 2);
    FOR_EACH(i, n) {
        const long long c = cell[i];
        const int q = dir[i];
        const long long w = c - LBM_OFFSET(q, px, pxy);
        const float cu = lbm_link_wall_cu(q, w, mate[i], vel, N);
        CK_STORE(f, q * N + c, CK_LOAD(f, opposite_dir(q) * N + w, CK_F_SCALE) + 6.f * W27[q] * cu, CK_F_SCALE);
    }
}
