// D3Q7 conservative Allen–Cahn phase field (paper 000 §4.4, Eqs. 44–52) and the phase-field quantities the
// flow needs (gradient Eq. 21, chemical potential Eqs. 22–23).  NumPy twin (the specification):
// couplekit/fluid/phasefield_reference.py.  Notes: shared/notes/lbm-method.md §1c (scheme), §1d (streaming).
//
// Storage: the flow's padded grid (couplekit/fluid/grid.py).  Every field has ONE ghost layer on every side:
//   padded extents NX = nx + 2, NY = ny + 2, NZ = nz + 2, interior cells at padded coordinates 1..nx etc.;
//   scalars (NZ, NY, NX), vectors (3, NZ, NY, NX), h (7, NZ, NY, NX), float32; linear index
//   c = X + NX*(Y + NY*Z); slot q of cell c at h[q*NCELL + c], NCELL = NX*NY*NZ.
//   flags (NZ, NY, NX) uint8, the flow's cell flags: FLUID 0 (updated), WALL 1 (solid / wall: no-flux
//   bounce-back), INFLOW 2 (bounce-back plus the advective flux phi_b d_q.u_b of the phi and velocity stored at
//   that cell: exactly phi_b u_b.n enters per face link, the fluid's volume flux times the carried phase value),
//   OUTFLOW 3 (bounce-back less the advective flux phi max(d_q.u, 0) of this cell's own phi and velocity: phi
//   leaves only by advection where the cell's velocity points out through the face, and nothing comes in:
//   pf_outflux).
//   Ghost cells on non-periodic axes must be WALL/INFLOW/OUTFLOW (grid.build_flags, phasefield.pad_flags).
//
// Neighbours: constant offsets, except on a periodic axis where a step out of the interior wraps to the
// other side (the kernels never read h in periodic ghosts, so h needs no halo copy).
//
// In-place streaming: the AA pattern (Bailey et al. 2009), exactly as the flow (kernels/lbm_core.cuh):
//   even parity: f_q = h[q][c]; store h[opp q][c] = f*_q (local).
//   odd parity:  f_q = h[opp q][c - d_q] (pull); store h[q][c + d_q] = f*_q (push).  Boundary rules, odd only:
//     pull from WALL c - d_q:              f_q = h[q][c]       (own f*_{opp q} of the even step: bounce-back)
//     push to WALL c + d_q:                h[opp q][c] = f*_q  (read back at the next even step)
//     pull from INFLOW p / push to INFLOW m: as a WALL plus 2 w_q phi_b d_q.u_b / cs^2 (q the direction into the
//                                          cell) with phi_b, u_b stored at the inflow cell, so that the link's
//                                          net flux is phi_b d_q.u_b: no diffusive or interface flux crosses
//                                          an inflow, the water it delivers is u_in x area x phi_b (pf_inflow);
//     pull from OUTFLOW / push to OUTFLOW: as a WALL less 2 w_q phi max(d_q.u, 0) / cs^2 (d_q the direction out
//                                          of the cell; pf_outflux) with this cell's u; on a pull phi solves
//                                          phi = sum of the populations so loaded, on a push phi = sum_k f*_k.
// After an even step the populations sit in reversed slots, after an odd step in natural order.
#include "common.cuh"
#include "lattice.cuh"
#include "lbm_core.cuh"  // the host row tests lbm_row_fluid / lbm_rows_all_fluid (the flags are the flow's)

// 0: surface tension sigma = 0, the chemical potential (double well + Laplacian) is compiled out.
// variants: CK_PF_SURFACE_TENSION=0,1 CK_PF_SOURCE=0,1 CK_STORAGE_FP16=0,1
#ifndef CK_PF_SURFACE_TENSION
#define CK_PF_SURFACE_TENSION 1
#endif

// 0: no source term S_phi (a fluid-only scene, or the Fig. 14 ablation): the collide kernel and the volume
// sums never read `source` (a placeholder may be passed) and sum S_phi = 0 (variants: the line above).
#ifndef CK_PF_SOURCE
#define CK_PF_SOURCE 1
#endif

// Storage of h: ck_store_t (common.cuh).  float32 holds h itself; with CK_STORAGE_FP16 the binary16 slots hold
// (h_q - CK_H_REST w_q) * CK_H_SCALE.  CK_H_REST = 0 (h unshifted) was measured against 1 (h - w_q: the water
// bulk's flux parts stored finely, but the air's small phi tails rounded away against -w_q, always towards 0):
// docs/precision.md "fp16 storage".  w_q is the same for a slot and its opposite, so a shift follows the slot.
// PF_LDS / PF_STS: the same, for loops the host runs scalar (CK_LOAD_SCALAR, common.cuh)
#if CK_STORAGE_FP16 && CK_H_REST
#define PF_LD(h, q, i) (CK_LOAD(h, i, CK_H_SCALE) + W7[q])
#define PF_ST(h, q, i, v) CK_STORE(h, i, (v) - W7[q], CK_H_SCALE)
#define PF_LDS(h, q, i) (CK_LOAD_SCALAR(h, i, CK_H_SCALE) + W7[q])
#define PF_STS(h, q, i, v) CK_STORE_SCALAR(h, i, (v) - W7[q], CK_H_SCALE)
#elif CK_STORAGE_FP16
#define PF_LD(h, q, i) CK_LOAD(h, i, CK_H_SCALE)
#define PF_ST(h, q, i, v) CK_STORE(h, i, (v), CK_H_SCALE)
#define PF_LDS(h, q, i) CK_LOAD_SCALAR(h, i, CK_H_SCALE)
#define PF_STS(h, q, i, v) CK_STORE_SCALAR(h, i, (v), CK_H_SCALE)
#else
#define PF_LD(h, q, i) ((h)[i])
#define PF_ST(h, q, i, v) ((h)[i] = (v))
#define PF_LDS(h, q, i) ((h)[i])
#define PF_STS(h, q, i, v) ((h)[i] = (v))
#endif

#define PF_FLUID 0
#define PF_WALL 1
#define PF_INFLOW 2
#define PF_OUTFLOW 3
#if PF_FLUID != FLAG_FLUID || PF_WALL != FLAG_WALL || PF_INFLOW != FLAG_INFLOW || PF_OUTFLOW != FLAG_OUTFLOW
#error "the phase field reads the flow's cell flags (kernels/lbm_core.cuh)"
#endif

// |grad phi|^2 below which the interface normal is set to zero (bulk phases, round-off gradients)
#define PF_GRAD_EPS2 1e-12f

// pragmas and inlining follow the compiler, not CK_ON_GPU: the device-path host build (CK_DEVICE_PATH=1)
// is compiled by g++ and takes the host spellings
#if defined(__CUDACC__)
#define PF_UNROLL _Pragma("unroll")
#define PF_INLINE DEVICE
#else
#define PF_UNROLL _Pragma("GCC unroll 27")
// the cell loops only vectorise on the host when the per-cell helpers are inlined into them
#define PF_INLINE static inline __attribute__((always_inline))
#endif

#if !CK_ON_GPU
// Host row scheme (as the flow's lbm_collide_stream, kernels/lbm_core.cuh): a padded row of cells whose
// neighbourhood is all FLUID takes a flag-free `omp simd` x loop; other rows a per-cell path with the flags, or
// a loop over 32-bit neighbour masks built from widened flags.  A byte (flag) read inside an x loop makes g++
// choose byte-wide vectors (four registers per float value) or leave the loop scalar.
#define PF_ROW_CHUNK 512

// FLUID masks of the `len` cells from padded index c0 for the 27-point stencils: bit k (cube order
// k = (dz + 1) * 9 + (dy + 1) * 3 + (dx + 1), as PF_W27_CUBE; bit 13 = the cell itself) is set when cell
// c + dx + sy dy + sz dz is FLUID.  The 9 rows' flags are widened to 32 bits in `scratch` (>= 9 (len + 2)) first,
// so the mask loop reads no byte data.
static inline __attribute__((always_inline)) void pf_fluid_masks(const unsigned char* RESTRICT flags,
                                                                 const long long c0, const int len,
                                                                 const long long sy, const long long sz,
                                                                 unsigned int* RESTRICT masks,
                                                                 unsigned int* RESTRICT scratch) {
    const int w = len + 2;
    for (int r = 0; r < 9; ++r) {  // r = (dz + 1) * 3 + (dy + 1)
        const unsigned char* fr = flags + c0 - 1 + (long long)(r % 3 - 1) * sy + (long long)(r / 3 - 1) * sz;
        unsigned int* sr = scratch + r * w;
        CK_SIMD_SHORT
        for (int i = 0; i < w; ++i) sr[i] = fr[i] == PF_FLUID ? 1u : 0u;
    }
    CK_SIMD_SHORT
    for (int i = 0; i < len; ++i) {
        unsigned int m = 0u;
        PF_UNROLL
        for (int k = 0; k < 27; ++k) m |= scratch[(k / 3) * w + i + k % 3] << k;
        masks[i] = m;
    }
}

