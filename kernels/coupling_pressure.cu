// The sand's terms of the mixture pressure update (paper 000 Eq. 39) folded into the fluid's kept population sum, in
// two parts (the lockstep step, schedulers/lockstep.py; SandFluidCoupler docstring):
//
//   coupling_pressure_slip_fluid   fsum <- [phi] u.grad eps / eps in every interior FLUID cell (0 outside the slip
//                                  cells): the part that reads the fluid velocity u of Eq. 13 (the last collision's),
//                                  run after this step's porosity and before lbm_momentum (want_fsum = 2) turns fsum
//                                  into sum_j (f_j - w_j) - that part; u's buffer then takes the exchange velocity
//                                  sum f c and, after the exchange, the force (one buffer for the three, 12 B per cell)
//   coupling_pressure_sand_terms   fsum <- fsum - ((1 - eps) div v + [phi] (0 - v).grad eps) / eps from the MPM grid
//                                  velocity, after G2P
//
// so that fsum = sum_j (f_j - w_j) - (the terms lbm_pressure_sand_terms would add from a stored sand velocity), to
// float32 round-off (the slip term's two parts are divided and subtracted apart), and the pressure update runs with
// use_fsum = 2, adding none.  Both through lbm_sand_terms.cuh.  Spec: couplekit/coupling/reference.py
// ReferenceOps.pressure_slip_fluid / pressure_sand_terms.
//
// Why: the lockstep step then keeps no padded copy of the sand velocity in lattice units (12 B per cell) and no
// force buffer besides the velocity's (12 B).  The sand velocity a stencil reads at padded cell (X, Y, Z) is the one
// coupling_sand_velocity would have stored there, grid_v[source node] * inv_velocity_scale (the same float
// product), the source node a ghost's periodic image or nearest interior node (coupling_source_index).  The host
// runs lbm_macro_pressure's row scheme (LBM_NB_BULK on rows whose 9-row neighbourhood is all fluid, except their
// tail vector; the GPU: LBM_NB_MASK).  Host rows with no sand around them (eps = 1 and v = 0 on the 9 rows: terms
// exactly 0) are left as they are by the second kernel and take 0 from the first.
// fsum: padded, its non-fluid cells left as they are; vel: the velocity of Eq. 13 the last collision wrote; eps: the
// porosity of this step (ghosts filled); slip_cells: the fluid's.
// variants: CK_TWO_PHASE=0,1
#include "common.cuh"
#include "lattice.cuh"
#include "lbm_core.cuh"
#include "lbm_sand_terms.cuh"
#include "coupling_fields.cuh"

#ifndef CK_TWO_PHASE
#define CK_TWO_PHASE 1
#endif

// host rows are processed in chunks of this many cells (a multiple of LBM_VEC): the chunk's 9 rows of the sand
// velocity, 3 components, live on the stack
#define CPL_P_CHUNK 256

KERNEL void coupling_pressure_sand_terms(
    const long long n, const float* RESTRICT grid_v /* size: 3 * nx * ny * nz */,
    const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
    const float* RESTRICT phi /* size >= 1 */, const float* RESTRICT eps /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
    const unsigned char* RESTRICT slip_cells /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
    float* RESTRICT fsum /* size: (nx + 2) * (ny + 2) * (nz + 2) */, const int nx, const int ny, const int nz,
    const int per_x, const int per_y, const int per_z, const float inv_velocity_scale) {
    const float* vel = nullptr;  // WITH_U = 0: the fluid velocity's part is coupling_pressure_slip_fluid's
    const long long ncell = (long long)nx * ny * nz;
#if CK_ON_GPU
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        const int px = CK_PER_ITEM(nx + 2);
        const long long pxy = (long long)px * (ny + 2);
        const long long N = pxy * (nz + 2);
        const long long c = (x + 1) + px * (long long)(y + 1) + pxy * (z + 1);
        if (flags[c] != FLAG_FLUID) continue;
        // the 27 sand velocities around c as a padded 3 x 3 x 3 block (strides 3, 9; centre 13) per component
        float sv[81];
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const long long node = coupling_source_index(x + 1 + dx, nx, per_x) +
                                           (long long)nx * (coupling_source_index(y + 1 + dy, ny, per_y) +
                                                            (long long)ny * coupling_source_index(z + 1 + dz, nz, per_z));
                    const int k = 13 + dx + 3 * dy + 9 * dz;
                    sv[k] = grid_v[node] * inv_velocity_scale;
                    sv[27 + k] = grid_v[ncell + node] * inv_velocity_scale;
                    sv[54 + k] = grid_v[2 * ncell + node] * inv_velocity_scale;
                }
        fsum[c] = fsum[c] - lbm_pressure_sand_terms<LBM_NB_MASK, CK_TWO_PHASE, 1, 0>(
                                c, flags, vel, phi, eps, px, pxy, N, sv, 13, 3, 9, 27, 0u, 0u, slip_cells);
    }
