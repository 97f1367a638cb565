// Shared pieces of the LBM flow kernels: padded-grid indexing, cell flags, the AA-pattern load/store rules
// with their boundary rules, the isotropic stencils.  Mirrors couplekit/fluid/reference.py (the spec).
//
// Grid: every field has one ghost layer: interior nx*ny*nz, padded Px = nx+2, Py = ny+2, Pz = nz+2, linear
// padded index x + Px*(y + Py*z).  Distributions are SoA: slot j of cell c is f[j*N + c], N = Px*Py*Pz.
//
// AA pattern (one copy of f).  Even parity: f_j = F[j][c]; store F[opp j][c] = f*_j (local).
// Odd parity: f_j = F[opp j][c - c_j] (pull), store F[j][c + c_j] = f*_j (push).  Boundary rules, odd only:
//   neighbour c - c_j is WALL/INFLOW: f_j = F[j][c] + 6 w_j c_j.u_w  (u_w = velocity stored at the wall cell)
//   push to WALL/INFLOW c + c_j:      F[opp j][c] = f*_j - 6 w_j c_j.u_w
// OUTFLOW ghosts are read and pushed to like fluid cells: lbm_halo_copy fills them from their nearest interior
// cell before an odd step (zero-gradient f*), lbm_outflow_fix sets what they would have pushed after it.
#pragma once
#include "common.cuh"
#include "lattice.cuh"

#define FLAG_FLUID 0
#define FLAG_WALL 1
#define FLAG_INFLOW 2
#define FLAG_OUTFLOW 3

#if defined(__CUDACC__)
#define LBM_UNROLL _Pragma("unroll")
#else
#define LBM_UNROLL _Pragma("GCC unroll 32")
#endif

// neighbour offset of direction q in a padded grid with row length px and plane size pxy
#define LBM_OFFSET(q, px, pxy) ((long long)CX27[q] + (long long)(px) * CY27[q] + (long long)(pxy) * CZ27[q])

// populations f_j(x, t) of padded cell c under the read rule of the parity
DEVICE void lbm_load(const float* RESTRICT f, const unsigned char* RESTRICT flags, const float* RESTRICT vel,
                     const long long c, const long long N, const int px, const long long pxy, const int odd,
                     float* RESTRICT fj) {
    if (!odd) {
        LBM_UNROLL
        for (int q = 0; q < 27; ++q) fj[q] = f[q * N + c];
        return;
    }
    fj[0] = f[c];
    LBM_UNROLL
    for (int q = 1; q < 27; ++q) {
        const int qo = opposite_dir(q);
        const long long nb = c - LBM_OFFSET(q, px, pxy);
        const int fl = flags[nb];
        if (fl == FLAG_FLUID || fl == FLAG_OUTFLOW) {
            fj[q] = f[qo * N + nb];
        } else {
            const float cu = CX27[q] * vel[nb] + CY27[q] * vel[N + nb] + CZ27[q] * vel[2 * N + nb];
            fj[q] = f[q * N + c] + 6.f * W27[q] * cu;
        }
    }
}

// write post-collision populations of padded cell c under the write rule of the parity
DEVICE void lbm_store(float* RESTRICT f, const unsigned char* RESTRICT flags, const float* RESTRICT vel,
                      const long long c, const long long N, const int px, const long long pxy, const int odd,
                      const float* RESTRICT fs) {
    if (!odd) {
        LBM_UNROLL
        for (int q = 0; q < 27; ++q) f[opposite_dir(q) * N + c] = fs[q];
        return;
    }
    f[c] = fs[0];
    LBM_UNROLL
    for (int q = 1; q < 27; ++q) {
        const int qo = opposite_dir(q);
        const long long nb = c + LBM_OFFSET(q, px, pxy);
        const int fl = flags[nb];
        if (fl == FLAG_FLUID || fl == FLAG_OUTFLOW) {
            f[q * N + nb] = fs[q];
        } else {
            const float cu = CX27[q] * vel[nb] + CY27[q] * vel[N + nb] + CZ27[q] * vel[2 * N + nb];
            f[qo * N + c] = fs[q] - 6.f * W27[q] * cu;
        }
    }
}

// a neighbour whose scalar values enter the stencils: fluid, or an outflow ghost (which holds the outlet's
// reference value, e.g. p = 0: a pressure Dirichlet condition half a link beyond the last cell)
#define LBM_STENCIL_CELL(fl) ((fl) == FLAG_FLUID || (fl) == FLAG_OUTFLOW)

// Eq. 18 isotropic gradient; wall / inflow / solid neighbours take the centre value (their term vanishes)
DEVICE void lbm_gradient(const float* RESTRICT s, const unsigned char* RESTRICT flags, const long long c,
                         const int px, const long long pxy, float* RESTRICT g) {
    const float sc = s[c];
    float gx = 0.f, gy = 0.f, gz = 0.f;
    LBM_UNROLL
    for (int q = 1; q < 27; ++q) {
        const long long nb = c + LBM_OFFSET(q, px, pxy);
        const float d = LBM_STENCIL_CELL(flags[nb]) ? (s[nb] - sc) : 0.f;
        const float wd = 3.f * W27[q] * d;
        gx += CX27[q] * wd;
        gy += CY27[q] * wd;
        gz += CZ27[q] * wd;
    }
    g[0] = gx;
    g[1] = gy;
    g[2] = gz;
}
