// D3Q7 conservative Allen–Cahn phase field (paper 000 §4.4, Eqs. 44–52) and the phase-field quantities the
// flow needs (normal / gradient Eq. 21, chemical potential Eqs. 22–23).  NumPy twin (the specification):
// couplekit/fluid/phasefield_reference.py.  Notes: shared/notes/lbm-method.md §1c (scheme), §1d (streaming).
//
// Storage (every field padded with ONE ghost layer on every side, as the flow's f):
//   padded extents NX = nx + 2, NY = ny + 2, NZ = nz + 2; interior cells have padded coordinates 1..nx etc.;
//   scalar fields (NZ, NY, NX), vectors (3, NZ, NY, NX), h (7, NZ, NY, NX), float32; linear index
//   c = X + NX*(Y + NY*Z), slot q of cell c at h[q*NCELL + c] with NCELL = NX*NY*NZ.
//   solid (NZ, NY, NX) uint8: 1 = obstacle cell (never updated); its ghost layer holds the mask of each ghost
//   cell's image (wrap on periodic axes, nearest interior cell on wall axes; see phasefield.pad_solid).
//
// Neighbours: the neighbour of an interior cell along d_q is the cell at constant offset, except on a
// periodic axis where the step out of the interior wraps to the other side (so the kernels never need
// ghost copies of h).  A link is BLOCKED when it leaves the interior on a wall (non-periodic) axis or ends
// in a solid cell; blocked links bounce back (no-flux wall for h, halfway in space and in time).
//
// In-place streaming, esoteric pull (Lehmann 2022; FluidX3D load_f/store_f), one copy of h.
// Pairs (j, j+1) with j odd and d_{j+1} = -d_j.  Step parity t (odd = t & 1), cell c, m = neighbour along
// d_j, a = (odd ? j : j+1), b = (odd ? j+1 : j):
//   load   f_0 = h[0][c];  f_j = h[a][c];  f_{j+1} = h[b][m]
//   store  h[0][c] = f*_0; h[b][m] = f*_j; h[a][c] = f*_{j+1}   (each value goes where its partner was read)
//   blocked fix (exact halfway bounce-back): if the link along d_j is blocked, f_{j+1} = h[a][m] (this
//   cell's own f*_j of the previous step, left in m as in a mailbox); if the link along d_{j+1} is blocked,
//   f_j = h[b][c] (this cell's own f*_{j+1} of the previous step).  Stores never change.
// So the populations of step t live at: f_q(c) = h[t odd ? q : opp(q)][c - (q even ? d_q : 0)].
// phase_set_equilibrium writes a state that loads as h^eq at a given parity (use it to initialise).
#include "common.cuh"
#include "lattice.cuh"

// 0: surface tension sigma = 0, the chemical potential (double well + Laplacian) is compiled out.
#ifndef CK_PF_SURFACE_TENSION
#define CK_PF_SURFACE_TENSION 1
#endif

// |grad phi|^2 below which the interface normal is set to zero (bulk phases, round-off gradients)
#define PF_GRAD_EPS2 1e-12f

#if CK_ON_GPU
#define PF_UNROLL _Pragma("unroll")
#else
#define PF_UNROLL _Pragma("GCC unroll 27")
#endif

// D3Q27 weights in 3x3x3 cube order, index (dz+1)*9 + (dy+1)*3 + (dx+1) (the isotropic stencils, Eqs. 21, 23)
CONSTANT float PF_W27_CUBE[27] = {
    1.f / 216, 1.f / 54, 1.f / 216, 1.f / 54, 2.f / 27, 1.f / 54, 1.f / 216, 1.f / 54, 1.f / 216,
    1.f / 54,  2.f / 27, 1.f / 54,  2.f / 27, 8.f / 27, 2.f / 27, 1.f / 54,  2.f / 27, 1.f / 54,
    1.f / 216, 1.f / 54, 1.f / 216, 1.f / 54, 2.f / 27, 1.f / 54, 1.f / 216, 1.f / 54, 1.f / 216,
};

// The 7 D3Q7 neighbours of interior cell (X, Y, Z) (padded coordinates) and which links are blocked.
DEVICE void pf_links(const int X, const int Y, const int Z, const int nx, const int ny, const int nz,
                     const int px, const int py, const int pz, const unsigned char* RESTRICT solid,
                     long long nb[7], bool blocked[7]) {
    const long long sx = 1, sy = (long long)(nx + 2), sz = (long long)(nx + 2) * (long long)(ny + 2);
    const long long c = X + sy * Y + sz * Z;
    nb[0] = c;
    nb[1] = (X == nx && px) ? c - sx * (nx - 1) : c + sx;
    nb[2] = (X == 1 && px) ? c + sx * (nx - 1) : c - sx;
    nb[3] = (Y == ny && py) ? c - sy * (ny - 1) : c + sy;
    nb[4] = (Y == 1 && py) ? c + sy * (ny - 1) : c - sy;
    nb[5] = (Z == nz && pz) ? c - sz * (nz - 1) : c + sz;
    nb[6] = (Z == 1 && pz) ? c + sz * (nz - 1) : c - sz;
    blocked[0] = false;
    blocked[1] = (X == nx && !px) || solid[nb[1]];
    blocked[2] = (X == 1 && !px) || solid[nb[2]];
    blocked[3] = (Y == ny && !py) || solid[nb[3]];
    blocked[4] = (Y == 1 && !py) || solid[nb[4]];
    blocked[5] = (Z == nz && !pz) || solid[nb[5]];
    blocked[6] = (Z == 1 && !pz) || solid[nb[6]];
}

