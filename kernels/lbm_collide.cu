// Fused collide + stream of the velocity-based D3Q27 NOCM-MRT flow (paper Eqs. 8-13, 15-20), AA pattern.
// Spec: couplekit/fluid/reference.py ReferenceOps.collide_stream.
// Defines: CK_TWO_PHASE (rho, mu from phi, Eq. 4; viscous correction F_mu), CK_SURFACE_TENSION (F_s = mu_phi
// grad phi from the chemical-potential field `mu`), CK_MIXTURE (fluid fraction eps), CK_EXT_FORCE (force
// density input, e.g. drag).  Switched-off inputs may be any float array (they are not read).
//
// Because every relaxation rate except the shear rate r_s is 1, the post-collision central moments depend on
// the pre-collision state only through m0, u and the second-order central moments (lbm-method note §1b):
// the forward transform reduces to 10 raw sums, and only the backward chimera transform is done.
// variants: CK_TWO_PHASE=0,1 CK_SURFACE_TENSION=0,1 CK_MIXTURE=0,1 CK_EXT_FORCE=1
// (CK_EXT_FORCE=0 compiles a strict subset of the =1 code, so the GPU build checks only =1)
#include "common.cuh"
#include "lattice.cuh"
#include "lbm_core.cuh"

#ifndef CK_TWO_PHASE
#define CK_TWO_PHASE 0
#endif
#ifndef CK_SURFACE_TENSION
#define CK_SURFACE_TENSION 0
#endif
#ifndef CK_MIXTURE
#define CK_MIXTURE 0
#endif
#ifndef CK_EXT_FORCE
#define CK_EXT_FORCE 0
#endif

// central moments (k0, k1, k2) along one axis -> populations (f-, f0, f+), in place
LBM_INLINE void chimera_backward(float& a0, float& a1, float& a2, const float u) {
    const float k0 = a0, k1 = a1, k2 = a2, uu = u * u;
    a1 = k0 * (1.f - uu) - 2.f * u * k1 - k2;
    a0 = 0.5f * (k0 * (uu - u) + k1 * (2.f * u - 1.f) + k2);
    a2 = 0.5f * (k0 * (uu + u) + k1 * (2.f * u + 1.f) + k2);
}

#define CUBE(q) ((CX27[q] + 1) * 9 + (CY27[q] + 1) * 3 + (CZ27[q] + 1))

