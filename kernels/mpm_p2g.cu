// MPM particle-to-grid transfer (paper 000 Eqs. 24, 25, 27; notes Sec. 1.2): one fused pass writing the
// node mass, the node momentum including the stress impulse (MLS-MPM "fused affine"), and the node sand
// volume.  Grid: the LBM lattice, node (i, j, k) at ((i + 1/2) dx, (j + 1/2) dx, (k + 1/2) dx), arrays
// (nz, ny, nx) / (3, nz, ny, nx), linear index x + nx*(y + ny*z).
//
//   m_i   = sum_p w_ip m_p
//   (mv)_i = sum_p w_ip [ m_p v_p + A_p (x_i - x_p) ],  A_p = m_p C_p - dt V_p (4/dx^2) tau_p
//   V_i   = sum_p w_ip V_p
//
// tau_p is the Kirchhoff stress (xx, yy, zz, yz, xz, xy) left by the previous G2P, V_p the initial particle
// volume (Eq. 27 with V^0 and tau = J sigma).
//
// The grid arrays are overwritten (no need to clear them first).
// Guard: a particle whose 3x3x3 stencil would leave the grid (x / dx outside [1, n - 1) on an axis), or whose
// position is not finite (NaN compares false), scatters nothing and is counted in *skipped: G2P keeps
// positions inside that band, so only a diverged state gets here, and without the guard a NaN position
// turned into a wild grid index (the host build wrote out of bounds and crashed with "double free").
// CUDA: float atomics straight into the grid (order-dependent round-off, as any GPU MPM).
// Host: deterministic, by tiles of particles (host_scatter.cuh; scratch sized by couplekit/backend/host_scatter.py): plain
// additions into the grid in one order for any thread count, so the result is bitwise reproducible whatever the
// number of threads.  (Until session 23 each thread scattered into a private grid of 5 floats per node, summed in
// thread order: 20 B per node per thread, and a result that changed with the thread count.)
// Define MPM_HOST_ATOMICS=1 to use `omp atomic` on the host instead (for benchmarking only:
// not reproducible).
// MPM_P2G_VOLUME=0: no node volume (grid_vol is a placeholder, never touched): when every particle has one density
// rho, V_i = m_i / rho, and the callers take it from the node mass (SandSolver.node_volume): 4 B per node and a
// fifth of the scatter's additions saved.
// variants: MPM_HOST_ATOMICS=0,1 MPM_P2G_VOLUME=0,1
#include "common.cuh"
#include "host_scatter.cuh"
#include "mpm_loops.cuh"

#ifndef MPM_HOST_ATOMICS
#define MPM_HOST_ATOMICS 0
#endif
#ifndef MPM_P2G_VOLUME
#define MPM_P2G_VOLUME 1
#endif

// Quadratic B-spline weights along one axis for grid coordinate X (node i at X = i); base node index.
DEVICE int mpm_bspline(const float X, float w[3], float& f) {
    const int base = (int)floorf(X - 0.5f);
    f = X - (float)base;  // in [0.5, 1.5)
    w[0] = 0.5f * (1.5f - f) * (1.5f - f);
    w[1] = 0.75f - (f - 1.f) * (f - 1.f);
    w[2] = 0.5f * (f - 0.5f) * (f - 0.5f);
    return base;
}

// grid coordinates of particle p (node i at i), and the guard: the whole stencil inside the grid, finite
#define MPM_P2G_GRID_COORDS \
    const float Xg = x[p] * inv_dx - 0.5f, Yg = x[np + p] * inv_dx - 0.5f, Zg = x[2 * np + p] * inv_dx - 0.5f;
#define MPM_P2G_INSIDE \
    (Xg >= 0.5f && Xg < (float)nx - 1.5f && Yg >= 0.5f && Yg < (float)ny - 1.5f && Zg >= 0.5f && Zg < (float)nz - 1.5f)
// After MPM_P2G_GRID_COORDS, for a particle inside: the per-particle quantities of the fused scatter, the affine
// matrix A_p (row-major) and m_p v_p - A_p x_p (relative to the stencil base node, in units of dx) so that the
// momentum a node receives is w * (mv0 + A dpos) with dpos = (node - base - f) dx.
#define MPM_P2G_PARTICLE_SETUP                                                                         \
    float wx[3], wy[3], wz[3], fx, fy, fz;                                                             \
    const int bx = mpm_bspline(Xg, wx, fx), by = mpm_bspline(Yg, wy, fy), bz = mpm_bspline(Zg, wz, fz); \
    const float mp = mass[p], vp = vol[p];                                                             \
    const float st = dt * vp * 4.f * inv_dx * inv_dx;                                                  \
    const float txx = tau[p], tyy = tau[np + p], tzz = tau[2 * np + p];                                \
    const float tyz = tau[3 * np + p], txz = tau[4 * np + p], txy = tau[5 * np + p];                   \
    const float A00 = mp * C[p] - st * txx, A01 = mp * C[np + p] - st * txy,                           \
                A02 = mp * C[2 * np + p] - st * txz;                                                   \
    const float A10 = mp * C[3 * np + p] - st * txy, A11 = mp * C[4 * np + p] - st * tyy,              \
                A12 = mp * C[5 * np + p] - st * tyz;                                                   \
    const float A20 = mp * C[6 * np + p] - st * txz, A21 = mp * C[7 * np + p] - st * tyz,              \
                A22 = mp * C[8 * np + p] - st * tzz;                                                   \
    const float mvx = mp * v[p], mvy = mp * v[np + p], mvz = mp * v[2 * np + p];