// Pre-collision populations of cell nb[0] at step parity `odd` (esoteric-pull load with the blocked fix).
DEVICE void pf_load(const float* RESTRICT h, const long long ncell, const long long nb[7],
                    const bool blocked[7], const int odd, float f[7]) {
    const long long c = nb[0];
    f[0] = h[c];
    PF_UNROLL
    for (int j = 1; j < 7; j += 2) {
        const int a = odd ? j : j + 1, b = odd ? j + 1 : j;
        f[j] = h[(blocked[j + 1] ? b : a) * ncell + c];
        f[j + 1] = h[(blocked[j] ? a : b) * ncell + nb[j]];
    }
}

// Inverse of pf_load: write f so that pf_load at the same parity returns it (initialisation only).
DEVICE void pf_unload(float* RESTRICT h, const long long ncell, const long long nb[7], const bool blocked[7],
                      const int odd, const float f[7]) {
    const long long c = nb[0];
    h[c] = f[0];
    PF_UNROLL
    for (int j = 1; j < 7; j += 2) {
        const int a = odd ? j : j + 1, b = odd ? j + 1 : j;
        h[(blocked[j + 1] ? b : a) * ncell + c] = f[j];
        h[(blocked[j] ? a : b) * ncell + nb[j]] = f[j + 1];
    }
}

// Esoteric-pull store of post-collision populations of cell nb[0].
DEVICE void pf_store(float* RESTRICT h, const long long ncell, const long long nb[7], const int odd,
                     const float f[7]) {
    const long long c = nb[0];
    h[c] = f[0];
    PF_UNROLL
    for (int j = 1; j < 7; j += 2) {
        const int a = odd ? j : j + 1, b = odd ? j + 1 : j;
        h[b * ncell + nb[j]] = f[j];
        h[a * ncell + c] = f[j + 1];
    }
}

// D3Q7 equilibrium h_k^eq = w_k phi (1 + d_k.u / cs^2), cs^2 = 1/4 (first order in u, notes §1c).
DEVICE void pf_equilibrium(const float phi, const float ux, const float uy, const float uz, float feq[7]) {
    const float inv_cs2 = 1.f / CS2_7;
    feq[0] = W7[0] * phi;
    feq[1] = W7[1] * phi * (1.f + inv_cs2 * ux);
    feq[2] = W7[2] * phi * (1.f - inv_cs2 * ux);
    feq[3] = W7[3] * phi * (1.f + inv_cs2 * uy);
    feq[4] = W7[4] * phi * (1.f - inv_cs2 * uy);
    feq[5] = W7[5] * phi * (1.f + inv_cs2 * uz);
    feq[6] = W7[6] * phi * (1.f - inv_cs2 * uz);
}

// h := a state that loads (at parity t) as h^eq(phi, u) in every interior fluid cell.  n = nx*ny*nz.
KERNEL void phase_set_equilibrium(const long long n, float* RESTRICT h, const float* RESTRICT phi,
                                  const float* RESTRICT u, const unsigned char* RESTRICT solid, const int nx,
                                  const int ny, const int nz, const int px, const int py, const int pz,
                                  const int parity) {
    const long long ncell = (long long)(nx + 2) * (ny + 2) * (nz + 2);
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        long long nb[7];
        bool blocked[7];
        pf_links(x + 1, y + 1, z + 1, nx, ny, nz, px, py, pz, solid, nb, blocked);
        const long long c = nb[0];
        if (solid[c]) continue;
        float feq[7];
        pf_equilibrium(phi[c], u[c], u[ncell + c], u[2 * ncell + c], feq);
        pf_unload(h, ncell, nb, blocked, parity & 1, feq);
    }
}