// one fluid cell: load, forces, collision, store (ODD = parity & 1)
template <int ODD>
LBM_INLINE void lbm_collide_cell(const long long c, float* RESTRICT f, const unsigned char* RESTRICT flags,
                                 float* RESTRICT vel, const float* RESTRICT phi, const float* RESTRICT mu,
                                 const float* RESTRICT eps, const float* RESTRICT force,
                                 const float* RESTRICT pbar, const int px, const long long pxy, const long long N,
                                 const float rho_h, const float rho_l, const float nu_h, const float nu_l,
                                 const float gx, const float gy, const float gz) {
    float fj[27];
    lbm_load<ODD>(f, c, N, px, pxy, fj);

    // raw moments m0, m_a, m_ab
    float m0 = 0.f, mx = 0.f, my = 0.f, mz = 0.f;
    float mxx = 0.f, myy = 0.f, mzz = 0.f, mxy = 0.f, mxz = 0.f, myz = 0.f;
#define LBM_MOMENTS(q)                                       \
    {                                                       \
    const float v = fj[q];                              \
    m0 += v;                                            \
    if (CX27[q]) mx += CX27[q] * v, mxx += v;           \
    if (CY27[q]) my += CY27[q] * v, myy += v;           \
    if (CZ27[q]) mz += CZ27[q] * v, mzz += v;           \
    if (CX27[q] * CY27[q]) mxy += CX27[q] * CY27[q] * v; \
    if (CX27[q] * CZ27[q]) mxz += CX27[q] * CZ27[q] * v; \
    if (CY27[q] * CZ27[q]) myz += CY27[q] * CZ27[q] * v; \
    }
    LBM_FOR27(LBM_MOMENTS)
#undef LBM_MOMENTS

    // material properties, Eq. 4
#if CK_TWO_PHASE
    const float ph = lbm_clamp01(phi[c]);
    const float rho = rho_l + (rho_h - rho_l) * ph;
    const float nu = (rho_l * nu_l + (rho_h * nu_h - rho_l * nu_l) * ph) / rho;
#else
    const float rho = rho_h;
    const float nu = nu_h;
#endif
    const float rs = 1.f / (3.f * nu + 0.5f);
    const float inv_rho = 1.f / rho;
#if CK_MIXTURE
    const float e = eps[c];
#else
    const float e = 1.f;
#endif

    // acceleration, Eq. 15: -grad pbar / rho + g (+ F_s / rho) (+ F_ext / (eps rho))
    float gp[3];
    lbm_gradient<1>(pbar, flags, c, px, pxy, gp);
    float ax = gx - gp[0] * inv_rho, ay = gy - gp[1] * inv_rho, az = gz - gp[2] * inv_rho;
#if CK_TWO_PHASE
    float gphi[3];
    lbm_gradient<0>(phi, flags, c, px, pxy, gphi);
#if CK_SURFACE_TENSION
    const float chem = mu[c] * inv_rho;
    ax += chem * gphi[0];
    ay += chem * gphi[1];
    az += chem * gphi[2];
#endif
#endif
#if CK_EXT_FORCE
    const float inv_erho = 1.f / (e * rho);
    ax += force[c] * inv_erho;
    ay += force[N + c] * inv_erho;
    az += force[2 * N + c] * inv_erho;
#endif
#if CK_TWO_PHASE || CK_MIXTURE
    {
        // viscous correction F_mu = nu grad^sym u . [grad rho + (rho/eps) grad eps]   (Eq. 16), with
        // grad^sym u ~ -3 r_s dev(kappa_2) + (2/3)(1 - m0) I from the pre-collision central moments
        const float vx = mx + 0.5f * ax, vy = my + 0.5f * ay, vz = mz + 0.5f * az;
        const float kxx = mxx - 2.f * vx * mx + vx * vx * m0;
        const float kyy = myy - 2.f * vy * my + vy * vy * m0;
        const float kzz = mzz - 2.f * vz * mz + vz * vz * m0;
        const float kxy = mxy - vx * my - vy * mx + vx * vy * m0;
        const float kxz = mxz - vx * mz - vz * mx + vx * vz * m0;
        const float kyz = myz - vy * mz - vz * my + vy * vz * m0;
        const float tr3 = (kxx + kyy + kzz) * (1.f / 3.f);
        const float iso = (2.f / 3.f) * (1.f - m0);
        const float s = -3.f * rs;
        const float sxx = s * (kxx - tr3) + iso, syy = s * (kyy - tr3) + iso, szz = s * (kzz - tr3) + iso;
        const float sxy = s * kxy, sxz = s * kxz, syz = s * kyz;
        float g0 = 0.f, g1 = 0.f, g2 = 0.f;
#if CK_TWO_PHASE
        g0 += (rho_h - rho_l) * gphi[0];
        g1 += (rho_h - rho_l) * gphi[1];
        g2 += (rho_h - rho_l) * gphi[2];
#endif
#if CK_MIXTURE
        float ge[3];
        lbm_gradient<0>(eps, flags, c, px, pxy, ge);
        g0 += rho / e * ge[0];
        g1 += rho / e * ge[1];
        g2 += rho / e * ge[2];
#endif
        const float k = nu / (e * rho);
        ax += k * (sxx * g0 + sxy * g1 + sxz * g2);
        ay += k * (sxy * g0 + syy * g1 + syz * g2);
        az += k * (sxz * g0 + syz * g1 + szz * g2);
    }
#endif
    // velocity with the half-force shift, Eq. 13
    const float ux = mx + 0.5f * ax, uy = my + 0.5f * ay, uz = mz + 0.5f * az;

    // post-collision central moments (rates 1 except r_s on the deviatoric second order; Guo forcing)
    const float kxx = mxx - 2.f * ux * mx + ux * ux * m0;
    const float kyy = myy - 2.f * uy * my + uy * uy * m0;
    const float kzz = mzz - 2.f * uz * mz + uz * uz * m0;
    const float kxy = mxy - ux * my - uy * mx + ux * uy * m0;
    const float kxz = mxz - ux * mz - uz * mx + ux * uz * m0;
    const float kyz = myz - uy * mz - uz * my + uy * uz * m0;
    const float om = 1.f - rs;
    const float dxy = om * (kxx - kyy), dxz = om * (kxx - kzz);
    float K[27];
    K[0] = 1.f;                                  // 000
    K[1] = 0.5f * az;                            // 001
    K[2] = 1.f / 3.f + (dxy + dxz) * (1.f / 3.f) - dxz;  // 002
    K[3] = 0.5f * ay;                            // 010
    K[4] = om * kyz;                             // 011
    K[5] = ay * (1.f / 6.f);                     // 012
    K[6] = (1.f + dxy + dxz) * (1.f / 3.f) - dxy;  // 020
    K[7] = az * (1.f / 6.f);                     // 021
    K[8] = 1.f / 9.f;                            // 022
    K[9] = 0.5f * ax;                            // 100
    K[10] = om * kxz;                            // 101
    K[11] = ax * (1.f / 6.f);                    // 102
    K[12] = om * kxy;                            // 110
    K[13] = 0.f;                                 // 111
    K[14] = 0.f;                                 // 112
    K[15] = ax * (1.f / 6.f);                    // 120
    K[16] = 0.f;                                 // 121
    K[17] = ax * (1.f / 18.f);                   // 122
    K[18] = (1.f + dxy + dxz) * (1.f / 3.f);     // 200
    K[19] = az * (1.f / 6.f);                    // 201
    K[20] = 1.f / 9.f;                           // 202
    K[21] = ay * (1.f / 6.f);                    // 210
    K[22] = 0.f;                                 // 211
    K[23] = ay * (1.f / 18.f);                   // 212
    K[24] = 1.f / 9.f;                           // 220
    K[25] = az * (1.f / 18.f);                   // 221
    K[26] = 1.f / 27.f;                          // 222

    // backward chimera transform: x, then y, then z (cube index a*9 + b*3 + c -> ix*9 + iy*3 + iz)
#define LBM_BACK_X(bc) chimera_backward(K[bc], K[9 + (bc)], K[18 + (bc)], ux);
#define LBM_BACK_Y(i) chimera_backward(K[(i) / 3 * 9 + (i) % 3], K[(i) / 3 * 9 + 3 + (i) % 3], K[(i) / 3 * 9 + 6 + (i) % 3], uy);
#define LBM_BACK_Z(ij) chimera_backward(K[(ij) * 3], K[(ij) * 3 + 1], K[(ij) * 3 + 2], uz);
    LBM_REP9(LBM_BACK_X, 0)
    LBM_REP9(LBM_BACK_Y, 0)
    LBM_REP9(LBM_BACK_Z, 0)
#undef LBM_BACK_X
#undef LBM_BACK_Y
#undef LBM_BACK_Z

    float fs[27];
#define LBM_FROM_CUBE(q) fs[q] = K[CUBE(q)];
    LBM_FOR27(LBM_FROM_CUBE)
#undef LBM_FROM_CUBE
    lbm_store<ODD>(f, c, N, px, pxy, fs);
    vel[c] = ux;
    vel[N + c] = uy;
    vel[2 * N + c] = uz;
}