#endif

// D3Q27 weights in 3x3x3 cube order, index (dz+1)*9 + (dy+1)*3 + (dx+1) (the isotropic stencils, Eqs. 21, 23)
CONSTANT float PF_W27_CUBE[27] = {
    1.f / 216, 1.f / 54, 1.f / 216, 1.f / 54, 2.f / 27, 1.f / 54, 1.f / 216, 1.f / 54, 1.f / 216,
    1.f / 54,  2.f / 27, 1.f / 54,  2.f / 27, 8.f / 27, 2.f / 27, 1.f / 54,  2.f / 27, 1.f / 54,
    1.f / 216, 1.f / 54, 1.f / 216, 1.f / 54, 2.f / 27, 1.f / 54, 1.f / 216, 1.f / 54, 1.f / 216,
};

// The cell itself (nb[0]) and its 6 D3Q7 neighbours nb[q] = c + d_q, wrapped on periodic axes.
DEVICE void pf_neighbours(const int X, const int Y, const int Z, const int nx, const int ny, const int nz,
                          const int px, const int py, const int pz, long long nb[7]) {
    const long long sy = (long long)(nx + 2), sz = (long long)(nx + 2) * (long long)(ny + 2);
    const long long c = X + sy * Y + sz * Z;
    nb[0] = c;
    nb[1] = (X == nx && px) ? c - (nx - 1) : c + 1;
    nb[2] = (X == 1 && px) ? c + (nx - 1) : c - 1;
    nb[3] = (Y == ny && py) ? c - sy * (ny - 1) : c + sy;
    nb[4] = (Y == 1 && py) ? c + sy * (ny - 1) : c - sy;
    nb[5] = (Z == nz && pz) ? c - sz * (nz - 1) : c + sz;
    nb[6] = (Z == 1 && pz) ? c + sz * (nz - 1) : c - sz;
}

PF_INLINE int pf_opp(const int q) { return q == 0 ? 0 : ((q & 1) ? q + 1 : q - 1); }

// d_q . u for the D3Q7 direction q
PF_INLINE float pf_dot(const int q, const float ux, const float uy, const float uz) {
    return (float)CX7[q] * ux + (float)CY7[q] * uy + (float)CZ7[q] * uz;
}

// D3Q7 equilibrium h_q^eq = w_q phi (1 + d_q.u / cs^2), cs^2 = 1/4 (first order in u, notes §1c).
PF_INLINE float pf_feq(const int q, const float phi, const float ux, const float uy, const float uz) {
    return W7[q] * phi * (1.f + pf_dot(q, ux, uy, uz) / CS2_7);
}

// The advective flux an outflow link passes out along q (from the cell into the outflow ghost): 2 w_q phi
// max(d_q.u, 0) / cs^2 = phi max(d_q.u, 0).  The ghost returns the cell's own f*_q bounced back less this, so the
// link's net flux is phi d_q.u where the fluid leaves and 0 where it comes in (backflow), and none of the
// sharpening or diffusive flux crosses the face (the former equilibrium feed let (1 - omega/2) H_q leave but not
// return: an outflow face drew phi in from a haze of it, and a water outlet in an outflow face delivered 1.08x
// its flux).  Reference: phasefield_reference._outflux.
PF_INLINE float pf_outflux(const int q, const float phi, const float ux, const float uy, const float uz) {
    const float du = pf_dot(q, ux, uy, uz);
    return du > 0.f ? 2.f * W7[q] * phi * du / CS2_7 : 0.f;
}

// The flux part of an inflow link (q: the direction from the inflow cell into the fluid cell): the population that
// enters is the bounced-back one plus 2 w_q phi_b d_q.u_b / cs^2, so the link's net flux is phi_b d_q.u_b (8 w_q = 1
// with w_q = 1/8, cs^2 = 1/4).  The former equilibrium inflow, h = w_q phi_b (1 + d_q.u_b / cs^2), added a
// diffusive exchange (phi_b - phi) / 8 that no counter flux balanced, and how much water it let in depended on the
// cells' phase values (measured: 0.96 u_in A for a 6 x 6 outlet at xi = 4; test_inflow_region).
PF_INLINE float pf_inflow(const int q, const float phi_b, const float ux, const float uy, const float uz) {
    return 2.f * W7[q] * phi_b * pf_dot(q, ux, uy, uz) / CS2_7;
}

// Pre-collision populations of fluid cell nb[0] at step parity `odd` (AA read rule with boundary rules).
// SCALAR = 1 in a loop the host does not vectorise (the odd step): PF_LDS.
#define PF_LDX(h, q, i) (SCALAR ? PF_LDS(h, q, i) : PF_LD(h, q, i))
template <int SCALAR>
DEVICE void pf_load(const ck_store_t* RESTRICT h, const unsigned char* RESTRICT flags, const float* RESTRICT phi,
                    const float* RESTRICT u, const long long ncell, const long long nb[7], const int odd,
                    float f[7]) {
    const long long c = nb[0];
    if (!odd) {
        PF_UNROLL
        for (int q = 0; q < 7; ++q) f[q] = PF_LDX(h, q, q * ncell + c);
        return;
    }
    const float ux = u[c], uy = u[ncell + c], uz = u[2 * ncell + c];
    f[0] = PF_LDX(h, 0, c);
    float known = f[0], outflow_rate = 0.f;
    PF_UNROLL
    for (int q = 1; q < 7; ++q) {
        const long long p = nb[pf_opp(q)];  // c - d_q
        const int kind = flags[p];
        float v;
        if (kind == PF_FLUID) {
            v = PF_LDX(h, q, pf_opp(q) * ncell + p);
        } else if (kind == PF_INFLOW) {
            v = PF_LDX(h, q, q * ncell + c) + pf_inflow(q, phi[p], u[p], u[ncell + p], u[2 * ncell + p]);
        } else {  // WALL; OUTFLOW bounced back here, less its advective flux below
            v = PF_LDX(h, q, q * ncell + c);
            if (kind == PF_OUTFLOW) outflow_rate += pf_outflux(pf_opp(q), 1.f, ux, uy, uz);
        }
        f[q] = v;
        known += v;
    }
    if (outflow_rate != 0.f) {
        // outflow links: bounced back less phi_c times their rates, phi_c the cell's own sum (phi_c = known -
        // phi_c rate), so that the load reads no stored phi (phase_macroscopic writes phi while it loads)
        const float phi_c = known / (1.f + outflow_rate);
        PF_UNROLL
        for (int q = 1; q < 7; ++q)
            if (flags[nb[pf_opp(q)]] == PF_OUTFLOW) f[q] -= pf_outflux(pf_opp(q), phi_c, ux, uy, uz);
    }
}

// AA write rule: post-collision populations of fluid cell nb[0] at step parity `odd`.
DEVICE void pf_store(ck_store_t* RESTRICT h, const unsigned char* RESTRICT flags, const float* RESTRICT phi,
                     const float* RESTRICT u, const long long ncell, const long long nb[7], const int odd,
                     const float f[7]) {
    const long long c = nb[0];
    if (!odd) {
        PF_UNROLL
        for (int q = 0; q < 7; ++q) PF_STS(h, q, pf_opp(q) * ncell + c, f[q]);
        return;
    }
    PF_STS(h, 0, c, f[0]);
    const float phi_post = f[0] + f[1] + f[2] + f[3] + f[4] + f[5] + f[6];
    PF_UNROLL
    for (int q = 1; q < 7; ++q) {
        const long long m = nb[q];
        const int kind = flags[m];
        const int qo = pf_opp(q);
        if (kind == PF_FLUID) {
            PF_STS(h, q, q * ncell + m, f[q]);
        } else if (kind == PF_INFLOW) {
            PF_STS(h, qo, qo * ncell + c, f[q] + pf_inflow(qo, phi[m], u[m], u[ncell + m], u[2 * ncell + m]));
        } else if (kind == PF_OUTFLOW) {
            PF_STS(h, qo, qo * ncell + c, f[q] - pf_outflux(q, phi_post, u[c], u[ncell + c], u[2 * ncell + c]));
        } else {
            PF_STS(h, qo, qo * ncell + c, f[q]);
        }
    }
}