// phi = sum_k h_k (Eq. 47) at parity t on every padded cell: a ghost cell takes the value of its image
// (wrap on periodic axes, nearest interior cell on wall axes: zero normal gradient, 90 degree contact
// angle); solid cells get 0.  n = (nx+2)*(ny+2)*(nz+2).
KERNEL void phase_macroscopic(const long long n, const float* RESTRICT h, float* RESTRICT phi,
                              const unsigned char* RESTRICT solid, const int nx, const int ny, const int nz,
                              const int px, const int py, const int pz, const int parity) {
    const long long ncell = (long long)(nx + 2) * (ny + 2) * (nz + 2);
    FOR_EACH_CELL(X, Y, Z, nx + 2, ny + 2, nz + 2) {
        const int xi = X == 0 ? (px ? nx : 1) : (X == nx + 1 ? (px ? 1 : nx) : X);
        const int yi = Y == 0 ? (py ? ny : 1) : (Y == ny + 1 ? (py ? 1 : ny) : Y);
        const int zi = Z == 0 ? (pz ? nz : 1) : (Z == nz + 1 ? (pz ? 1 : nz) : Z);
        const long long c = X + (long long)(nx + 2) * (Y + (long long)(ny + 2) * Z);
        long long nb[7];
        bool blocked[7];
        pf_links(xi, yi, zi, nx, ny, nz, px, py, pz, solid, nb, blocked);
        float s = 0.f;
        if (!solid[nb[0]]) {
            float f[7];
            pf_load(h, ncell, nb, blocked, parity & 1, f);
            s = f[0] + f[1] + f[2] + f[3] + f[4] + f[5] + f[6];
        }
        phi[c] = s;
    }
}

// grad phi by the isotropic D3Q27 stencil (Eq. 21) and, with CK_PF_SURFACE_TENSION, the chemical potential
// mu = 4 beta phi (phi - 1)(phi - 1/2) - kappa lap(phi) (Eq. 22) with the isotropic Laplacian (Eq. 23).
// A solid neighbour contributes the centre value (zero gradient along that link).  phi must have its
// ghost layer filled (phase_macroscopic does).  Interior cells only; solid cells get 0.  n = nx*ny*nz.
// Without CK_PF_SURFACE_TENSION, mu, beta and kappa are not used (pass a 1-element dummy for mu).
KERNEL void phase_gradients(const long long n, const float* RESTRICT phi, const unsigned char* RESTRICT solid,
                            float* RESTRICT grad, float* RESTRICT mu, const int nx, const int ny, const int nz,
                            const float beta, const float kappa) {
    const long long sy = (long long)(nx + 2), sz = (long long)(nx + 2) * (ny + 2);
    const long long ncell = sz * (nz + 2);
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        const long long c = (x + 1) + sy * (y + 1) + sz * (z + 1);
        if (solid[c]) {
            grad[c] = 0.f;
            grad[ncell + c] = 0.f;
            grad[2 * ncell + c] = 0.f;
#if CK_PF_SURFACE_TENSION
            mu[c] = 0.f;
#endif
            continue;
        }
        const float p0 = phi[c];
        float gx = 0.f, gy = 0.f, gz = 0.f;
#if CK_PF_SURFACE_TENSION
        float lap = 0.f;
#endif
        PF_UNROLL
        for (int k = 0; k < 27; ++k) {
            const int dx = k % 3 - 1, dy = (k / 3) % 3 - 1, dz = k / 9 - 1;
            const long long o = c + dx + sy * dy + sz * dz;
            const float v = solid[o] ? p0 : phi[o];
            const float w = PF_W27_CUBE[k];
            gx += (w * dx) * v;
            gy += (w * dy) * v;
            gz += (w * dz) * v;
#if CK_PF_SURFACE_TENSION
            lap += w * (v - p0);
#endif
        }
        // Eq. 21: 3 sum_j w_j c_j phi(x + c_j)  (3 = 1/cs^2 of D3Q27)
        grad[c] = 3.f * gx;
        grad[ncell + c] = 3.f * gy;
        grad[2 * ncell + c] = 3.f * gz;
#if CK_PF_SURFACE_TENSION
        // Eqs. 22-23
        mu[c] = 4.f * beta * p0 * (p0 - 1.f) * (p0 - 0.5f) - kappa * (6.f * lap);
#endif
    }
}

