// The water-retention model (paper 000 Sec. 4.5): its particle side, its node update, and the saturation that
// drives the sand's cohesion.  Spec: couplekit/coupling/reference.py ReferenceOps.bound_water_p2g / particle_moisture.
// Grid: the MPM grid (unpadded (nz, ny, nx), node (i, j, k) at ((i + 1/2) dx, ...)), quadratic B-splines
// N_i(x_p) exactly as the sand's transfers; x, V_p in SI (m, m^3), fractions dimensionless.
//
// coupling_bound_water_p2g:   R_i = (1 / V_cell) sum_p r_p V_p N_i(x_p)                       (Eq. 53)
//   CUDA: float atomics into `bound` (cleared first by coupling_clear).  Host: deterministic: each OpenMP
//   thread scatters its static block of particles into a private grid (scratch: nthreads * ncell floats),
//   summed node by node in thread order (bitwise reproducible for a fixed thread count).
// coupling_particle_moisture:  S_p = sum_i water_i N_i(x_p)                            (Eq. 59 / text after Eq. 28)
//   with retention (CK_RETENTION=1) also     r_p += sum_i (dR_i / eps_i) N_i(x_p)    (Eq. 58)
//   where eps_i = V_i / V_cell is the UNCLAMPED rasterised sand fraction (grid_vol): then
//   sum_p r_p V_p grows by exactly V_cell sum_i dR_i (partition of unity), i.e. bound water is conserved.
//   (With Eq. 25's clamped eps the particles would gain more water than the grid absorbed wherever the sand
//   is packed beyond eps_max.)  Call it with the positions of this step's P2G, before the sand's G2P moves
//   the particles.
//
// coupling_absorption (called with retention only): the node side, Eqs. 54-56 and the Eq. 59 summand, run after
// coupling_fractions (built with CK_RETENTION=0, which fills eps_sand with its ghosts):
//   free   = min(1 - eps_s - R_i, eps_prev)                            (Eq. 54 before the update)
//   dR     = min(max(free, 0) phi, min(R_a dt r_max eps_s phi, r_max eps_s - R_i))   (Eq. 55, dt = 1 step)
//   R'     = R_i + dR;  eps_f = 1 - eps_s - R';  water = R' + eps_f phi         (Eqs. 56, 54, 59)
// The uptake rate is Eq. 55's R_a dt r_max eps_s times the pores' water fraction phi (phi = 1: the paper's
// rate).  With the paper's rate alone, the outer min is the only limit in a partly wet node, so every node
// of the phase field's diffuse tail inside a dry plug's air-filled pores (phi ~ 1e-4 .. 0.1) lost ALL its
// water in one step: phi undershot below 0 there, the density flipped between air and tail water every
// step under the old hydrostatic pressure gradient, which accelerates air by (d rho / rho_l) g, and the dry
// plug under water went NaN at step ~97 at R_a = 0.01 (~1900 at 0.001).  With the rate proportional to phi
// a node loses at most R_a r_max eps_s / eps_f of its water per step.  Measurements and the ruled-out
// causes: couplekit/coupling/reference.py (module docstring).
// phi is clamped to [0, 1] (CK_TWO_PHASE=1) or 1 (single-phase water).  Every padded cell takes R_i,
// phi and eps_prev from its source node (periodic image / nearest interior node, as coupling_fractions),
// so eps_fluid comes out with its ghosts; the unpadded outputs are written by interior cells only.
// eps_prev must not alias eps_fluid.
// variants: CK_RETENTION=0,1 CK_TWO_PHASE=0,1
#include "common.cuh"

