// Phase-field source term S_phi of the mixture (paper 000 Eq. 45; with water retention Eq. 57), the field
// the phase-field collision takes as its `source` input (Eq. 51; the volume controller of Eq. 52 scales it
// there).  Spec: couplekit/coupling/reference.py ReferenceOps.phase_source.  Lattice units (dt = 1).
//
//   S = -(phi / eps) [ (eps - eps_prev) + u . grad eps ]            (Eq. 45)
//   S = -(phi / eps) [ (eps - eps_prev) + u . grad eps ] - dR / eps  (Eq. 57, CK_RETENTION=1)
// eps is the porosity of this step after the retention update (1 - eps_s - R', Eq. 54), eps_prev that of
// the previous step, dR this step's bound-water increment (Eq. 55), phi the phase field of this step (not
// clamped: with u = 0 the update phi + S keeps sum(eps phi) + sum R exact, see ReferenceOps.phase_source),
// u the fluid velocity.  d eps/dt is the backward difference over the step (eps_prev -> eps), so
// the retention part of d eps/dt is -dR and Eq. 57's extra -dR/eps converts exactly the absorbed
// volume of free water into bound water.
// grad eps is the isotropic D3Q27 gradient (Eq. 18), grad s = sum_j 3 w_j c_j s(x + c_j), where a
// neighbour that is not a FLUID cell (flags != 0) contributes the centre value (the fluid's rule).
// Interior FLUID cells are written; other interior cells get S = 0; ghosts are not touched.
// variants: CK_RETENTION=0,1
#include "common.cuh"
#include "lattice.cuh"

#ifndef CK_RETENTION
#define CK_RETENTION 0
#endif

#define CPL_REP8(M, b) M(b + 0) M(b + 1) M(b + 2) M(b + 3) M(b + 4) M(b + 5) M(b + 6) M(b + 7)
#define CPL_REP26(M) CPL_REP8(M, 1) CPL_REP8(M, 9) CPL_REP8(M, 17) M(25) M(26)

// n = nx * ny * nz.  Without retention d_bound is not read (pass a 1-element array).
// the source of interior cell c (x, y, z) from its eps stencil; CPL_DIFF(q, nb) (defined by each path) is
// eps[nb] - e where neighbour q (index nb) is a FLUID cell, else 0 (GPU: its flag, a predicated load; host: the
// row chunk's widened flags and a blend), ISFLUID likewise for c, CPL_MAX_E(e) = fmaxf(e, 1e-6)
// STENCIL = 0 (host rows whose 3 x 3-row neighbourhood has eps exactly 1): grad eps is exactly +0 there (each term
// is w * 0, and +0 + -0 = +0), so the 26 terms are skipped and the same s results, bit for bit
#define CPL_SOURCE_CELL_S(ISFLUID, STENCIL)                                                             \
    {                                                                                                   \
        const float e = eps[c];                                                                         \
        float gx = 0.f, gy = 0.f, gz = 0.f;                                                             \
        /* straight-line over the 26 neighbours: an inner loop would stop the host's x-loop vectoriser */ \
        if (STENCIL) { CPL_REP26(CPL_GRAD_TERM) }                                                       \
        const float advect = u[c] * gx + u[N + c] * gy + u[2 * N + c] * gz;                             \
        const float inv_e = 1.f / CPL_MAX_E(e);                                                       \
        float s = -phi[c] * inv_e * ((e - eps_prev[c]) + advect); /* Eq. 45 */                         \
        CPL_RETENTION_TERM                                                                              \
        source[c] = ck_select(ISFLUID, s, 0.f); /* no early exit: keeps the host x loop vectorisable */ \
    }
#define CPL_SOURCE_CELL(ISFLUID) CPL_SOURCE_CELL_S(ISFLUID, 1)
#define CPL_GRAD_TERM(q)                                                                \
    {                                                                                   \
        const long long nb = c + CX27[q] + PX * (long long)CY27[q] + PXY * CZ27[q];     \
        const float w = 3.f * W27[q] * CPL_DIFF(q, nb);                                 \
        gx += w * (float)CX27[q];                                                       \
        gy += w * (float)CY27[q];                                                       \
        gz += w * (float)CZ27[q];                                                       \
    }
// the bound-water increment's index (unpadded): CPL_D_INDEX, defined by each path
#if CK_RETENTION
#define CPL_RETENTION_TERM s -= d_bound[CPL_D_INDEX] * inv_e; /* Eq. 57 */
#else
#define CPL_RETENTION_TERM
#endif

// host rows are processed in chunks of this many cells (their widened flags live on the stack)
#define CPL_ROW_CHUNK 256