// h := a state that loads (at parity t) as h^eq(phi, u) in every interior fluid cell.  n = nx*ny*nz.
KERNEL void phase_set_equilibrium(const long long n,
                                  ck_store_t* RESTRICT h /* size: 7 * (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const float* RESTRICT phi /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const float* RESTRICT u /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const int nx, const int ny, const int nz, const int px, const int py,
                                  const int pz, const int parity) {
    const long long ncell = (long long)(nx + 2) * (ny + 2) * (nz + 2);
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        long long nb[7];
        pf_neighbours(x + 1, y + 1, z + 1, nx, ny, nz, px, py, pz, nb);
        const long long c = nb[0];
        if (flags[c] != PF_FLUID) continue;
        const float p0 = phi[c], ux = u[c], uy = u[ncell + c], uz = u[2 * ncell + c];
        PF_UNROLL
        for (int q = 0; q < 7; ++q) {
            const float feq = pf_feq(q, p0, ux, uy, uz);
            if (!(parity & 1) || q == 0) {
                PF_ST(h, q, q * ncell + c, feq);
            } else {
                const long long p = nb[pf_opp(q)];
                const int kind = flags[p];
                if (kind == PF_FLUID) PF_ST(h, q, pf_opp(q) * ncell + p, feq);
                else if (kind == PF_WALL) PF_ST(h, q, q * ncell + c, feq);
                else if (kind == PF_INFLOW)
                    PF_ST(h, q, q * ncell + c, feq - pf_inflow(q, phi[p], u[p], u[ncell + p], u[2 * ncell + p]));
                else if (kind == PF_OUTFLOW)
                    PF_ST(h, q, q * ncell + c, feq + pf_outflux(pf_opp(q), p0, ux, uy, uz));
            }
        }
    }
}

// phase_macroscopic for padded cell (X, Y, Z), as the GPU runs it (and the host outside its bulk loops)
DEVICE void pf_macro_cell(const int X, const int Y, const int Z, const ck_store_t* RESTRICT h, float* RESTRICT phi,
                          const float* RESTRICT u, const unsigned char* RESTRICT flags, const int nx, const int ny,
                          const int nz, const int px, const int py, const int pz, const int parity,
                          const long long ncell) {
    const long long c = X + (long long)(nx + 2) * (Y + (long long)(ny + 2) * Z);
    if (flags[c] == PF_INFLOW) return;
    const int xi = X == 0 ? (px ? nx : 1) : (X == nx + 1 ? (px ? 1 : nx) : X);
    const int yi = Y == 0 ? (py ? ny : 1) : (Y == ny + 1 ? (py ? 1 : ny) : Y);
    const int zi = Z == 0 ? (pz ? nz : 1) : (Z == nz + 1 ? (pz ? 1 : nz) : Z);
    long long nb[7];
    pf_neighbours(xi, yi, zi, nx, ny, nz, px, py, pz, nb);
    const int kind = flags[nb[0]];
    float s = 0.f;
    if (kind == PF_FLUID) {
        float f[7];
        pf_load<1>(h, flags, phi, u, ncell, nb, parity & 1, f);
        // summed in double as in phase_collide_stream: phi is the populations' sum up to one rounding
        s = (float)((double)f[0] + (double)f[1] + (double)f[2] + (double)f[3] + (double)f[4] + (double)f[5] +
                    (double)f[6]);
    } else if (kind == PF_INFLOW) {
        s = phi[nb[0]];
    }
    phi[c] = s;
}

#if !CK_ON_GPU
// Host: the offsets nb[q] - c (q = 1..6) of the D3Q7 neighbours of the cells X = 2..nx - 1 of interior row
// (Y, Z) (constant along the row: only x = 1 and x = nx can wrap in x), and whether those cells are a bulk
// run: the row's cells 1..nx and, with NEIGH, the 4 neighbour rows' cells 2..nx - 1 all FLUID
template <int NEIGH>
static inline __attribute__((always_inline)) bool pf_bulk_row(const unsigned char* RESTRICT flags, const int Y,
                                                              const int Z, const int nx, const int ny, const int nz,
                                                              const int px, const int py, const int pz,
                                                              long long off[7]) {
    long long nb[7];
    pf_neighbours(2, Y, Z, nx, ny, nz, px, py, pz, nb);
    for (int q = 0; q < 7; ++q) off[q] = nb[q] - nb[0];
    if (nx < 3) return false;
    const long long row = nb[0] - 2;
    bool bulk = lbm_row_fluid(flags, row, 1, nx);
    if (NEIGH)
        for (int q = 3; q < 7; ++q) bulk = bulk && lbm_row_fluid(flags, row + off[q], 2, nx - 1);
    return bulk;
}

// Host: whether the odd step of cell X (2 .. nx - 1) of padded row `row` may take the bulk run's loop: the cell
// and its six neighbours (x +- 1 in the row, the four y / z rows by pf_bulk_row's offsets `off`) are FLUID, so
// none of its links meets a boundary.  A bulk row's cells 2 .. nx - 1 all are.
static inline bool pf_odd_run_cell(const unsigned char* RESTRICT flags, const long long row, const int X,
                                   const int nx, const long long off[7]) {
    if (X < 2 || X > nx - 1) return false;
    const long long c = row + X;
    unsigned int any = flags[c] | flags[c - 1] | flags[c + 1];
    for (int q = 3; q < 7; ++q) any |= flags[c + off[q]];
    return any == 0;  // FLAG_FLUID == 0
}
#endif

#if !CK_ON_GPU
// Host: phi = sum_k h_k of the cells X = xa .. xb of padded row `row` whose links all meet fluid (a bulk run:
// pf_bulk_row, pf_odd_run_cell), by one `omp simd` loop with the row's constant neighbour offsets `off`; the
// same sums in the same order as pf_macro_cell.
template <int ODD>
static inline __attribute__((always_inline)) void pf_macro_run(const ck_store_t* RESTRICT h, float* RESTRICT phi,
                                                              const long long row, const int xa, const int xb,
                                                              const long long ncell, const long long off[7]) {
    const long long o1 = off[1], o2 = off[2], o3 = off[3], o4 = off[4], o5 = off[5], o6 = off[6];
    CK_SIMD_SHORT
    for (int X = xa; X <= xb; ++X) {
        const long long c = row + X;
        const float f0 = PF_LD(h, 0, c);
        const float f1 = ODD ? PF_LD(h, 1, 2 * ncell + c + o2) : PF_LD(h, 1, ncell + c);
        const float f2 = ODD ? PF_LD(h, 2, ncell + c + o1) : PF_LD(h, 2, 2 * ncell + c);
        const float f3 = ODD ? PF_LD(h, 3, 4 * ncell + c + o4) : PF_LD(h, 3, 3 * ncell + c);
        const float f4 = ODD ? PF_LD(h, 4, 3 * ncell + c + o3) : PF_LD(h, 4, 4 * ncell + c);
        const float f5 = ODD ? PF_LD(h, 5, 6 * ncell + c + o6) : PF_LD(h, 5, 5 * ncell + c);
        const float f6 = ODD ? PF_LD(h, 6, 5 * ncell + c + o5) : PF_LD(h, 6, 6 * ncell + c);
        phi[c] = (float)((double)f0 + (double)f1 + (double)f2 + (double)f3 + (double)f4 + (double)f5 + (double)f6);
    }
}
#endif

// phi = sum_k h_k (Eq. 47) at parity t, on every padded cell.  A ghost cell takes the value of its image
// (wrap on periodic axes, nearest interior cell otherwise); an interior WALL / OUTFLOW cell (or a ghost whose
// image is one) gets 0; INFLOW cells, ghost or interior, keep the phase value they carry (set by the
// caller).  n = (nx+2)*(ny+2)*(nz+2).
KERNEL void phase_macroscopic(const long long n,
                              const ck_store_t* RESTRICT h /* size: 7 * (nx + 2) * (ny + 2) * (nz + 2) */,
                              float* RESTRICT phi /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                              const float* RESTRICT u /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
                              const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                              const int nx, const int ny, const int nz, const int px, const int py,
                              const int pz, const int parity) {
    const long long ncell = (long long)(nx + 2) * (ny + 2) * (nz + 2);
#if CK_ON_GPU
    FOR_EACH_CELL(X, Y, Z, nx + 2, ny + 2, nz + 2) {
        pf_macro_cell(X, Y, Z, h, phi, u, flags, nx, ny, nz, px, py, pz, parity, ncell);
    }
#else
    // host: interior rows first, a bulk run (pf_bulk_row) by a flag-free `omp simd` loop with the row's constant
    // neighbour offsets, everything else by pf_macro_cell; then the ghosts, each the value its image (an interior
    // cell) has now, which is what pf_macro_cell computes for a ghost (the sum of the image's populations, its
    // inflow value, or 0).  Same values as the GPU path (the same sums in the same order).
    const long long sy = nx + 2, sz = sy * (ny + 2);
#define PF_MACRO_ROWS(ODD)                                                                                   \
    CK_PRAGMA(omp parallel for collapse(2) schedule(static))                                                 \
    for (int Z = 1; Z <= nz; ++Z)                                                                            \
        for (int Y = 1; Y <= ny; ++Y) {                                                                      \
            long long off[7];                                                                                \
            const bool bulk = pf_bulk_row<ODD>(flags, Y, Z, nx, ny, nz, px, py, pz, off);                    \
            const long long row = sy * Y + sz * Z;                                                           \
            if (!ODD && !bulk) {                                                                             \
                /* even step, a row with non-fluid cells: every interior cell by one vector loop, the     */ \
                /* kind blended in (flags widened to 32 bits first), then the row's two x ghosts          */ \
                unsigned int isf[PF_ROW_CHUNK], isi[PF_ROW_CHUNK];                                           \
                for (int x0 = 1; x0 <= nx; x0 += PF_ROW_CHUNK) {                                             \
                    const int len = nx + 1 - x0 < PF_ROW_CHUNK ? nx + 1 - x0 : PF_ROW_CHUNK;                 \
                    const long long c0 = row + x0;                                                           \
                    CK_PRAGMA(omp simd)                                                                      \
                    for (int i = 0; i < len; ++i) {                                                          \
                        isf[i] = flags[c0 + i] == PF_FLUID ? 1u : 0u;                                        \
                        isi[i] = flags[c0 + i] == PF_INFLOW ? 1u : 0u;                                       \
                    }                                                                                        \
                    CK_PRAGMA(omp simd)                                                                      \
                    for (int i = 0; i < len; ++i) {                                                          \
                        const long long c = c0 + i;                                                          \
                        const float s = (float)((double)PF_LD(h, 0, c) + (double)PF_LD(h, 1, ncell + c) +    \
                                                (double)PF_LD(h, 2, 2 * ncell + c) +                         \
                                                (double)PF_LD(h, 3, 3 * ncell + c) +                         \
                                                (double)PF_LD(h, 4, 4 * ncell + c) +                         \
                                                (double)PF_LD(h, 5, 5 * ncell + c) +                         \
                                                (double)PF_LD(h, 6, 6 * ncell + c));                         \
                        phi[c] = ck_select(isf[i], s, ck_select(isi[i], phi[c], 0.f));                       \
                    }                                                                                        \
                }                                                                                            \
                pf_macro_cell(0, Y, Z, h, phi, u, flags, nx, ny, nz, px, py, pz, parity, ncell);             \
                pf_macro_cell(nx + 1, Y, Z, h, phi, u, flags, nx, ny, nz, px, py, pz, parity, ncell);        \
                continue;                                                                                    \
            }                                                                                                \
            if (ODD && !bulk) {                                                                              \
                /* odd step, a row with non-fluid cells: the runs of cells whose six neighbours are fluid     */ \
                /* (pf_odd_run_cell) by the bulk run's vector loop, every other cell by pf_macro_cell         */ \
                for (int xs = 0; xs <= nx + 1;) {                                                            \
                    if (!pf_odd_run_cell(flags, row, xs, nx, off)) {                                         \
                        pf_macro_cell(xs, Y, Z, h, phi, u, flags, nx, ny, nz, px, py, pz, parity, ncell);    \
                        ++xs;                                                                                \
                        continue;                                                                            \
                    }                                                                                        \
                    int xe = xs;                                                                             \
                    while (pf_odd_run_cell(flags, row, xe + 1, nx, off)) ++xe;                               \
                    pf_macro_run<ODD>(h, phi, row, xs, xe, ncell, off);                                      \
                    xs = xe + 1;                                                                             \
                }                                                                                            \
                continue;                                                                                    \
            }                                                                                                \
            const int xa = bulk ? (ODD ? 2 : 1) : nx + 1, xb = bulk ? (ODD ? nx - 1 : nx) : nx;               \
            pf_macro_run<ODD>(h, phi, row, xa, xb, ncell, off);                                              \
            for (int X = 0; X <= nx + 1; ++X)                                                                \
                if (X < xa || X > xb) pf_macro_cell(X, Y, Z, h, phi, u, flags, nx, ny, nz, px, py, pz, parity, ncell); \
        }
    // (the row's own x ghosts are done above: their images lie in the same row)
    if (parity & 1) {
        PF_MACRO_ROWS(1)
    } else {
        PF_MACRO_ROWS(0)
    }
#undef PF_MACRO_ROWS
    CK_PRAGMA(omp parallel for collapse(2) schedule(static))
    for (int Z = 0; Z <= nz + 1; ++Z)
        for (int Y = 0; Y <= ny + 1; ++Y) {
            if (Z >= 1 && Z <= nz && Y >= 1 && Y <= ny) continue;
            const int yi = Y == 0 ? (py ? ny : 1) : (Y == ny + 1 ? (py ? 1 : ny) : Y);
            const int zi = Z == 0 ? (pz ? nz : 1) : (Z == nz + 1 ? (pz ? 1 : nz) : Z);
            const long long row = sy * Y + sz * Z, img = sy * yi + sz * zi;
            for (int X = 0; X <= nx + 1; ++X) {
                const int xi = X == 0 ? (px ? nx : 1) : (X == nx + 1 ? (px ? 1 : nx) : X);
                if (flags[row + X] != PF_INFLOW) phi[row + X] = phi[img + xi];
            }
        }
#endif
}