#else
    // host: lbm_macro_pressure's row scheme (the same rows, spans, chunks and tail vector, so the same stencil
    // mode per cell), the chunk's 9 rows of the sand velocity gathered from their source nodes first
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
    const long long N = pxy * (nz + 2);
    CK_PRAGMA(omp parallel for collapse(2) schedule(static))
    for (int z = 0; z < nz; ++z)
        for (int y = 0; y < ny; ++y) {
            const long long row = px * (long long)(y + 1) + pxy * (z + 1);
            int lo = 1, hi = nx;
            const bool bulk = lbm_rows_all_fluid(flags, row, 0, nx + 1, px, pxy);
            if (!bulk) lbm_row_fluid_span(flags, row, nx, lo, hi);
            if (lo > hi) continue;
            // the source node rows of the 9 rows around this one; no sand there and eps = 1: terms exactly 0
            long long src[9];
            unsigned int any = 0;
            for (int r = 0; r < 9; ++r) {  // r = (dy + 1) + 3 (dz + 1)
                const int dy = r % 3 - 1, dz = r / 3 - 1;
                src[r] = (long long)nx * (coupling_source_index(y + 1 + dy, ny, per_y) +
                                          (long long)ny * coupling_source_index(z + 1 + dz, nz, per_z));
                any |= ck_any_differs(eps + row + (long long)dy * px + (long long)dz * pxy, nx + 2, 1.f) |
                       ck_any_differs(grid_v + src[r], nx, 0.f) | ck_any_differs(grid_v + ncell + src[r], nx, 0.f) |
                       ck_any_differs(grid_v + 2 * ncell + src[r], nx, 0.f);
            }
            if (any == 0) continue;
            const int rem = lbm_row_tail(lo, hi);
            float sv[3 * 9 * (CPL_P_CHUNK + 2)];
            unsigned int masks[CPL_P_CHUNK], scratch[10 * (CPL_P_CHUNK + 2)], slipw[CPL_P_CHUNK];
            for (int x0 = lo; x0 <= hi;) {
                int len;
                long long c0;
                const int tail = lbm_row_chunk(x0, hi, rem, CPL_P_CHUNK, row, len, c0);
                // local rows of w = len + 2 cells (padded x from X0 - 1 to X0 + len): strides w, 3 w, 9 w
                const int X0 = (int)(c0 - row), w = len + 2;
                for (int r = 0; r < 9; ++r)
                    for (int d = 0; d < 3; ++d) {
                        const float* g = grid_v + d * ncell + src[r];
                        float* o = sv + d * 9 * w + r * w;
                        o[0] = g[coupling_source_index(X0 - 1, nx, per_x)] * inv_velocity_scale;
                        o[w - 1] = g[coupling_source_index(X0 + len, nx, per_x)] * inv_velocity_scale;
                        CK_SIMD_SHORT
                        for (int i = 1; i < w - 1; ++i) o[i] = g[X0 - 2 + i] * inv_velocity_scale;
                    }
                CK_SIMD_SHORT
                for (int i = 0; i < len; ++i) slipw[i] = slip_cells[c0 + i] != 0 ? 1u : 0u;
                if (bulk && !tail) {
                    CK_PRAGMA(omp simd)
                    for (int i = 0; i < len; ++i)
                        fsum[c0 + i] = fsum[c0 + i] - lbm_pressure_sand_terms<LBM_NB_BULK, CK_TWO_PHASE, 0, 0>(
                                                          c0 + i, flags, vel, phi, eps, px, pxy, N, sv, i + 1 + 4 * w,
                                                          w, 3 * w, 9 * w, LBM_FULL_MASK, slipw[i], slip_cells);
                    continue;
                }
                if (tail)
                    lbm_tail_masks(flags, c0, rem, px, pxy, masks, scratch);
                else
                    lbm_link_masks(flags, c0, len, px, pxy, masks, scratch);
                CK_PRAGMA(omp simd)
                for (int i = 0; i < len; ++i) {
                    const float t = lbm_pressure_sand_terms<LBM_NB_MASK, CK_TWO_PHASE, 0, 0>(
                        c0 + i, flags, vel, phi, eps, px, pxy, N, sv, i + 1 + 4 * w, w, 3 * w, 9 * w, masks[i],
                        slipw[i], slip_cells);
                    fsum[c0 + i] = ck_select(masks[i] & 1u, fsum[c0 + i] - t, fsum[c0 + i]);
                }
            }
        }
    (void)n;