#ifndef CK_RETENTION
#define CK_RETENTION 0
#endif
#ifndef CK_TWO_PHASE
#define CK_TWO_PHASE 1
#endif

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
                                     float* RESTRICT scratch /* size >= 1 */, const int nthreads, const int nx,
                                     const int ny, const int nz, const float dx) {
    const long long np = n;
    const long long ncell = (long long)nx * ny * nz;
    const float inv_dx = 1.f / dx;
    const float inv_cell = inv_dx * inv_dx * inv_dx;
#if CK_ON_GPU
    FOR_EACH(p, n) {
        float wx[3], wy[3], wz[3];
        const int bx = coupling_bspline(x[p] * inv_dx - 0.5f, wx);
        const int by = coupling_bspline(x[np + p] * inv_dx - 0.5f, wy);
        const int bz = coupling_bspline(x[2 * np + p] * inv_dx - 0.5f, wz);
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
    CK_PRAGMA(omp parallel num_threads(nthreads)) {
        const int t = omp_get_thread_num();
        const int team = omp_get_num_threads();
        float* RESTRICT g = scratch + (long long)t * ncell;
        for (long long k = 0; k < ncell; ++k) g[k] = 0.f;
        CK_PRAGMA(omp for schedule(static))
        for (long long p = 0; p < np; ++p) {
            float wx[3], wy[3], wz[3];
            const int bx = coupling_bspline(x[p] * inv_dx - 0.5f, wx);
            const int by = coupling_bspline(x[np + p] * inv_dx - 0.5f, wy);
            const int bz = coupling_bspline(x[2 * np + p] * inv_dx - 0.5f, wz);
            const float q = r[p] * vol[p] * inv_cell;
            for (int c = 0; c < 3; ++c)
                for (int b = 0; b < 3; ++b) {
                    const long long row = (long long)nx * ((long long)(by + b) + (long long)ny * (bz + c)) + bx;
                    const float wyz = q * wy[b] * wz[c];
                    for (int a = 0; a < 3; ++a) g[row + a] += wx[a] * wyz;
                }
        }
        // implicit barrier: every private grid is complete; sum them in thread order
        CK_PRAGMA(omp for schedule(static))
        for (long long i = 0; i < ncell; ++i) {
            float s = 0.f;
            for (int u = 0; u < team; ++u) s += scratch[(long long)u * ncell + i];
            bound[i] = s;
        }
    }
#endif
}

// n = number of entries of a: a := 0 (before an atomic scatter on CUDA).
KERNEL void coupling_clear(const long long n, float* RESTRICT a /* size: n */) {
    FOR_EACH(i, n) a[i] = 0.f;
}

// n = number of particles.  Without retention r, d_bound and grid_vol are not used (pass 1-element arrays).
KERNEL void coupling_particle_moisture(const long long n, const float* RESTRICT x /* size: 3 * n */,
                                       float* RESTRICT r /* size >= 1 */, float* RESTRICT saturation /* size: n */,
                                       const float* RESTRICT water /* size: nx * ny * nz */,
                                       const float* RESTRICT d_bound /* size >= 1 */,
                                       const float* RESTRICT grid_vol /* size >= 1 */, const int nx, const int ny,
                                       const int nz, const float dx) {
    const long long np = n;
    const float inv_dx = 1.f / dx;
#if CK_RETENTION
    const float cell = dx * dx * dx;
#endif
    FOR_EACH(p, n) {
        float wx[3], wy[3], wz[3];
        const int bx = coupling_bspline(x[p] * inv_dx - 0.5f, wx);
        const int by = coupling_bspline(x[np + p] * inv_dx - 0.5f, wy);
        const int bz = coupling_bspline(x[2 * np + p] * inv_dx - 0.5f, wz);
        float s = 0.f;
#if CK_RETENTION
        float dr = 0.f;
#endif
        for (int c = 0; c < 3; ++c)
            for (int b = 0; b < 3; ++b) {
                const long long row = (long long)nx * ((long long)(by + b) + (long long)ny * (bz + c)) + bx;
                const float wyz = wy[b] * wz[c];
                for (int a = 0; a < 3; ++a) {
                    const long long i = row + a;
                    const float w = wx[a] * wyz;
                    s += w * water[i];  // Eq. 59
#if CK_RETENTION
                    const float v = grid_vol[i];
                    if (v > 0.f) dr += w * d_bound[i] * cell / v;  // Eq. 58, divided by the unclamped eps_i
#endif
                }
            }
        saturation[p] = s;
#if CK_RETENTION
        r[p] += dr;
#endif
    }
    (void)nz;
#if !CK_RETENTION
    (void)r;
    (void)d_bound;
    (void)grid_vol;
#endif
}

// interior source node (0-based) of padded coordinate X (0 .. n + 1): periodic image or nearest interior node
DEVICE int coupling_absorption_source(const int X, const int n, const int periodic) {
    if (X < 1) return periodic ? n - 1 : 0;
    if (X > n) return periodic ? 0 : n - 1;
    return X - 1;
}

// n = (nx + 2) * (ny + 2) * (nz + 2).  Single-phase (CK_TWO_PHASE=0): phi is not read (pass a 1-element array).
KERNEL void coupling_absorption(const long long n, const float* RESTRICT eps_sand /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                const float* RESTRICT phi /* size >= 1 */,
                                const float* RESTRICT bound_in /* size: nx * ny * nz */,
                                const float* RESTRICT eps_prev /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                float* RESTRICT eps_fluid /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                float* RESTRICT d_bound /* size: nx * ny * nz */,
                                float* RESTRICT bound_out /* size: nx * ny * nz */,
                                float* RESTRICT water /* size: nx * ny * nz */, const int nx, const int ny,
                                const int nz, const int px, const int py, const int pz, const float r_max,
                                const float absorption) {
    const int PX = nx + 2;
    const long long PXY = (long long)PX * (ny + 2);
    FOR_EACH_CELL(X, Y, Z, nx + 2, ny + 2, nz + 2) {
        const int ix = coupling_absorption_source(X, nx, px);
        const int iy = coupling_absorption_source(Y, ny, py);
        const int iz = coupling_absorption_source(Z, nz, pz);
        const long long node = ix + (long long)nx * (iy + (long long)ny * iz);
        const long long cell = X + PX * (long long)Y + PXY * Z;
        const long long image = (ix + 1) + PX * (long long)(iy + 1) + PXY * (iz + 1);
        const float es = eps_sand[cell];
#if CK_TWO_PHASE
        const float ph = fminf(fmaxf(phi[image], 0.f), 1.f);
#else
        const float ph = 1.f;
#endif
        const float R = bound_in[node];
        const float cap = r_max * es;  // retention capacity
        const float free_water = fmaxf(fminf(1.f - es - R, eps_prev[image]), 0.f) * ph;
        const float dR = fminf(free_water, fminf(absorption * cap * ph, cap - R));  // Eq. 55, rate x phi
        const float Rn = R + dR;                                                    // Eq. 56
        const float ef = 1.f - es - Rn;                                             // Eq. 54
        eps_fluid[cell] = ef;
        const int inside = X >= 1 && X <= nx && Y >= 1 && Y <= ny && Z >= 1 && Z <= nz;
        if (inside) {
            water[node] = Rn + ef * ph;  // Eq. 59 summand
            d_bound[node] = dR;
            bound_out[node] = Rn;
        }
    }
#if !CK_TWO_PHASE
    (void)phi;
#endif
}
