// Sand-water coupling, per node: volume fractions (paper 000 Eqs. 25, 33, 54) and, with water retention,
// the bound-water update (Eqs. 55, 56) and the water volume fraction that drives cohesion (Eq. 59).
// Spec: couplekit/coupling/reference.py ReferenceOps.fractions.
//
// One pass over the PADDED box (nx + 2, ny + 2, nz + 2) of the fluid fields.  Every padded cell takes its
// values from a source node of the (unpadded) MPM grid: its own node for an interior cell; for a ghost,
// the periodic image on a periodic axis (px/py/pz = 1) and the nearest interior node otherwise (zero normal
// gradient).  So eps_fluid comes out with its ghost layer filled and stencils may read it directly.  The
// unpadded outputs (d_bound, bound_out) are written by interior cells only.  The sand fraction and the water
// fraction are not stored: the drag and the moisture G2P recompute them (kernels/coupling_fields.cuh), from
// grid_vol and from eps_fluid, phi and bound_out.
//
//   eps_s  = min(eps_max, V_i / V_cell)                           (Eq. 25, V_i = sum_p V_p N_i(x_p))
//   eps_f  = 1 - eps_s                                            (Eq. 33, no retention)
// with retention (CK_RETENTION=1), R_i the bound water rasterised from the particles (Eq. 53):
//   cap    = r_max eps_s, or with per-body retention (masked = 1) r_max min(eps_s, eps_r), eps_r the
//            retentive sand's fraction sum_p [p retains] V_p N_i(x_p) / V_cell (Eq. 53 with r_p = 1 on retentive
//            particles): only retentive sand has capacity; masked = 0 is bitwise the one-setting model
//   free   = min(1 - eps_s - R_i, eps_prev)                       (Eq. 54 before the update, see below)
//   dR     = min(max(free, 0) phi, min(R_a dt cap phi, cap - R_i))   (Eq. 55, dt = 1 lattice step)
//   R'     = R_i + dR                                             (Eq. 56)
//   eps_f  = 1 - eps_s - R'                                       (Eq. 54 after the update: the porosity the
//                                                                  fluid and the source term see)
// (the water fraction R' + eps_f phi of Eq. 59, eps_f phi without retention, is the moisture G2P's)
// phi is the liquid phase field clamped to [0, 1] (CK_TWO_PHASE=1) or 1 (single-phase water, CK_TWO_PHASE=0).
// Eq. 55's "currently available fluid volume" eps~ phi: the phase field holds eps_prev phi of free water
// (eps_prev = last step's porosity, the one the last source term conserved), while R_i re-rasterised from
// the moved particles may differ from last step's R'; taking the smaller porosity keeps dR at most the free
// water actually present, so phi never goes negative (with 1 - eps_s - R_i alone it can, by ~1e-4).
// The uptake rate is Eq. 55's R_a dt r_max eps_s times the pores' water fraction phi (phi = 1: the paper's
// rate).  With the paper's rate alone, the outer min is the only limit in a partly wet node, so every node of
// the phase field's diffuse tail inside a dry plug's air-filled pores (phi ~ 1e-4 .. 0.1) lost ALL its water
// in one step: phi undershot below 0 there, the density flipped between air and tail water every step under
// the old hydrostatic pressure gradient, and the dry plug under water went NaN at step ~97 at R_a = 0.01.
// With the rate proportional to phi a node loses at most R_a r_max eps_s / eps_f of its water per step.
// A step of the sand that covers a share s of a fluid step (a substep, s = 1/k; several fluid steps of a
// multi-rate block, s = m; schedulers/) passes absorption = R_a s and free_share = min(s, 1): its uptake is
// its share of the fluid step's, and the substeps of one fluid step together take at most the free water the
// phase field holds (s = 1: the lockstep step, bitwise).
// Measurements and the ruled-out causes: couplekit/coupling/reference.py (module docstring).
// eps_prev must not alias eps_fluid.
// variants: CK_RETENTION=0,1 CK_TWO_PHASE=0,1
#include "common.cuh"
#include "coupling_fields.cuh"

#ifndef CK_RETENTION
#define CK_RETENTION 0
#endif
#ifndef CK_TWO_PHASE
#define CK_TWO_PHASE 1
#endif