// grad phi by the isotropic D3Q27 stencil (Eq. 21) and, with CK_PF_SURFACE_TENSION, the chemical potential
// mu = 4 beta phi (phi - 1)(phi - 1/2) - kappa lap(phi) (Eq. 22) with the isotropic Laplacian (Eq. 23).
// Only FLUID neighbours contribute their value, any other takes the centre value (zero gradient along that
// link, as the flow's stencils).  phi must have its ghost layer filled (phase_macroscopic does).  Interior
// cells only; non-fluid cells get 0.  n = nx*ny*nz.  Without CK_PF_SURFACE_TENSION, mu, beta and kappa
// are not used (pass a 1-element dummy for mu).
// MODE: how a stencil learns the kind of a neighbour: PF_NB_FLAGS reads its flag, PF_NB_MASK takes bit k of `mask`
// (pf_fluid_masks), PF_NB_BULK: the caller guarantees that c and all its neighbours are FLUID.
#define PF_NB_FLAGS 0
#define PF_NB_BULK 1
#define PF_NB_MASK 2
// The raw stencil sums of cell c: sum_k w_k d_k v_k (x, y, z) and sum_k w_k (v_k - phi_c) (lap), v_k = phi of
// neighbour k where it is FLUID, phi_c otherwise.  By value (a struct, as PfCell): sums passed out by reference
// kept the host x loops scalar.
struct PfGrad {
    float x, y, z, lap;
};

template <int MODE>
PF_INLINE PfGrad pf_gradient_sums(const long long c, const float* RESTRICT phi, const unsigned char* RESTRICT flags,
                                  const long long sy, const long long sz, const unsigned int mask) {
    const float p0 = phi[c];
    // scalar accumulators, copied into the struct at the end: accumulated in the struct's fields, g++ 12 kept it
    // in memory in some variants (CK_PF_SOURCE=0: "not suitable for scatter store", the collide's x loops scalar)
    float gx = 0.f, gy = 0.f, gz = 0.f, lap = 0.f;
    // the strides through CK_PER_ITEM (common.cuh): inside phase_collide_stream the 26 offsets were otherwise
    // computed once and kept live (sm_90: 95 -> 128 registers with the stencil in the collide)
    const long long isy = CK_PER_ITEM(sy), isz = CK_PER_ITEM(sz);
    PF_UNROLL
    for (int k = 0; k < 27; ++k) {
        const int dx = k % 3 - 1, dy = (k / 3) % 3 - 1, dz = k / 9 - 1;
        const long long o = c + dx + isy * dy + isz * dz;
        // 0 / 1 as 32-bit values and a blend (ck_select): a bool select kept the host mask loop scalar
        const unsigned int fluid = MODE == PF_NB_BULK ? 1u
                                                      : (MODE == PF_NB_MASK ? ((mask >> k) & 1u)
                                                                            : (unsigned int)(flags[o] == PF_FLUID));
#if CK_ON_GPU
        const float v = fluid ? phi[o] : p0;  // the load only where needed (the blend's load: 56 -> 80 registers)
#else
        const float v = ck_select(fluid, phi[o], p0);
#endif
        const float w = PF_W27_CUBE[k];
        gx += (w * dx) * v;
        gy += (w * dy) * v;
        gz += (w * dz) * v;
        lap += w * (v - p0);
    }
    PfGrad g;
    g.x = gx, g.y = gy, g.z = gz, g.lap = lap;
    return g;
}