#endif
}

// fsum <- the fluid velocity's part of Eq. 39's slip term, [phi] u.grad eps / eps (lbm_pressure_slip_fluid), in every
// interior FLUID cell: 0 outside the slip cells and, on the host, in rows with eps = 1 on their 9 rows; fsum's other
// cells are left as they are (p-bar's boundary values).  lbm_momentum (want_fsum = 2) then subtracts it from the
// population sum.  Host: coupling_pressure_sand_terms's rows, spans, chunks and stencil modes.
KERNEL void coupling_pressure_slip_fluid(const long long n,
                                         const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                         const float* RESTRICT vel /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
                                         const float* RESTRICT phi /* size >= 1 */,
                                         const float* RESTRICT eps /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                         const unsigned char* RESTRICT slip_cells /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                         float* RESTRICT fsum /* size: (nx + 2) * (ny + 2) * (nz + 2) */, const int nx,
                                         const int ny, const int nz) {
#if CK_ON_GPU
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        const int px = CK_PER_ITEM(nx + 2);
        const long long pxy = (long long)px * (ny + 2);
        const long long N = pxy * (nz + 2);
        const long long c = (x + 1) + px * (long long)(y + 1) + pxy * (z + 1);
        if (flags[c] != FLAG_FLUID) continue;
        fsum[c] = lbm_pressure_slip_fluid<LBM_NB_MASK, CK_TWO_PHASE, 1>(c, flags, vel, phi, eps, px, pxy, N, 0u, 0u,
                                                                        slip_cells);
    }
#else
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
    const long long N = pxy * (nz + 2);
    CK_PRAGMA(omp parallel for collapse(2) schedule(static))
    for (int z = 0; z < nz; ++z)
        for (int y = 0; y < ny; ++y) {
            const long long row = px * (long long)(y + 1) + pxy * (z + 1);
            int lo = 1, hi = nx;
            const bool bulk = lbm_rows_all_fluid(flags, row, 0, nx + 1, px, pxy);
            if (!bulk) lbm_row_fluid_span(flags, row, nx, lo, hi);
            if (lo > hi) continue;
            if (ck_rows_equal(eps, row, 0, nx + 1, px, pxy, 1.f)) {  // eps = 1 on the 9 rows: gradient exactly 0
                CK_SIMD_SHORT
                for (int x = lo; x <= hi; ++x) fsum[row + x] = flags[row + x] == FLAG_FLUID ? 0.f : fsum[row + x];
                continue;
            }
            const int rem = lbm_row_tail(lo, hi);
            unsigned int masks[CPL_P_CHUNK], scratch[10 * (CPL_P_CHUNK + 2)], slipw[CPL_P_CHUNK];
            for (int x0 = lo; x0 <= hi;) {
                int len;
                long long c0;
                const int tail = lbm_row_chunk(x0, hi, rem, CPL_P_CHUNK, row, len, c0);
                CK_SIMD_SHORT
                for (int i = 0; i < len; ++i) slipw[i] = slip_cells[c0 + i] != 0 ? 1u : 0u;
                if (bulk && !tail) {
                    CK_PRAGMA(omp simd)
                    for (int i = 0; i < len; ++i)
                        fsum[c0 + i] = lbm_pressure_slip_fluid<LBM_NB_BULK, CK_TWO_PHASE>(
                            c0 + i, flags, vel, phi, eps, px, pxy, N, LBM_FULL_MASK, slipw[i], slip_cells);
                    continue;
                }
                if (tail)
                    lbm_tail_masks(flags, c0, rem, px, pxy, masks, scratch);
                else
                    lbm_link_masks(flags, c0, len, px, pxy, masks, scratch);
                CK_PRAGMA(omp simd)
                for (int i = 0; i < len; ++i) {
                    const float t = lbm_pressure_slip_fluid<LBM_NB_MASK, CK_TWO_PHASE>(
                        c0 + i, flags, vel, phi, eps, px, pxy, N, masks[i], slipw[i], slip_cells);
                    fsum[c0 + i] = ck_select(masks[i] & 1u, t, fsum[c0 + i]);
                }
            }
        }
    (void)n;
#endif
}