KERNEL void lbm_collide_stream(const long long n, float* RESTRICT f /* size: 27 * (nx + 2) * (ny + 2) * (nz + 2) */,
                               const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                               float* RESTRICT vel /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
                               const float* RESTRICT phi, const float* RESTRICT mu, const float* RESTRICT eps,
                               const float* RESTRICT force,
                               const float* RESTRICT pbar /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                               const int parity, const int nx, const int ny, const int nz, const float rho_h,
                               const float rho_l, const float nu_h, const float nu_l, const float gx,
                               const float gy, const float gz) {
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
    const long long N = pxy * (nz + 2);
    // one loop per parity, so the parity is a compile-time constant inside the (vectorised) x loop
#define LBM_COLLIDE_LOOP(ODD)                                                                                  \
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {                                                                       \
        const long long c = (x + 1) + px * (long long)(y + 1) + pxy * (z + 1);                                 \
        if (flags[c] != FLAG_FLUID) continue;                                                                  \
        lbm_collide_cell<ODD>(c, f, flags, vel, phi, mu, eps, force, pbar, px, pxy, N, rho_h, rho_l, nu_h, nu_l, \
                              gx, gy, gz);                                                                     \
    }
    if (parity & 1) {
        LBM_COLLIDE_LOOP(1)
    } else {
        LBM_COLLIDE_LOOP(0)
    }
#undef LBM_COLLIDE_LOOP
}