// Gradient sums from three values (a temporary for pf_collide; lap is not used there).
PF_INLINE PfGrad pf_grad_of(const float x, const float y, const float z) {
    PfGrad g;
    g.x = x, g.y = y, g.z = z, g.lap = 0.f;
    return g;
}

#if !CK_ON_GPU
// Host: the gradient sums of the `len` cells from padded index c0 into gx, gy, gz (stack buffers of the collide's
// row chunk), by one `omp simd` loop; MODE as pf_gradient_sums (`masks`: pf_fluid_masks of the chunk, read with
// PF_NB_MASK only).
template <int MODE>
static inline __attribute__((always_inline)) void pf_gradient_chunk(const long long c0, const int len,
                                                                    const float* RESTRICT phi,
                                                                    const unsigned char* RESTRICT flags,
                                                                    const long long sy, const long long sz,
                                                                    const unsigned int* RESTRICT masks,
                                                                    float* RESTRICT gx, float* RESTRICT gy,
                                                                    float* RESTRICT gz) {
    CK_SIMD_SHORT
    for (int i = 0; i < len; ++i) {
        const PfGrad g = pf_gradient_sums<MODE>(c0 + i, phi, flags, sy, sz, MODE == PF_NB_MASK ? masks[i] : 0u);
        gx[i] = g.x;
        gy[i] = g.y;
        gz[i] = g.z;
    }
}
#endif

// One cell c of phase_gradients (see pf_gradient_sums for MODE; with PF_NB_MASK bit 13 of `mask` says whether c
// itself is FLUID, else c gets zeros).  The same terms in the same order in all three modes (bitwise equal).
template <int MODE>
PF_INLINE void pf_gradient_cell(const long long c, const float* RESTRICT phi, const unsigned char* RESTRICT flags,
                                float* RESTRICT grad, float* RESTRICT mu, const long long sy, const long long sz,
                                const long long ncell, const float beta, const float kappa,
                                const unsigned int mask) {
    const PfGrad g = pf_gradient_sums<MODE>(c, phi, flags, sy, sz, mask);
#if !CK_PF_SURFACE_TENSION
    (void)mu, (void)beta, (void)kappa;
#endif
    // MODE == PF_NB_MASK: a non-fluid cell gets zeros (a select, so the host mask loop has no branch)
    const unsigned int self = MODE == PF_NB_MASK ? ((mask >> 13) & 1u) : 1u;
    // Eq. 21: 3 sum_j w_j c_j phi(x + c_j)  (3 = 1/cs^2 of D3Q27)
    grad[c] = ck_select(self, 3.f * g.x, 0.f);
    grad[ncell + c] = ck_select(self, 3.f * g.y, 0.f);
    grad[2 * ncell + c] = ck_select(self, 3.f * g.z, 0.f);
#if CK_PF_SURFACE_TENSION
    // Eqs. 22-23
    const float p0 = phi[c];
    mu[c] = ck_select(self, 4.f * beta * p0 * (p0 - 1.f) * (p0 - 0.5f) - kappa * (6.f * g.lap), 0.f);
#endif
}

KERNEL void phase_gradients(const long long n, const float* RESTRICT phi /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                            const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                            float* RESTRICT grad /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */, float* RESTRICT mu /* size >= 1 */,
                            const int nx, const int ny, const int nz, const float beta, const float kappa) {
    const long long sy = (long long)(nx + 2), sz = (long long)(nx + 2) * (ny + 2);
    const long long ncell = sz * (nz + 2);
#if CK_ON_GPU
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        const long long c = (x + 1) + sy * (y + 1) + sz * (z + 1);
        if (flags[c] != PF_FLUID) {
            grad[c] = 0.f;
            grad[ncell + c] = 0.f;
            grad[2 * ncell + c] = 0.f;
#if CK_PF_SURFACE_TENSION
            mu[c] = 0.f;
#endif
            continue;
        }
        pf_gradient_cell<PF_NB_FLAGS>(c, phi, flags, grad, mu, sy, sz, ncell, beta, kappa, 0u);
    }
#else
    // host row scheme (lbm_rows_all_fluid): the 27 flag reads per cell in the x loop made this 21 B/cell stage
    // cost a quarter of the flow collide
    CK_PRAGMA(omp parallel for collapse(2) schedule(static))
    for (int z = 0; z < nz; ++z)
        for (int y = 0; y < ny; ++y) {
            const long long row = sy * (y + 1) + sz * (z + 1);
            if (lbm_rows_all_fluid(flags, row, 0, nx + 1, (int)sy, sz)) {
                CK_PRAGMA(omp simd)
                for (int x = 1; x <= nx; ++x)
                    pf_gradient_cell<PF_NB_BULK>(row + x, phi, flags, grad, mu, sy, sz, ncell, beta, kappa, 0u);
                continue;
            }
            unsigned int masks[PF_ROW_CHUNK], scratch[9 * (PF_ROW_CHUNK + 2)];
            for (int x0 = 1; x0 <= nx; x0 += PF_ROW_CHUNK) {
                const int len = nx + 1 - x0 < PF_ROW_CHUNK ? nx + 1 - x0 : PF_ROW_CHUNK;
                const long long c0 = row + x0;
                pf_fluid_masks(flags, c0, len, sy, sz, masks, scratch);
                CK_PRAGMA(omp simd)
                for (int i = 0; i < len; ++i)
                    pf_gradient_cell<PF_NB_MASK>(c0 + i, phi, flags, grad, mu, sy, sz, ncell, beta, kappa, masks[i]);
            }
        }
#endif
}

// Error-free transformation (Knuth's TwoSum): s + e == a + b exactly, in float arithmetic.  Used to keep
// Sigma phi exact to one rounding per cell without double precision (which blocks host vectorisation).
PF_INLINE void pf_two_sum(const float a, const float b, float& s, float& e) {
    s = a + b;
    const float bb = s - a;
    e = (a - (s - bb)) + (b - bb);
}

// Compensated accumulation: (sum + comp) carries the running total to about one rounding.
PF_INLINE void pf_accumulate(float& sum, float& comp, const float term) {
    float err;
    pf_two_sum(sum, term, sum, err);
    comp += err;
}

// The 7 populations of one cell, by value (a local array inside the cell loop, or scalars passed by
// reference, stop the host compiler from vectorising the loop).
struct PfCell {
    float f0, f1, f2, f3, f4, f5, f6;
};

// Post-collision value of one moving population q (Eq. 48): relaxation to h_q^eq (feq) plus the interface and
// source terms, minus `sym`, the two-relaxation-time part of the pair q, opp q (pf_collide); accumulates -h*_q
// into the compensated rest balance.
PF_INLINE float pf_relax(const int q, const float fq, const float feq, const float sym, const float hx, const float hy,
                         const float hz, const float s, const float omega, float& rest, float& rest_comp) {
    float post = fq - omega * (fq - feq) - sym + W7[q] * (pf_dot(q, hx, hy, hz) + s);
#if CK_STORAGE_FP16
    // rounded to the storage here, so that the rest population (the exact balance) takes the six moving
    // populations' rounding: sum phi then changes per cell by the rounding of h_0 alone, not by seven binary16
    // roundings
    {
        ck_store_t r;
        PF_ST(&r, q, 0, post);
        post = PF_LD(&r, q, 0);
    }
#endif
    pf_accumulate(rest, rest_comp, -post);
    return post;
}