// every padded cell (X, Y, Z) with its source node (ix, iy, iz) and whether it is an interior cell (inner):
// CELL(X, Y, Z, ix, iy, iz, inner).  The GPU a thread per cell; the host by padded rows in parallel, a row's
// interior cells a vector loop over consecutive nodes (the source index of y and z taken once per row; inner a
// literal per loop, rows versioned: the per-cell test kept the retention variant scalar, and a per-row flag
// vectorised it with masked stores at twice the time, 0.23 against 0.12 ms on Fig. 10 small's grid) and its two
// ghost cells their x source node (per cell, the GPU's form took the three source indices' branches in every cell and ran scalar).  Uses
// nx..nz, px..pz, n.
#if CK_ON_GPU
#define CPL_FOR_PADDED_CELLS(CELL)                                                                     \
    FOR_EACH_CELL(X, Y, Z, nx + 2, ny + 2, nz + 2) {                                                   \
        CELL(X, Y, Z, coupling_source_index(X, nx, px), coupling_source_index(Y, ny, py),              \
             coupling_source_index(Z, nz, pz), X >= 1 && X <= nx && Y >= 1 && Y <= ny && Z >= 1 && Z <= nz) \
    }
#else
#define CPL_FOR_PADDED_CELLS(CELL)                                                                     \
    CK_PRAGMA(omp parallel for collapse(2) schedule(static))                                           \
    for (int Z = 0; Z < nz + 2; ++Z)                                                                   \
        for (int Y = 0; Y < ny + 2; ++Y) {                                                             \
            const int iy = coupling_source_index(Y, ny, py), iz = coupling_source_index(Z, nz, pz);    \
            CELL(0, Y, Z, coupling_source_index(0, nx, px), iy, iz, 0)                                 \
            CELL(nx + 1, Y, Z, coupling_source_index(nx + 1, nx, px), iy, iz, 0)                       \
            if (Y >= 1 && Y <= ny && Z >= 1 && Z <= nz) {                                              \
                CK_PRAGMA(omp simd)                                                                    \
                for (int X = 1; X <= nx; ++X) CELL(X, Y, Z, X - 1, iy, iz, 1)                          \
            } else {                                                                                   \
                CK_PRAGMA(omp simd)                                                                    \
                for (int X = 1; X <= nx; ++X) CELL(X, Y, Z, X - 1, iy, iz, 0)                          \
            }                                                                                          \
        }                                                                                              \
    (void)n;
#endif