KERNEL void mpm_p2g(const long long n, const float* RESTRICT x, const float* RESTRICT v,
                    const float* RESTRICT C, const float* RESTRICT tau, const float* RESTRICT mass,
                    const float* RESTRICT vol, float* RESTRICT grid_m, float* RESTRICT grid_mv,
                    float* RESTRICT grid_vol, int* RESTRICT scratch, int* RESTRICT skipped /* size: 1 */,
                    const int nthreads, const int nx,
                    const int ny, const int nz, const float dx, const float dt) {
    const long long np = n;
    const long long ncell = (long long)nx * ny * nz;
    const float inv_dx = 1.f / dx;
#if CK_ON_GPU || MPM_HOST_ATOMICS
    // the caller clears the grid on CUDA / host-atomics builds (mpm_clear_grid)
    FOR_EACH(p, n) {
        MPM_P2G_GRID_COORDS
        if (!MPM_P2G_INSIDE) {
            atomic_add(skipped, 1);
            continue;
        }
        MPM_P2G_PARTICLE_SETUP
        for (int c = 0; c < 3; ++c) {
            const float dz = ((float)c - fz) * dx;
            const long long zoff = (long long)(bz + c) * ny;
            for (int b = 0; b < 3; ++b) {
                const float dy = ((float)b - fy) * dx;
                const float wyz = wy[b] * wz[c];
                const long long row = (long long)nx * (zoff + by + b);
                for (int a = 0; a < 3; ++a) {
                    const float ddx = ((float)a - fx) * dx;
                    const float w = wx[a] * wyz;
                    const long long i = row + bx + a;
                    atomic_add(&grid_m[i], w * mp);
                    atomic_add(&grid_mv[i], w * (mvx + A00 * ddx + A01 * dy + A02 * dz));
                    atomic_add(&grid_mv[ncell + i], w * (mvy + A10 * ddx + A11 * dy + A12 * dz));
                    atomic_add(&grid_mv[2 * ncell + i], w * (mvz + A20 * ddx + A21 * dy + A22 * dz));
#if MPM_P2G_VOLUME
                    atomic_add(&grid_vol[i], w * vp);
#endif
                }
            }
        }
    }
    (void)scratch;
    (void)nthreads;
#else
    // host: the tiles of host_scatter.cuh (one summation order for any thread count)
    // the node's fields side by side in the tile buffer: m, (mv)_x, (mv)_y, (mv)_z[, V]
    constexpr int NF = 4 + MPM_P2G_VOLUME;
    float* const grid[5] = {grid_m, grid_mv, grid_mv + ncell, grid_mv + 2 * ncell, grid_vol};
    host_scatter<NF>(
        np, nx, ny, nz, np > MPM_SERIAL_PARTICLES ? nthreads : 1, scratch, skipped, grid,
        [&](const long long p) -> long long {
            MPM_P2G_GRID_COORDS
            return MPM_P2G_INSIDE ? host_scatter_tile(Yg, Zg, ny) : -1;
        },
        [&](const long long p) { return host_scatter_base(x[p] * inv_dx - 0.5f); },
        [=](const long long p, auto row) {
            MPM_P2G_GRID_COORDS
            MPM_P2G_PARTICLE_SETUP
            for (int c = 0; c < 3; ++c) {
                const float dz = ((float)c - fz) * dx;
                for (int b = 0; b < 3; ++b) {
                    const float dy = ((float)b - fy) * dx;
                    const float wyz = wy[b] * wz[c];
                    const float bxv = mvx + A01 * dy + A02 * dz;
                    const float byv = mvy + A11 * dy + A12 * dz;
                    const float bzv = mvz + A21 * dy + A22 * dz;
                    float* RESTRICT gr = row(bz + c, by + b) + NF * bx;
                    for (int a = 0; a < 3; ++a) {
                        const float ddx = ((float)a - fx) * dx;
                        const float w = wx[a] * wyz;
                        gr[NF * a + 0] += w * mp;
                        gr[NF * a + 1] += w * (bxv + A00 * ddx);
                        gr[NF * a + 2] += w * (byv + A10 * ddx);
                        gr[NF * a + 3] += w * (bzv + A20 * ddx);
#if MPM_P2G_VOLUME
                        gr[NF * a + 4] += w * vp;
#endif
                    }
                }
            }
        });
#endif
}

// Zero the grid accumulators before an atomic P2G (CUDA, host-atomics build); n = ncell.
KERNEL void mpm_clear_grid(const long long n, float* RESTRICT grid_m, float* RESTRICT grid_mv,
                           float* RESTRICT grid_vol) {
    FOR_EACH(i, n) {
        grid_m[i] = 0.f;
        grid_mv[i] = 0.f;
        grid_mv[n + i] = 0.f;
        grid_mv[2 * n + i] = 0.f;
#if MPM_P2G_VOLUME
        grid_vol[i] = 0.f;
#else
        (void)grid_vol;
#endif
    }
}
