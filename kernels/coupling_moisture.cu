// The water-retention model (paper 000 Sec. 4.5): its particle side, its node update, and the saturation that
// drives the sand's cohesion.  Spec: couplekit/coupling/reference.py ReferenceOps.bound_water_p2g / particle_moisture.
// Grid: the MPM grid (unpadded (nz, ny, nx), node (i, j, k) at ((i + 1/2) dx, ...)), quadratic B-splines
// N_i(x_p) exactly as the sand's transfers; x, V_p in SI (m, m^3), fractions dimensionless.
//
// coupling_bound_water_p2g:   R_i = (1 / V_cell) sum_p r_p V_p N_i(x_p)                       (Eq. 53)
//   CUDA: float atomics into `bound` (cleared first by coupling_clear).  Host: deterministic, by tiles of
//   particles (host_scatter.cuh; scratch sized by couplekit/backend/host_scatter.py), bitwise the same for any thread count.
// coupling_particle_moisture:  S_p = sum_i water_i N_i(x_p)                            (Eq. 59 / text after Eq. 28)
//   water_i = R'_i + eps_f,i phi_i (coupling_water; eps_f phi without retention) from the porosity (padded),
//   the phase field (padded; 1 single-phase, CK_TWO_PHASE=0) and the bound water R' of this step: not a stored
//   field (the fields it comes from are unchanged between coupling_fractions and this stage)
//   with retention (CK_RETENTION=1) also     r_p += sum_i (dR_i / eps_i) N_i(x_p)    (Eq. 58)
//   where eps_i = V_i / V_cell is the UNCLAMPED rasterised sand fraction (grid_vol): then
//   sum_p r_p V_p grows by exactly V_cell sum_i dR_i (partition of unity), i.e. bound water is conserved.
//   (With Eq. 25's clamped eps the particles would gain more water than the grid absorbed wherever the sand
//   is packed beyond eps_max.)  Call it with the positions of this step's P2G, before the sand's G2P moves
//   the particles.
//   Per-body retention (masked = 1): only retentive particles (retain_p = 1, else 0) gain bound water,
//   r_p += retain_p sum_i (dR_i / eps_r,i) N_i(x_p), eps_r,i the retentive sand's unclamped fraction
//   (coupling_bound_water_p2g with r_p = retain_p); then sum_p r_p V_p grows by V_cell sum_i dR_i again.
//
// The node side of retention (Eqs. 54-56, the phi-scaled uptake of Eq. 55): kernels/coupling_fractions.cu.
// variants: CK_RETENTION=0,1 CK_TWO_PHASE=0,1
#include "common.cuh"
#include "coupling_fields.cuh"
#include "host_scatter.cuh"

#ifndef CK_RETENTION
#define CK_RETENTION 0
#endif
#ifndef CK_TWO_PHASE
#define CK_TWO_PHASE 1
#endif

// Is the 3x3x3 stencil of a particle at grid coordinates (X, Y, Z) = x / dx - 1/2 inside the grid?  False for a
// position that is not finite: such a particle reads and writes nothing (P2G's rule, kernels/mpm_p2g.cu).
DEVICE bool coupling_inside(const float X, const float Y, const float Z, const int nx, const int ny, const int nz) {
    return X >= 0.5f && X < (float)nx - 1.5f && Y >= 0.5f && Y < (float)ny - 1.5f && Z >= 0.5f && Z < (float)nz - 1.5f;
}

DEVICE int coupling_bspline(const float X, float w[3]) {
    const int base = (int)floorf(X - 0.5f);
    const float f = X - (float)base;  // in [0.5, 1.5)
    w[0] = 0.5f * (1.5f - f) * (1.5f - f);
    w[1] = 0.75f - (f - 1.f) * (f - 1.f);
    w[2] = 0.5f * (f - 0.5f) * (f - 0.5f);
    return base;
}

// n = number of particles.  On CUDA `bound` must be zero on entry; on the host it is overwritten.
KERNEL void coupling_bound_water_p2g(const long long n, const float* RESTRICT x /* size: 3 * n */,
                                     const float* RESTRICT r /* size: n */, const float* RESTRICT vol /* size: n */,
                                     float* RESTRICT bound /* size: nx * ny * nz */,
                                     int* RESTRICT scratch /* size >= 1 */, const int nthreads, const int nx,
                                     const int ny, const int nz, const float dx) {
    const long long np = n;
    const long long ncell = (long long)nx * ny * nz;
    const float inv_dx = 1.f / dx;
    const float inv_cell = inv_dx * inv_dx * inv_dx;
#if CK_ON_GPU
    FOR_EACH(p, n) {
        const float X = x[p] * inv_dx - 0.5f, Y = x[np + p] * inv_dx - 0.5f, Z = x[2 * np + p] * inv_dx - 0.5f;
        if (!coupling_inside(X, Y, Z, nx, ny, nz)) continue;
        float wx[3], wy[3], wz[3];
        const int bx = coupling_bspline(X, wx);
        const int by = coupling_bspline(Y, wy);
        const int bz = coupling_bspline(Z, wz);
        const float q = r[p] * vol[p] * inv_cell;
        for (int c = 0; c < 3; ++c)
            for (int b = 0; b < 3; ++b) {
                const long long row = (long long)nx * ((long long)(by + b) + (long long)ny * (bz + c)) + bx;
                const float wyz = q * wy[b] * wz[c];
                for (int a = 0; a < 3; ++a) atomic_add(&bound[row + a], wx[a] * wyz);
            }
    }
    (void)scratch;
    (void)nthreads;
    (void)ncell;
#else
    // host: the tiles of host_scatter.cuh (one summation order for any thread count)
    float* const grid[1] = {bound};
    (void)ncell;
    host_scatter<1>(
        np, nx, ny, nz, nthreads, scratch, nullptr, grid,
        [&](const long long p) -> long long {
            const float Y = x[np + p] * inv_dx - 0.5f, Z = x[2 * np + p] * inv_dx - 0.5f;
            return coupling_inside(x[p] * inv_dx - 0.5f, Y, Z, nx, ny, nz) ? host_scatter_tile(Y, Z, ny) : -1;
        },
        [&](const long long p) { return host_scatter_base(x[p] * inv_dx - 0.5f); },
        [=](const long long p, auto row) {
            const float X = x[p] * inv_dx - 0.5f, Y = x[np + p] * inv_dx - 0.5f, Z = x[2 * np + p] * inv_dx - 0.5f;
            float wx[3], wy[3], wz[3];
            const int bx = coupling_bspline(X, wx);
            const int by = coupling_bspline(Y, wy);
            const int bz = coupling_bspline(Z, wz);
            const float q = r[p] * vol[p] * inv_cell;
            for (int c = 0; c < 3; ++c)
                for (int b = 0; b < 3; ++b) {
                    float* RESTRICT gr = row(bz + c, by + b) + bx;
                    const float wyz = q * wy[b] * wz[c];
                    for (int a = 0; a < 3; ++a) gr[a] += wx[a] * wyz;
                }
        });
#endif
}