// n = (nx + 2) * (ny + 2) * (nz + 2).  Arrays of switched-off effects (phi, bound_in, eps_prev, d_bound,
// bound_out without retention; phi single-phase; retentive unless masked) are not read or written: pass a
// 1-element array.
KERNEL void coupling_fractions(const long long n, const float* RESTRICT grid_vol /* size: nx * ny * nz */,
                               const float* RESTRICT phi /* size >= 1 */,
                               const float* RESTRICT bound_in /* size >= 1 */,
                               const float* RESTRICT retentive /* size >= 1 */,
                               const float* RESTRICT eps_prev /* size >= 1 */,
                               float* RESTRICT eps_fluid /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                               float* RESTRICT d_bound /* size >= 1 */, float* RESTRICT bound_out /* size >= 1 */,
                               const int nx, const int ny,
                               const int nz, const int px, const int py, const int pz, const float inv_cell_volume,
                               const float eps_max, const float r_max, const float absorption, const float free_share,
                               const int masked) {
    const int PX = nx + 2;
    const long long PXY = (long long)PX * (ny + 2);
    // padded cell (X, Y, Z) from source node (ix, iy, iz)
#if CK_RETENTION
#if CK_TWO_PHASE
#define CPL_PHASE(image) coupling_water_phase(phi[image])
#else
#define CPL_PHASE(image) 1.f
#endif
#define CPL_FRACTION_CELL(X, Y, Z, ix, iy, iz, inner, mask)                                                    \
    {                                                                                                          \
        const long long node = (ix) + (long long)nx * ((iy) + (long long)ny * (iz));                           \
        const long long cell = (X) + PX * (long long)(Y) + PXY * (Z);                                          \
        const long long image = ((ix) + 1) + PX * (long long)((iy) + 1) + PXY * ((iz) + 1);                    \
        const float es = coupling_sand_fraction(grid_vol[node], inv_cell_volume, eps_max); /* Eq. 25 */        \
        const float ph = CPL_PHASE(image);                                                                     \
        const float R = bound_in[node];                                                                        \
        const float cap = r_max * ((mask) ? ck_fminf(es, retentive[node]) : es); /* retention capacity */    \
        const float free_water = free_share * (ck_fmaxf(ck_fminf(1.f - es - R, eps_prev[image]), 0.f) * ph);  \
        const float dR = ck_fminf(free_water, ck_fminf(absorption * cap * ph, cap - R)); /* Eq. 55 */         \
        const float Rn = R + dR;                                                /* Eq. 56 */                   \
        eps_fluid[cell] = 1.f - es - Rn;                                        /* Eq. 54 */                   \
        if (inner) {                                                                                           \
            d_bound[node] = dR;                                                                                \
            bound_out[node] = Rn;                                                                              \
        }                                                                                                      \
    }
#define CPL_FRACTION_MASKED(X, Y, Z, ix, iy, iz, inner) CPL_FRACTION_CELL(X, Y, Z, ix, iy, iz, inner, 1)
#define CPL_FRACTION_UNMASKED(X, Y, Z, ix, iy, iz, inner) CPL_FRACTION_CELL(X, Y, Z, ix, iy, iz, inner, 0)
    // masked a kernel argument, tested outside the loop: a load of retentive under a test kept the loop scalar
    if (masked) {
        CPL_FOR_PADDED_CELLS(CPL_FRACTION_MASKED)
    } else {
        CPL_FOR_PADDED_CELLS(CPL_FRACTION_UNMASKED)
    }
#undef CPL_FRACTION_MASKED
#undef CPL_FRACTION_UNMASKED
#else
#define CPL_FRACTION_CELL(X, Y, Z, ix, iy, iz, inner)                                                          \
    {                                                                                                          \
        const long long node = (ix) + (long long)nx * ((iy) + (long long)ny * (iz));                           \
        const float es = coupling_sand_fraction(grid_vol[node], inv_cell_volume, eps_max); /* Eq. 25 */        \
        eps_fluid[(X) + PX * (long long)(Y) + PXY * (Z)] = 1.f - es;                       /* Eq. 33 */        \
    }
    CPL_FOR_PADDED_CELLS(CPL_FRACTION_CELL)
#endif
#undef CPL_FRACTION_CELL
#undef CPL_PHASE
#if !CK_RETENTION
    (void)phi;
    (void)bound_in;
    (void)eps_prev;
    (void)d_bound;
    (void)bound_out;
    (void)r_max;
    (void)absorption;
    (void)free_share;
    (void)retentive;
    (void)masked;
#endif
#if !CK_TWO_PHASE
    (void)phi;
#endif
}

// The sand velocity input of the mixture pressure update (Eq. 39): the MPM grid velocity (SI, unpadded,
// zero on nodes without sand) in lattice units on the padded fluid layout, ghosts filled by the same rule
// as the fractions (periodic image / nearest interior node).  n = (nx + 2) * (ny + 2) * (nz + 2).
KERNEL void coupling_sand_velocity(const long long n, const float* RESTRICT grid_v /* size: 3 * nx * ny * nz */,
                                   float* RESTRICT sand_v /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
                                   const int nx, const int ny, const int nz, const int px, const int py,
                                   const int pz, const float inv_velocity_scale) {
    const long long ncell = (long long)nx * ny * nz;
    const int PX = nx + 2;
    const long long PXY = (long long)PX * (ny + 2);
    const long long N = PXY * (nz + 2);
#define CPL_SAND_V_CELL(X, Y, Z, ix, iy, iz, inner)                                      \
    {                                                                                 \
        const long long node = (ix) + (long long)nx * ((iy) + (long long)ny * (iz));  \
        const long long cell = (X) + PX * (long long)(Y) + PXY * (Z);                 \
        sand_v[cell] = grid_v[node] * inv_velocity_scale;                             \
        sand_v[N + cell] = grid_v[ncell + node] * inv_velocity_scale;                 \
        sand_v[2 * N + cell] = grid_v[2 * ncell + node] * inv_velocity_scale;         \
    }
    CPL_FOR_PADDED_CELLS(CPL_SAND_V_CELL)
#undef CPL_SAND_V_CELL
}
