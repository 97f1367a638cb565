// Periodic and outflow ghost layers of the padded LBM grid.
// Spec: couplekit/fluid/reference.py halo_copy / fold / outflow_fill / outflow_fix (backflow_correction).
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

// The periodic ghosts' populations an odd step exchanges with the interior, by boxes
// (couplekit.fluid.grid.periodic_link_boxes: rows x0, x1, y0, y1, z0, z1, ox, oy, oz, q of the inclusive box of
// ghost cells g whose direction q has g - c_q interior, image g + (ox, oy, oz)).  fold = 0, before the pull:
// F[q][g] = F[q][image] (only the populations the pull reads: a face ghost's 9); fold = 1, after the push:
// F[q][image] = F[q][g].  The (g, q) pairs of all boxes are distinct and so are their images' (ghost, image a
// bijection per direction), so the boxes may run in any order.  start: the prefix sums of the boxes' cell counts
// (size nbox + 1), n = start[nbox].  The host copies whole rows of x (the ghosts of the y and z faces: contiguous
// runs; a loop over the ghost list took all 27 populations of one ghost at a time for the copy and decoded every
// ghost's coordinates for the fold: 5.1 and 6.7 ms on one thread at 128^3, periodic; by boxes 2.2 and 2.2 ms).
KERNEL void lbm_halo_boxes(const long long n, ck_store_t* RESTRICT f /* size: 27 * (nx + 2) * (ny + 2) * (nz + 2) */,
                           const int* RESTRICT boxes /* size: 10 * nbox */, const long long* RESTRICT start /* size: nbox + 1 */,
                           const int nbox, const int fold, const int nx, const int ny, const int nz) {
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
    const long long N = pxy * (nz + 2);
#if CK_ON_GPU
    FOR_EACH(i, n) {
        int lo = 0, hi = nbox - 1;  // the box holding cell i: start[b] <= i < start[b + 1]
        while (lo < hi) {
            const int mid = (lo + hi + 1) / 2;
            if (start[mid] <= i) lo = mid; else hi = mid - 1;
        }
        const int* b = boxes + 10 * lo;
        const long long k = i - start[lo];
        const int w = b[1] - b[0] + 1, h = b[3] - b[2] + 1;
        const long long x = b[0] + k % w, y = b[2] + (k / w) % h, z = b[4] + k / ((long long)w * h);
        const long long g = x + px * y + pxy * z, s = g + b[6] + px * (long long)b[7] + pxy * b[8];
        const long long q = (long long)b[9] * N;
        if (fold) f[q + s] = f[q + g]; else f[q + g] = f[q + s];
    }
#else
    // every thread takes an equal share of each box's rows of x (y, z), walking them with running indices: the
    // x faces' boxes are rows of one cell, 16 k of them per direction at 128^3, where a division per row cost more
    // than the copy
    (void)n, (void)start;
    CK_PRAGMA(omp parallel) {
        const int nth = omp_get_num_threads(), tid = omp_get_thread_num();
        for (int bi = 0; bi < nbox; ++bi) {
            const int* b = boxes + 10 * bi;
            const int h = b[3] - b[2] + 1, rows = h * (b[5] - b[4] + 1), w = b[1] - b[0] + 1;
            const int r0 = (int)((long long)rows * tid / nth), r1 = (int)((long long)rows * (tid + 1) / nth);
            if (r0 >= r1) continue;
            const long long off = b[6] + px * (long long)b[7] + pxy * b[8];
            ck_store_t* fq = f + (long long)b[9] * N;
            int y = b[2] + r0 % h;
            long long g0 = b[0] + px * (long long)y + pxy * (b[4] + r0 / h);
            for (int r = r0; r < r1; ++r) {
                ck_store_t* dst = fq + (fold ? g0 + off : g0);
                const ck_store_t* src = fq + (fold ? g0 : g0 + off);
                if (w == 1) {
                    *dst = *src;
                } else {
                    CK_PRAGMA(omp simd)
                    for (int x = 0; x < w; ++x) dst[x] = src[x];
                }
                if (++y > b[3]) {  // the next row: y + 1, or the next z's first y
                    y = b[2];
                    g0 += pxy - px * (long long)(h - 1);
                } else {
                    g0 += px;
                }
            }
        }
    }
#endif
}

// The backflow an outflow ghost would send in (reference backflow_correction): m the momentum sum_j f*_j c_j of its
// interior cell, o its `outward` directions (couplekit.fluid.grid.outflow_directions: +-1 on each axis the ghost
// lies outside a non-periodic face, 0 elsewhere; layout (3, n)): du_a = -o_a min(o_a m_a, 0), the inward part of m
// on those axes.  Returns whether any is non-zero (then f*_j += 3 w_j c_j.du on the links into the domain;
// otherwise the zero-gradient copy stands as it is, bitwise).
DEVICE bool lbm_backflow_du(const float m[3], const int ox, const int oy, const int oz, float du[3]) {
    const int o[3] = {ox, oy, oz};
    bool any = false;
    for (int a = 0; a < 3; ++a) {
        const float on = (float)o[a] * m[a];
        du[a] = on < 0.f ? -(float)o[a] * on : 0.f;
        any = any || on < 0.f;
    }
    return any;
}