// n = nx * ny * nz.  Without retention d_bound is not read (pass a 1-element array).
// eps_prev and source may be one array (no RESTRICT on either): each cell's eps_prev is read before that cell's
// source is written, and no other cell's eps_prev is read, so the schedulers keep S_phi in last step's porosity
// buffer (SandFluidCoupler.share_source_buffer, 4 B per cell).
KERNEL void coupling_phase_source(const long long n, const float* RESTRICT eps /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const float* eps_prev /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const float* RESTRICT phi /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const float* RESTRICT u /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const float* RESTRICT d_bound /* size >= 1 */,
                                  float* source /* size: (nx + 2) * (ny + 2) * (nz + 2) */, const int nx,
                                  const int ny, const int nz) {
    const int PX = nx + 2;
    const long long PXY = (long long)PX * (ny + 2);
    const long long N = PXY * (nz + 2);
#if CK_ON_GPU
// the GPU takes the original form: a conditional load and fmaxf (64-78 registers on sm_80/90; the host's blend
// form took 94-106 there)
#define CPL_DIFF(q, nb) (flags[nb] == 0 ? eps[nb] - e : 0.f)
#define CPL_MAX_E(e) fmaxf(e, 1e-6f)
#define CPL_D_INDEX (x + (long long)nx * (y + (long long)ny * z))
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        const long long c = (x + 1) + PX * (long long)(y + 1) + PXY * (z + 1);
        CPL_SOURCE_CELL((unsigned int)(flags[c] == 0))
    }
#undef CPL_DIFF
#undef CPL_MAX_E
#undef CPL_D_INDEX
#else
    // host: (z, y) rows in parallel; per chunk of a row the flags of its 9 neighbour rows (x - 1 .. x + len) are
    // widened to 32-bit 0/1 words first, so the x loop reads no byte data (26 flag bytes per cell read in the
    // loop left this stage at ~11 ns per cell, a third of the flow collide's time in Fig. 13 small)
#define CPL_D_INDEX (d0 + i)
// fmaxf as a blend (same value, NaN included): g++ does not if-convert fmaxf in the x loop
#define CPL_MAX_E(e) ck_select((unsigned int)((e) > 1e-6f), e, 1e-6f)
#define CPL_DIFF(q, nb) ck_select(CPL_NB(q), eps[nb] - e, 0.f)
#define CPL_NB(q) fl[((CY27[q] + 1) * 3 + (CZ27[q] + 1)) * (CPL_ROW_CHUNK + 2) + i + 1 + CX27[q]]
    CK_PRAGMA(omp parallel for collapse(2) schedule(static))
    for (int z = 0; z < nz; ++z)
        for (int y = 0; y < ny; ++y) {
            unsigned int fl[9 * (CPL_ROW_CHUNK + 2)];
            const long long row = PX * (long long)(y + 1) + PXY * (z + 1);
            // no sand around the row: eps exactly 1 in its 9-row neighbourhood, grad eps exactly 0 (CPL_SOURCE_CELL_S)
            const bool sandy = !ck_rows_equal(eps, row, 0, nx + 1, PX, PXY, 1.f);
            for (int x0 = 0; x0 < nx; x0 += CPL_ROW_CHUNK) {
                const int len = nx - x0 < CPL_ROW_CHUNK ? nx - x0 : CPL_ROW_CHUNK;
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dz = -1; dz <= 1; ++dz) {
                        const unsigned char* r = flags + row + dy * (long long)PX + dz * PXY + x0;  // x = x0 - 1 + 1
                        unsigned int* w = fl + ((dy + 1) * 3 + (dz + 1)) * (CPL_ROW_CHUNK + 2);
                        CK_SIMD_SHORT
                        for (int i = 0; i < len + 2; ++i) w[i] = r[i] == 0 ? 1u : 0u;
                    }
                const long long c0 = row + x0 + 1, d0 = x0 + (long long)nx * (y + (long long)ny * z);
                (void)d0;
                if (sandy) {
                    CK_PRAGMA(omp simd)
                    for (int i = 0; i < len; ++i) {
                        const long long c = c0 + i;
                        CPL_SOURCE_CELL_S(fl[4 * (CPL_ROW_CHUNK + 2) + i + 1], 1)
                    }
                } else {
                    CK_PRAGMA(omp simd)
                    for (int i = 0; i < len; ++i) {
                        const long long c = c0 + i;
                        CPL_SOURCE_CELL_S(fl[4 * (CPL_ROW_CHUNK + 2) + i + 1], 0)
                    }
                }
            }
        }
#undef CPL_NB
#undef CPL_DIFF
#undef CPL_MAX_E
#undef CPL_D_INDEX
#endif
#if !CK_RETENTION
    (void)d_bound;
#endif
}
#undef CPL_SOURCE_CELL
#undef CPL_GRAD_TERM
#undef CPL_RETENTION_TERM