// Collision of Eq. 48 of cell c (see phase_collide_stream): pre-collision populations in, post out.
PF_INLINE PfCell pf_collide(const PfCell in, const long long c, const long long ncell, const PfGrad grad,
                            const float* RESTRICT u, const float* RESTRICT source, const float omega,
                            const float interface_factor, const float source_scale, const float omega_plus) {
    // Eq. 47 with compensated sums: together with the rest population below, Sigma phi changes per step
    // only by the source and one float32 rounding per cell (plain float32 sums drifted ~50x more in
    // steady states, where the same rounding repeats every step)
    float mass = in.f0, mass_comp = 0.f;
    pf_accumulate(mass, mass_comp, in.f1);
    pf_accumulate(mass, mass_comp, in.f2);
    pf_accumulate(mass, mass_comp, in.f3);
    pf_accumulate(mass, mass_comp, in.f4);
    pf_accumulate(mass, mass_comp, in.f5);
    pf_accumulate(mass, mass_comp, in.f6);
    const float p0 = mass + mass_comp;
    // Eq. 21: grad phi = 3 sum_j w_j c_j phi(x + c_j) of this step's phi (pf_gradient_sums; 3 = 1/cs^2 of D3Q27)
    const float gx = 3.f * grad.x, gy = 3.f * grad.y, gz = 3.f * grad.z;
    const float g2 = gx * gx + gy * gy + gz * gz;
    // (1 - omega/2) |H| / |grad phi|, Eq. 49.  The guard is a 32-bit blend (ck_select), not fmaxf or a float
    // select: with either, g++ 12 left every x loop of this kernel scalar ("control flow in loop")
    const unsigned int big = (unsigned int)(g2 > PF_GRAD_EPS2);
    const float g2_safe = ck_select(big, g2, PF_GRAD_EPS2);
    const float hscale = ck_select(big, interface_factor * p0 * (1.f - p0) / sqrtf(g2_safe), 0.f);
    const float hx = hscale * gx, hy = hscale * gy, hz = hscale * gz;
#if CK_PF_SOURCE
    const float s = source_scale * source[c];
#else
    (void)source;
    (void)source_scale;
    const float s = 0.f;
#endif
    const float ux = u[c], uy = u[ncell + c], uz = u[2 * ncell + c];
    // rest population from the exact local balance sum_k h*_k = sum_k h_k + S_phi (the H_k sum to zero
    // and the equilibria to phi); equal to the collision formula for q = 0 up to rounding
    float rest = mass, rest_comp = mass_comp;
    pf_accumulate(rest, rest_comp, s);
    // two relaxation times (TRT): the symmetric part (n_q + n_opp q) / 2 of the non-equilibrium n = h - h^eq of
    // each pair relaxes at omega_plus instead of omega (the antisymmetric part, which carries the flux and sets
    // M, keeps omega): h*_q = h_q - omega n_q - (omega_plus - omega) (n_q + n_opp q) / 2 + ...  With
    // omega_plus = omega (trt_lambda = 0) the correction is exactly 0: Eq. 48's single rate.
    const float e1 = pf_feq(1, p0, ux, uy, uz), e2 = pf_feq(2, p0, ux, uy, uz), e3 = pf_feq(3, p0, ux, uy, uz);
    const float e4 = pf_feq(4, p0, ux, uy, uz), e5 = pf_feq(5, p0, ux, uy, uz), e6 = pf_feq(6, p0, ux, uy, uz);
    const float dw = 0.5f * (omega_plus - omega);
    const float s12 = dw * ((in.f1 - e1) + (in.f2 - e2)), s34 = dw * ((in.f3 - e3) + (in.f4 - e4));
    const float s56 = dw * ((in.f5 - e5) + (in.f6 - e6));
    PfCell out;
    out.f1 = pf_relax(1, in.f1, e1, s12, hx, hy, hz, s, omega, rest, rest_comp);
    out.f2 = pf_relax(2, in.f2, e2, s12, hx, hy, hz, s, omega, rest, rest_comp);
    out.f3 = pf_relax(3, in.f3, e3, s34, hx, hy, hz, s, omega, rest, rest_comp);
    out.f4 = pf_relax(4, in.f4, e4, s34, hx, hy, hz, s, omega, rest, rest_comp);
    out.f5 = pf_relax(5, in.f5, e5, s56, hx, hy, hz, s, omega, rest, rest_comp);
    out.f6 = pf_relax(6, in.f6, e6, s56, hx, hy, hz, s, omega, rest, rest_comp);
    out.f0 = rest + rest_comp;
    return out;
}

