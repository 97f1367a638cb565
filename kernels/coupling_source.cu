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
KERNEL void coupling_phase_source(const long long n, const float* RESTRICT eps /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const float* RESTRICT eps_prev /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const float* RESTRICT phi /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const float* RESTRICT u /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                  const float* RESTRICT d_bound /* size >= 1 */,
                                  float* RESTRICT source /* size: (nx + 2) * (ny + 2) * (nz + 2) */, const int nx,
                                  const int ny, const int nz) {
    const int PX = nx + 2;
    const long long PXY = (long long)PX * (ny + 2);
    const long long N = PXY * (nz + 2);
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        const long long c = (x + 1) + PX * (long long)(y + 1) + PXY * (z + 1);
        const float e = eps[c];
        float gx = 0.f, gy = 0.f, gz = 0.f;
        // straight-line over the 26 neighbours: an inner loop would stop the host's x-loop vectoriser
#define CPL_GRAD_TERM(q)                                                                \
    {                                                                                   \
        const long long nb = c + CX27[q] + PX * (long long)CY27[q] + PXY * CZ27[q];     \
        const float w = 3.f * W27[q] * (flags[nb] == 0 ? eps[nb] - e : 0.f);            \
        gx += w * (float)CX27[q];                                                       \
        gy += w * (float)CY27[q];                                                       \
        gz += w * (float)CZ27[q];                                                       \
    }
        CPL_REP26(CPL_GRAD_TERM)
#undef CPL_GRAD_TERM
        const float advect = u[c] * gx + u[N + c] * gy + u[2 * N + c] * gz;
        const float inv_e = 1.f / fmaxf(e, 1e-6f);
        float s = -phi[c] * inv_e * ((e - eps_prev[c]) + advect);  // Eq. 45
#if CK_RETENTION
        s -= d_bound[x + (long long)nx * (y + (long long)ny * z)] * inv_e;  // Eq. 57
#endif
        source[c] = flags[c] == 0 ? s : 0.f;  // no early exit: keeps the host x loop vectorisable
    }
#if !CK_RETENTION
    (void)d_bound;
#endif
}