// n = number of entries of a: a := 0 (before an atomic scatter on CUDA).
KERNEL void coupling_clear(const long long n, float* RESTRICT a /* size: n */) {
    FOR_EACH(i, n) a[i] = 0.f;
}

// n = number of particles.  Without retention r, bound, d_bound, grid_vol, retentive, retain are not used (pass
// 1-element arrays), nor phi single-phase; retentive and retain are read only when masked.  The node sand volume
// is V_i = volume_scale grid_vol[i] (SandSolver.node_volume: the P2G's volume and 1, or the node mass and 1 / rho).
KERNEL void coupling_particle_moisture(const long long n, const float* RESTRICT x /* size: 3 * n */,
                                       float* RESTRICT r /* size >= 1 */, float* RESTRICT saturation /* size: n */,
                                       const float* RESTRICT eps_fluid /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                       const float* RESTRICT phi /* size >= 1 */,
                                       const float* RESTRICT bound /* size >= 1 */,
                                       const float* RESTRICT d_bound /* size >= 1 */,
                                       const float* RESTRICT grid_vol /* size >= 1 */,
                                       const float* RESTRICT retentive /* size >= 1 */,
                                       const float* RESTRICT retain /* size >= 1 */, const int nx, const int ny,
                                       const int nz, const float dx, const float volume_scale, const int masked) {
    const long long np = n;
    const float inv_dx = 1.f / dx;
    const int PX = nx + 2;
    const long long PXY = (long long)PX * (ny + 2);
#if CK_RETENTION
    const float cell = dx * dx * dx / volume_scale;  // V_cell / V_i = cell / grid_vol[i]: V_i = volume_scale grid_vol[i]
#else
    (void)volume_scale;
#endif
    FOR_EACH(p, n) {
        const float X = x[p] * inv_dx - 0.5f, Y = x[np + p] * inv_dx - 0.5f, Z = x[2 * np + p] * inv_dx - 0.5f;
        if (!coupling_inside(X, Y, Z, nx, ny, nz)) {
            saturation[p] = CK_NANF;  // no grid to read: visibly not a number (the finiteness check names it)
            continue;
        }
        float wx[3], wy[3], wz[3];
        const int bx = coupling_bspline(X, wx);
        const int by = coupling_bspline(Y, wy);
        const int bz = coupling_bspline(Z, wz);
        float s = 0.f;
#if CK_RETENTION
        float dr = 0.f;
#endif
        for (int c = 0; c < 3; ++c)
            for (int b = 0; b < 3; ++b) {
                const long long row = (long long)nx * ((long long)(by + b) + (long long)ny * (bz + c)) + bx;
                const long long prow = (bx + 1) + PX * (long long)(by + b + 1) + PXY * (bz + c + 1);  // padded
                const float wyz = wy[b] * wz[c];
                for (int a = 0; a < 3; ++a) {
                    const long long i = row + a;
                    const float w = wx[a] * wyz;
#if CK_TWO_PHASE
                    const float ph = coupling_water_phase(phi[prow + a]);
#else
                    const float ph = 1.f;
#endif
#if CK_RETENTION
                    const float held = bound[i];
#else
                    const float held = 0.f;
#endif
                    s += w * coupling_water(held, eps_fluid[prow + a], ph);  // Eq. 59
#if CK_RETENTION
                    if (masked) {
                        const float v = retentive[i];
                        if (v > 0.f) dr += w * d_bound[i] / v;  // Eq. 58 over the retentive sand only
                    } else {
                        const float v = grid_vol[i];
                        if (v > 0.f) dr += w * d_bound[i] * cell / v;  // Eq. 58, divided by the unclamped eps_i
                    }
#endif
                }
            }
        saturation[p] = s;
#if CK_RETENTION
        r[p] += masked ? retain[p] * dr : dr;
#endif
    }
#if !CK_TWO_PHASE
    (void)phi;
#endif
#if !CK_RETENTION
    (void)r;
    (void)bound;
    (void)d_bound;
    (void)grid_vol;
    (void)retentive;
    (void)retain;
    (void)masked;
#endif
}