// One phase-field step: load h at parity t (AA), collide (Eq. 48), store (stream in place).
//   h*_k = h_k - omega (h_k - h_k^eq) + (1 - omega/2) H_k + S_k
//   H_k = w_k d_k . H,  H = (4/W) phi (1 - phi) grad(phi)/|grad(phi)|   (Eqs. 49-50; the (1 - omega/2)
//         factor makes the recovered counter-flux M H, notes §1c pitfall)
//   S_k = w_k gamma S_phi  (Eq. 51, source corrected by the volume controller factor gamma, Eq. 52)
//   omega = 1/tau, tau = M / cs^2 + 1/2 (mobility M, cs^2 = 1/4)
//   trt_lambda > 0: two relaxation times, the pairs' symmetric non-equilibrium relaxed at omega_plus with
//         (1/omega - 1/2)(1/omega_plus - 1/2) = trt_lambda (Ginzburg's "magic" product; 0 = Eq. 48's single rate)
// grad phi (Eq. 21) is computed here from phi of the same step (pf_gradient_sums; phi with its ghost layer filled,
// phase_macroscopic): no stored gradient field, no pass of its own.  u: fluid velocity (and the velocity of
// INFLOW cells); phi: also the phase value of INFLOW cells; source: S_phi.  n = nx*ny*nz.
KERNEL void phase_collide_stream(const long long n, ck_store_t* RESTRICT h /* size: 7 * (nx + 2) * (ny + 2) * (nz + 2) */,
                                 const float* RESTRICT phi /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                 const float* RESTRICT u /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
                                 const float* RESTRICT source /* size >= 1 */ /* (nx + 2)(ny + 2)(nz + 2); a placeholder with CK_PF_SOURCE=0 */,
                                 const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                 const int nx, const int ny, const int nz, const int px, const int py,
                                 const int pz, const int parity, const float mobility, const float width,
                                 const float source_scale, const float trt_lambda) {
    const long long ncell = (long long)(nx + 2) * (ny + 2) * (nz + 2);
    const long long sy = (long long)(nx + 2), sz = sy * (ny + 2);
    const float omega = 1.f / (mobility / CS2_7 + 0.5f);
    const float omega_plus = trt_lambda > 0.f ? 1.f / (0.5f + trt_lambda / (1.f / omega - 0.5f)) : omega;
    const float interface_factor = (1.f - 0.5f * omega) * 4.f / width;
    // the gradient of cell c by stencil mode MODE (pf_gradient_sums) and the per-cell arguments of pf_collide
#define PF_GRAD(MODE, mask) pf_gradient_sums<MODE>(c, phi, flags, sy, sz, mask)
#define PF_CELL_ARGS(G) c, ncell, G, u, source, omega, interface_factor, source_scale, omega_plus
    // GPU: the gradient G into a variable before the population loads (its stencil then does not keep the 7
    // populations live: sm_90 128 -> 115 registers); host: G passed as a temporary, since a named struct in the
    // `omp simd` loop body was kept in memory by g++ 12 ("not suitable for scatter store": every x loop scalar)
#if CK_ON_GPU
#define PF_GRAD_FIRST(G) const PfGrad g_ = G;
#define PF_GRAD_ARG(G) g_
#else
#define PF_GRAD_FIRST(G)
#define PF_GRAD_ARG(G) G
#endif
    // even step of cell c, flag test included (PF_ST_EVEN: the AA even store)
#define PF_EVEN_SKIP \
    if (flags[c] != PF_FLUID) continue;
#define PF_ST_EVEN(q, i, v) PF_ST(h, q, i, v)
#if !CK_ON_GPU
    // host rows with non-fluid cells: every cell is computed and a non-fluid one (live = 0, from flags widened
    // to 32 bits before the loop) stores its slots' own bits back, blended without a branch.  A skip of
    // non-fluid cells, a bool, or a flag byte read in the loop each left it scalar (g++ 12, -fopt-info-vec).
    // The even step writes only the cell's own slots, so the write-back races with nothing.
#define PF_ST_GUARDED(q, i, v)                       \
    {                                                \
        ck_store_t new_;                             \
        PF_ST(&new_, q, 0, v);                       \
        h[i] = ck_store_blend(live, new_, h[i]);     \
    }
#endif
    // the even step's body after the skip: load, collide with gradient sums G, store in the opposite slots (AA
    // even step)
#define PF_EVEN_BODY(ST, G)                                                                                 \
    {                                                                                                       \
        PF_GRAD_FIRST(G)                                                                                    \
        PfCell in;                                                                                          \
        in.f0 = PF_LD(h, 0, c);                                                                             \
        in.f1 = PF_LD(h, 1, ncell + c);                                                                     \
        in.f2 = PF_LD(h, 2, 2 * ncell + c);                                                                 \
        in.f3 = PF_LD(h, 3, 3 * ncell + c);                                                                 \
        in.f4 = PF_LD(h, 4, 4 * ncell + c);                                                                 \
        in.f5 = PF_LD(h, 5, 5 * ncell + c);                                                                 \
        in.f6 = PF_LD(h, 6, 6 * ncell + c);                                                                 \
        const PfCell out = pf_collide(in, PF_CELL_ARGS(PF_GRAD_ARG(G)));                                    \
        ST(0, c, out.f0);                                                                                   \
        ST(2, 2 * ncell + c, out.f1);                                                                       \
        ST(1, ncell + c, out.f2);                                                                           \
        ST(4, 4 * ncell + c, out.f3);                                                                       \
        ST(3, 3 * ncell + c, out.f4);                                                                       \
        ST(6, 6 * ncell + c, out.f5);                                                                       \
        ST(5, 5 * ncell + c, out.f6);                                                                       \
    }
    // the odd step of interior cell (X, Y, Z) with the boundary rules (pf_load / pf_store), gradient G
#define PF_ODD_CELL(X, Y, Z, G)                                                                             \
    {                                                                                                       \
        long long nb[7];                                                                                    \
        pf_neighbours(X, Y, Z, nx, ny, nz, px, py, pz, nb);                                                 \
        const long long c = nb[0];                                                                          \
        if (flags[c] == PF_FLUID) {                                                                         \
            PF_GRAD_FIRST(G)                                                                                \
            float f[7];                                                                                     \
            pf_load<1>(h, flags, phi, u, ncell, nb, 1, f);                                                  \
            PfCell in;                                                                                      \
            in.f0 = f[0];                                                                                   \
            in.f1 = f[1];                                                                                   \
            in.f2 = f[2];                                                                                   \
            in.f3 = f[3];                                                                                   \
            in.f4 = f[4];                                                                                   \
            in.f5 = f[5];                                                                                   \
            in.f6 = f[6];                                                                                   \
            const PfCell out = pf_collide(in, PF_CELL_ARGS(PF_GRAD_ARG(G)));                                \
            const float post[7] = {out.f0, out.f1, out.f2, out.f3, out.f4, out.f5, out.f6};                 \
            pf_store(h, flags, phi, u, ncell, nb, 1, post);                                                 \
        }                                                                                                   \
    }
#if CK_ON_GPU
    // two loops, so that the local even step has no neighbour logic
    if (!(parity & 1)) {
        FOR_EACH_CELL(x, y, z, nx, ny, nz) {
            const long long c = (x + 1) + sy * (y + 1) + sz * (z + 1);
            PF_EVEN_SKIP
            PF_EVEN_BODY(PF_ST_EVEN, PF_GRAD(PF_NB_FLAGS, 0u))
        }
    } else {
        FOR_EACH_CELL(x, y, z, nx, ny, nz) PF_ODD_CELL(x + 1, y + 1, z + 1, PF_GRAD(PF_NB_FLAGS, 0u))
    }
#else
    // host row scheme: a bulk run takes a flag-free `omp simd` loop, the odd one with the row's constant neighbour
    // offsets (pull from h[opp q][c - d_q], push to h[q][c + d_q]: in a bulk run no link meets a boundary);
    // everything else the per-cell code of the GPU path.  The gradient of a chunk of cells is computed first, by
    // its own `omp simd` loop into a stack buffer (pf_gradient_chunk): PF_NB_BULK where the 9 rows around are
    // all FLUID (lbm_rows_all_fluid), else with the neighbour masks of pf_fluid_masks (bit 13: the cell itself,
    // the even step's `live`).  The stencil inside the collide loop measured slower (48^3 walled box, 1 thread:
    // 2.9 ms against 2.35 for the former gradient pass + collide; its loop body holds the 7 populations and the
    // stencil in 16 AVX2 registers), the buffer stays in L1.  The same arithmetic per cell everywhere.
#define PF_ST_BULK(q, i, v) PF_ST(h, q, i, v)
    // gradient sums of chunk cell i from the buffers (a temporary: see PF_GRAD_ARG)
#define PF_GRAD_BUF(i) pf_grad_of(gbx[i], gby[i], gbz[i])
    if (!(parity & 1)) {
        CK_PRAGMA(omp parallel for collapse(2) schedule(static))
        for (int z = 0; z < nz; ++z)
            for (int y = 0; y < ny; ++y) {
                const long long row = sy * (y + 1) + sz * (z + 1);
                const bool bulk9 = lbm_rows_all_fluid(flags, row, 0, nx + 1, (int)sy, sz);
                unsigned int masks[PF_ROW_CHUNK], scratch[9 * (PF_ROW_CHUNK + 2)];
                float gbx[PF_ROW_CHUNK], gby[PF_ROW_CHUNK], gbz[PF_ROW_CHUNK];
                // a masked row from its first to its last fluid cell (the others are left as they are)
                int lo = 1, hi = nx;
                if (!bulk9) lbm_row_fluid_span(flags, row, nx, lo, hi);
                const int rem = lbm_row_tail(lo, hi);
                for (int x0 = lo; x0 <= hi;) {
                    int len;
                    long long c0;
                    const int tail = lbm_row_chunk(x0, hi, rem, PF_ROW_CHUNK, row, len, c0);
                    if (bulk9 && !tail) {
                        pf_gradient_chunk<PF_NB_BULK>(c0, len, phi, flags, sy, sz, masks, gbx, gby, gbz);
                        CK_PRAGMA(omp simd)
                        for (int i = 0; i < len; ++i) {
                            const long long c = c0 + i;
                            PF_EVEN_BODY(PF_ST_BULK, PF_GRAD_BUF(i))
                        }
                        continue;
                    }
                    pf_fluid_masks(flags, c0, len, sy, sz, masks, scratch);
                    pf_gradient_chunk<PF_NB_MASK>(c0, len, phi, flags, sy, sz, masks, gbx, gby, gbz);
                    if (tail)
                        for (int i = 0; i < LBM_VEC - rem; ++i) masks[i] &= ~(1u << 13);  // done: kept
                    CK_PRAGMA(omp simd)
                    for (int i = 0; i < len; ++i) {
                        const long long c = c0 + i;
                        const unsigned int live = (masks[i] >> 13) & 1u;
                        PF_EVEN_BODY(PF_ST_GUARDED, PF_GRAD_BUF(i))
                    }
                }
            }
    } else {
        // the bulk run's odd x loop (X = xa .. xb, the row's neighbour offsets o1..o6), gradient G
#define PF_ODD_RUN(xa, xb, G)                                                                               \
    CK_SIMD_SHORT                                                                                           \
    for (int X = (xa); X <= (xb); ++X) {                                                                    \
        const long long c = row + X;                                                                        \
        PF_GRAD_FIRST(G)                                                                                    \
        PfCell in;                                                                                          \
        in.f0 = PF_LD(h, 0, c);                                                                             \
        in.f1 = PF_LD(h, 1, 2 * ncell + c + o2);                                                            \
        in.f2 = PF_LD(h, 2, ncell + c + o1);                                                                \
        in.f3 = PF_LD(h, 3, 4 * ncell + c + o4);                                                            \
        in.f4 = PF_LD(h, 4, 3 * ncell + c + o3);                                                            \
        in.f5 = PF_LD(h, 5, 6 * ncell + c + o6);                                                            \
        in.f6 = PF_LD(h, 6, 5 * ncell + c + o5);                                                            \
        const PfCell out = pf_collide(in, PF_CELL_ARGS(PF_GRAD_ARG(G)));                                    \
        PF_ST(h, 0, c, out.f0);                                                                             \
        PF_ST(h, 1, ncell + c + o1, out.f1);                                                                \
        PF_ST(h, 2, 2 * ncell + c + o2, out.f2);                                                            \
        PF_ST(h, 3, 3 * ncell + c + o3, out.f3);                                                            \
        PF_ST(h, 4, 4 * ncell + c + o4, out.f4);                                                            \
        PF_ST(h, 5, 5 * ncell + c + o5, out.f5);                                                            \
        PF_ST(h, 6, 6 * ncell + c + o6, out.f6);                                                            \
    }
        CK_PRAGMA(omp parallel for collapse(2) schedule(static))
        for (int Z = 1; Z <= nz; ++Z)
            for (int Y = 1; Y <= ny; ++Y) {
                long long off[7];
                const bool bulk = pf_bulk_row<1>(flags, Y, Z, nx, ny, nz, px, py, pz, off);
                const long long row = sy * Y + sz * Z;
                const int xa = bulk ? 2 : nx + 1, xb = bulk ? nx - 1 : nx;
                const long long o1 = off[1], o2 = off[2], o3 = off[3], o4 = off[4], o5 = off[5], o6 = off[6];
                // chunks of the row: the gradient of every cell first (a vector loop, also for the boundary cells,
                // whose per-cell code was 2x the odd step's time with the stencil's 27 flag reads inside it), then
                // the bulk run's part of the chunk, then its other cells
                const bool bulk9 = bulk && lbm_rows_all_fluid(flags, row, 0, nx + 1, (int)sy, sz);
                unsigned int masks[PF_ROW_CHUNK], scratch[9 * (PF_ROW_CHUNK + 2)];
                float gbx[PF_ROW_CHUNK], gby[PF_ROW_CHUNK], gbz[PF_ROW_CHUNK];
                // a row with non-fluid cells: from its first to its last fluid cell only (PF_ODD_CELL does
                // nothing in the others), and within that span the runs of cells whose six neighbours are fluid
                // (no link meets a boundary) by the bulk run's vector loop, the others per cell
                int lo = 1, hi = nx;
                if (!bulk) lbm_row_fluid_span(flags, row, nx, lo, hi);
                for (int x0 = lo; x0 <= hi; x0 += PF_ROW_CHUNK) {
                    const int len = hi + 1 - x0 < PF_ROW_CHUNK ? hi + 1 - x0 : PF_ROW_CHUNK;
                    if (bulk9) {
                        pf_gradient_chunk<PF_NB_BULK>(row + x0, len, phi, flags, sy, sz, masks, gbx, gby, gbz);
                    } else {
                        pf_fluid_masks(flags, row + x0, len, sy, sz, masks, scratch);
                        pf_gradient_chunk<PF_NB_MASK>(row + x0, len, phi, flags, sy, sz, masks, gbx, gby, gbz);
                    }
                    if (bulk) {
                        const int ra = xa > x0 ? xa : x0, rb = xb < x0 + len - 1 ? xb : x0 + len - 1;
                        if (ra <= rb) PF_ODD_RUN(ra, rb, PF_GRAD_BUF(X - x0))
                        for (int X = x0; X < x0 + len; ++X)
                            if (X < xa || X > xb) PF_ODD_CELL(X, Y, Z, PF_GRAD_BUF(X - x0))
                        continue;
                    }
                    for (int xs = x0; xs < x0 + len;) {
                        if (!pf_odd_run_cell(flags, row, xs, nx, off)) {
                            PF_ODD_CELL(xs, Y, Z, PF_GRAD_BUF(xs - x0))
                            ++xs;
                            continue;
                        }
                        int xe = xs;
                        while (xe + 1 < x0 + len && pf_odd_run_cell(flags, row, xe + 1, nx, off)) ++xe;
                        PF_ODD_RUN(xs, xe, PF_GRAD_BUF(X - x0))
                        xs = xe + 1;
                    }
                }
            }
#undef PF_ODD_RUN
    }
#undef PF_GRAD_BUF
#undef PF_ST_BULK
#undef PF_ST_GUARDED
#endif
#undef PF_ODD_CELL
#undef PF_EVEN_BODY
#undef PF_EVEN_SKIP
#undef PF_ST_EVEN
#undef PF_CELL_ARGS
#undef PF_GRAD_FIRST
#undef PF_GRAD_ARG
#undef PF_GRAD
}