// One phase-field step: load h at parity t (esoteric pull), collide (Eq. 48), store (stream in place).
//   h*_k = h_k - omega (h_k - h_k^eq) + (1 - omega/2) H_k + S_k
//   H_k = w_k d_k . H,  H = (4/W) phi (1 - phi) grad(phi)/|grad(phi)|   (Eqs. 49-50; the (1 - omega/2)
//         factor makes the recovered counter-flux M H, notes §1c pitfall)
//   S_k = w_k gamma S_phi  (Eq. 51, source corrected by the volume controller factor gamma, Eq. 52)
//   omega = 1/tau, tau = M / cs^2 + 1/2 (mobility M, cs^2 = 1/4)
// grad: grad phi of the same step (phase_gradients); u: fluid velocity; source: S_phi.  n = nx*ny*nz.
KERNEL void phase_collide_stream(const long long n, float* RESTRICT h, const float* RESTRICT grad,
                                 const float* RESTRICT u, const float* RESTRICT source,
                                 const unsigned char* RESTRICT solid, const int nx, const int ny, const int nz,
                                 const int px, const int py, const int pz, const int parity,
                                 const float mobility, const float width, const float source_scale) {
    const long long ncell = (long long)(nx + 2) * (ny + 2) * (nz + 2);
    const float omega = 1.f / (mobility / CS2_7 + 0.5f);
    const float interface_factor = (1.f - 0.5f * omega) * 4.f / width;
    const int odd = parity & 1;
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        long long nb[7];
        bool blocked[7];
        pf_links(x + 1, y + 1, z + 1, nx, ny, nz, px, py, pz, solid, nb, blocked);
        const long long c = nb[0];
        if (solid[c]) continue;
        float f[7];
        pf_load(h, ncell, nb, blocked, odd, f);
        const float phi = f[0] + f[1] + f[2] + f[3] + f[4] + f[5] + f[6];  // Eq. 47

        const float gx = grad[c], gy = grad[ncell + c], gz = grad[2 * ncell + c];
        const float g2 = gx * gx + gy * gy + gz * gz;
        // (1 - omega/2) |H| / |grad phi|, Eq. 49
        const float hscale = g2 > PF_GRAD_EPS2 ? interface_factor * phi * (1.f - phi) / sqrtf(g2) : 0.f;
        const float hx = hscale * gx, hy = hscale * gy, hz = hscale * gz;
        const float s = source_scale * source[c];

        float feq[7];
        pf_equilibrium(phi, u[c], u[ncell + c], u[2 * ncell + c], feq);
        const float dH[7] = {0.f, hx, -hx, hy, -hy, hz, -hz};  // d_k . (1 - omega/2) H
        PF_UNROLL
        for (int k = 0; k < 7; ++k) f[k] = f[k] - omega * (f[k] - feq[k]) + W7[k] * (dH[k] + s);
        pf_store(h, ncell, nb, odd, f);
    }
}

// Global volume sums for the volume controller (Eq. 52), in float64 over interior fluid cells:
//   out[0] += sum phi,  out[1] += sum S_phi.  n = ny*nz (one work item per x row).
KERNEL void phase_volume_sums(const long long n, const float* RESTRICT phi, const float* RESTRICT source,
                              const unsigned char* RESTRICT solid, double* RESTRICT out, const int nx,
                              const int ny, const int nz) {
    const long long sy = (long long)(nx + 2), sz = (long long)(nx + 2) * (ny + 2);
    REDUCE_SUM_BEGIN(row, n, acc) {
        const long long c0 = 1 + sy * (row % ny + 1) + sz * (row / ny + 1);
        double s = 0.0;
        for (int x = 0; x < nx; ++x) s += solid[c0 + x] ? 0.0 : (double)phi[c0 + x];
        acc += s;
    }
    REDUCE_SUM_END(out, acc)
    REDUCE_SUM_BEGIN(row, n, acc_s) {
        const long long c0 = 1 + sy * (row % ny + 1) + sz * (row / ny + 1);
        double s = 0.0;
        for (int x = 0; x < nx; ++x) s += solid[c0 + x] ? 0.0 : (double)source[c0 + x];
        acc_s += s;
    }
    REDUCE_SUM_END(out + 1, acc_s)
}

// As phase_volume_sums with the fluid volume fraction eps of the mixture (Eq. 45's epsilon):
//   out[0] += sum eps phi (the heavy-fluid volume),  out[1] += sum S_phi.  n = ny*nz.
KERNEL void phase_volume_sums_eps(const long long n, const float* RESTRICT phi, const float* RESTRICT eps,
                                  const float* RESTRICT source, const unsigned char* RESTRICT solid,
                                  double* RESTRICT out, const int nx, const int ny, const int nz) {
    const long long sy = (long long)(nx + 2), sz = (long long)(nx + 2) * (ny + 2);
    REDUCE_SUM_BEGIN(row, n, acc) {
        const long long c0 = 1 + sy * (row % ny + 1) + sz * (row / ny + 1);
        double s = 0.0;
        for (int x = 0; x < nx; ++x) s += solid[c0 + x] ? 0.0 : (double)eps[c0 + x] * (double)phi[c0 + x];
        acc += s;
    }
    REDUCE_SUM_END(out, acc)
    REDUCE_SUM_BEGIN(row, n, acc_s) {
        const long long c0 = 1 + sy * (row % ny + 1) + sz * (row / ny + 1);
        double s = 0.0;
        for (int x = 0; x < nx; ++x) s += solid[c0 + x] ? 0.0 : (double)source[c0 + x];
        acc_s += s;
    }
    REDUCE_SUM_END(out + 1, acc_s)
}