// The change 3 w_q c_q.du of the population f*_q an outflow ghost sends in (reference backflow_correction).
DEVICE float lbm_backflow_corr(const int q, const float du[3]) {
    return 3.f * W27[q] * ((float)CX27[q] * du[0] + (float)CY27[q] * du[1] + (float)CZ27[q] * du[2]);
}

// before an odd (pull) step, outflow ghosts: all 27 stored populations of ghost[i] copied from src[i] (zero
// gradient), then the backflow taken out (lbm_backflow_du): after an even step f*_j of src sits in slot opp(j), so
// m = -sum_k F[k] c_k over the copied slots and slot opp(j) takes f*_j + 3 w_j c_j.du (float32, CK_LOAD / CK_STORE);
// du (layout (3, n)) is kept for lbm_outflow_fix after the step
KERNEL void lbm_outflow_fill(const long long n, ck_store_t* RESTRICT f /* size: 27 * (nx + 2) * (ny + 2) * (nz + 2) */,
                             const long long* RESTRICT ghost /* size: n */, const long long* RESTRICT src /* size: n */,
                             const signed char* RESTRICT outward /* size: 3 * n */,
                             float* RESTRICT du_out /* size: 3 * n */, const int nx, const int ny, const int nz) {
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
    const long long N = pxy * (nz + 2);
    FOR_EACH(i, n) {
        const long long g = ghost[i], s = src[i];
        float m[3] = {0.f, 0.f, 0.f};
        for (int k = 0; k < 27; ++k) {
            f[k * N + g] = f[k * N + s];
            const float v = CK_LOAD(f, k * N + g, CK_F_SCALE);
            m[0] -= v * (float)CX27[k];
            m[1] -= v * (float)CY27[k];
            m[2] -= v * (float)CZ27[k];
        }
        float du[3];
        const bool back = lbm_backflow_du(m, outward[i], outward[n + i], outward[2 * n + i], du);
        du_out[i] = du[0], du_out[n + i] = du[1], du_out[2 * n + i] = du[2];
        if (!back) continue;
        for (int q = 1; q < 27; ++q) {
            const long long k = (long long)opposite_dir(q) * N + g;
            CK_STORE(f, k, CK_LOAD(f, k, CK_F_SCALE) + lbm_backflow_corr(q, du), CK_F_SCALE);
        }
    }
}

// after an odd (push) step, outflow ghosts: F[j][ghost + c_j] = F[j][src + c_j] for every direction j with
// ghost + c_j and src + c_j interior (the ghost "pushes" what its interior neighbour src pushed: zero gradient),
// plus 3 w_j c_j.du with the du lbm_outflow_fill found before the step (src's momentum cannot be summed from its
// neighbours' slots now: pushes toward walls stay at src).  No ghost writes a value another reads
// (ghost + c_j = src' + c_j would need ghost = src').
KERNEL void lbm_outflow_fix(const long long n, ck_store_t* RESTRICT f /* size: 27 * (nx + 2) * (ny + 2) * (nz + 2) */,
                            const long long* RESTRICT ghost /* size: n */, const long long* RESTRICT src /* size: n */,
                            const float* RESTRICT du_in /* size: 3 * n */, const int nx, const int ny,
                            const int nz) {
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
    const long long N = pxy * (nz + 2);
    FOR_EACH(i, n) {
        const long long g = ghost[i], s = src[i];
        const int gz = (int)(g / pxy), gy = (int)((g / px) % (ny + 2)), gx = (int)(g % px);
        const int sz = (int)(s / pxy), sy = (int)((s / px) % (ny + 2)), sx = (int)(s % px);
        const float du[3] = {du_in[i], du_in[n + i], du_in[2 * n + i]};
        const bool back = du[0] != 0.f || du[1] != 0.f || du[2] != 0.f;
        for (int q = 1; q < 27; ++q) {
            const int tx = gx + CX27[q], ty = gy + CY27[q], tz = gz + CZ27[q];
            const int ux = sx + CX27[q], uy = sy + CY27[q], uz = sz + CZ27[q];
            if (tx >= 1 && tx <= nx && ty >= 1 && ty <= ny && tz >= 1 && tz <= nz && ux >= 1 && ux <= nx &&
                uy >= 1 && uy <= ny && uz >= 1 && uz <= nz) {
                const long long t = q * N + tx + px * (long long)ty + pxy * tz;
                const long long u = q * N + ux + px * (long long)uy + pxy * uz;
                if (back) {
                    CK_STORE(f, t, CK_LOAD(f, u, CK_F_SCALE) + lbm_backflow_corr(q, du), CK_F_SCALE);
                } else {
                    f[t] = f[u];
                }
            }
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