// Both sums of a mixture's volume controller (Eq. 52) in one pass, float64 over interior FLUID cells:
//   out[0] += sum eps phi,  out[1] += sum eps S_phi  (n = ny*nz, one work item per x row).
// Each row sums in x order and the rows combine as in phase_volume_sums_eps, so the two are bitwise what two
// calls of that kernel (phi, then S_phi in its place) give; one read of the flags and the porosity instead of
// two, and no unused sum S_phi (the two calls computed it twice and dropped it).  The two add chains of a row
// run side by side: the separate calls were four float64 chains one after the other (latency-bound).
KERNEL void phase_volume_sums_mixture(const long long n,
                                      const float* RESTRICT phi /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                      const float* RESTRICT eps /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                      const float* RESTRICT source /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                      const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                      double* RESTRICT out /* size: 2 */, const int nx, const int ny,
                                      const int nz) {
    const long long sy = (long long)(nx + 2), sz = (long long)(nx + 2) * (ny + 2);
    (void)nz;
    REDUCE_SUM2_BEGIN(row, n, acc_v, acc_s) {
        const long long c0 = 1 + sy * (row % ny + 1) + sz * (row / ny + 1);
        double v = 0.0, s = 0.0;
        for (int x = 0; x < nx; ++x) {
            const bool fluid = flags[c0 + x] == PF_FLUID;
            const double e = (double)eps[c0 + x];
            v += fluid ? e * (double)phi[c0 + x] : 0.0;
            s += fluid ? e * (double)source[c0 + x] : 0.0;
        }
        acc_v += v;
        acc_s += s;
    }
    REDUCE_SUM2_END(out, acc_v, acc_s)
}

// Global volume sums for the volume controller (Eq. 52), in float64 over interior FLUID cells:
//   out[0] += sum phi,  out[1] += sum S_phi.  n = ny*nz (one work item per x row).
KERNEL void phase_volume_sums(const long long n, const float* RESTRICT phi /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                              const float* RESTRICT source /* size >= 1 */ /* (nx + 2)(ny + 2)(nz + 2); a placeholder with CK_PF_SOURCE=0 */,
                              const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                              double* RESTRICT out /* size: 2 */, const int nx, const int ny, const int nz) {
    const long long sy = (long long)(nx + 2), sz = (long long)(nx + 2) * (ny + 2);
    REDUCE_SUM_BEGIN(row, n, acc) {
        const long long c0 = 1 + sy * (row % ny + 1) + sz * (row / ny + 1);
        double s = 0.0;
        for (int x = 0; x < nx; ++x) s += flags[c0 + x] == PF_FLUID ? (double)phi[c0 + x] : 0.0;
        acc += s;
    }
    REDUCE_SUM_END(out, acc)
#if CK_PF_SOURCE
    REDUCE_SUM_BEGIN(row, n, acc_s) {
        const long long c0 = 1 + sy * (row % ny + 1) + sz * (row / ny + 1);
        double s = 0.0;
        for (int x = 0; x < nx; ++x) s += flags[c0 + x] == PF_FLUID ? (double)source[c0 + x] : 0.0;
        acc_s += s;
    }
    REDUCE_SUM_END(out + 1, acc_s)
#else
    (void)source;  // out[1] stays the 0 the caller zeroed: sum S_phi = 0
#endif
}

// As phase_volume_sums with the fluid volume fraction eps of the mixture (Eq. 45's epsilon):
//   out[0] += sum eps phi (the heavy-fluid volume),  out[1] += sum S_phi.  n = ny*nz.
KERNEL void phase_volume_sums_eps(const long long n, const float* RESTRICT phi /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const float* RESTRICT eps /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const float* RESTRICT source /* size >= 1 */ /* (nx + 2)(ny + 2)(nz + 2); a placeholder with CK_PF_SOURCE=0 */,
                                  const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                  double* RESTRICT out /* size: 2 */, const int nx, const int ny,
                                  const int nz) {
    const long long sy = (long long)(nx + 2), sz = (long long)(nx + 2) * (ny + 2);
    REDUCE_SUM_BEGIN(row, n, acc) {
        const long long c0 = 1 + sy * (row % ny + 1) + sz * (row / ny + 1);
        double s = 0.0;
        for (int x = 0; x < nx; ++x)
            s += flags[c0 + x] == PF_FLUID ? (double)eps[c0 + x] * (double)phi[c0 + x] : 0.0;
        acc += s;
    }
    REDUCE_SUM_END(out, acc)
#if CK_PF_SOURCE
    REDUCE_SUM_BEGIN(row, n, acc_s) {
        const long long c0 = 1 + sy * (row % ny + 1) + sz * (row / ny + 1);
        double s = 0.0;
        for (int x = 0; x < nx; ++x) s += flags[c0 + x] == PF_FLUID ? (double)source[c0 + x] : 0.0;
        acc_s += s;
    }
    REDUCE_SUM_END(out + 1, acc_s)
#else
    (void)source;  // out[1] stays the 0 the caller zeroed: sum S_phi = 0
#endif
}
