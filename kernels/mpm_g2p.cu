// MPM grid-to-particle transfer, constitutive update and advection (paper 000 Eq. 30; notes Secs. 1.5, 2):
//
//   v_p     = sum_i w_ip v_i                                   (Eq. 30)
//   C_p     = (4/dx^2) sum_i w_ip v_i (x_i - x_p)^T            (APIC affine velocity, B D^-1)
//   F_trial = (I + dt C_p) F_p                                 (MLS: grad v ~ C)
//   F_p, q_p, vc_p <- return mapping of F_trial (mpm_model.cuh)
//   tau_p   = Kirchhoff stress of the new F_p (for the next P2G)
//   x_p    += dt v_p
//
// Safety net: positions are clamped to [dx, (n - 1) dx) per axis so the 3x3x3 stencil of the next P2G
// stays inside the grid (the domain walls keep sand well inside this band; the clamp only matters for a
// broken setup).  One thread per particle; n = number of particles.
// variants: MPM_PLASTICITY=0,1 MPM_HARDENING=0,1 MPM_COHESION=0,1 MPM_VOLUME_CORRECTION=0,1
#include "common.cuh"
#include "mpm_model.cuh"
#include "mpm_loops.cuh"

#if defined(__CUDACC__)
#define MPM_UNROLL _Pragma("unroll")
#else
#define MPM_UNROLL _Pragma("GCC unroll 3")
#endif

#ifndef MPM_G2P_BATCH
#define MPM_G2P_BATCH 64  // host: particles per batch (a multiple of every SIMD width)
#endif

// floor as truncation and a correction (floorf does not vectorise); equal to floorf within the int range
MPM_INLINE int mpm_floor_int(const float X) {
    const int t = (int)X;
    return t - (X < (float)t ? 1 : 0);
}

// Quadratic B-spline weights along one axis for grid coordinate X (node i at X = i); base node index.
MPM_INLINE int mpm_bspline_g(const float X, float w[3], float& f) {
    const int base = mpm_floor_int(X - 0.5f);
    f = X - (float)base;
    w[0] = 0.5f * (1.5f - f) * (1.5f - f);
    w[1] = 0.75f - (f - 1.f) * (f - 1.f);
    w[2] = 0.5f * (f - 0.5f) * (f - 0.5f);
    return base;
}

// clamp with selects (fminf / fmaxf do not vectorise: NaN rules)
MPM_INLINE float mpm_clamp_axis(const float p, const int ncell, const float dx) {
    const float lo = dx;
    const float hi = ((float)ncell - 1.f) * dx * (1.f - 1e-6f);
    const float a = p > lo ? p : lo;
    return a < hi ? a : hi;
}

// Stage a: gather v_p, C_p from the grid (Eq. 30, APIC), write them and the advected position, and the
// trial F = (I + dt C) F_p into ft[k * ld] (row-major).  Node indices are int: grids below 2^31 nodes.
MPM_INLINE void mpm_g2p_transfer(const long long p, const long long np, float* RESTRICT x, float* RESTRICT v,
                                 float* RESTRICT C, const float* RESTRICT F, const float* RESTRICT grid_v,
                                 const int nx, const int ny, const int nz, const long long ncell,
                                 const float dx, const float inv_dx, const float dt, float* ft,
                                 const long long ld) {
    const float* RESTRICT gvx = grid_v;
    const float* RESTRICT gvy = grid_v + ncell;
    const float* RESTRICT gvz = grid_v + 2 * ncell;
    const float xp = x[p], yp = x[np + p], zp = x[2 * np + p];
    float wx[3], wy[3], wz[3], fx, fy, fz;
    const int bx = mpm_bspline_g(xp * inv_dx - 0.5f, wx, fx);
    const int by = mpm_bspline_g(yp * inv_dx - 0.5f, wy, fy);
    const int bz = mpm_bspline_g(zp * inv_dx - 0.5f, wz, fz);
    float ux = 0.f, uy = 0.f, uz = 0.f;
    float B00 = 0.f, B01 = 0.f, B02 = 0.f, B10 = 0.f, B11 = 0.f, B12 = 0.f, B20 = 0.f, B21 = 0.f, B22 = 0.f;
    MPM_UNROLL
    for (int c = 0; c < 3; ++c) {
        const float dz = (float)c - fz;  // (x_i - x_p) / dx
        MPM_UNROLL
        for (int b = 0; b < 3; ++b) {
            const float dy = (float)b - fy;
            const float wyz = wy[b] * wz[c];
            const int row = nx * ((by + b) + ny * (bz + c)) + bx;
            MPM_UNROLL
            for (int a = 0; a < 3; ++a) {
                const float ddx = (float)a - fx;
                const float w = wx[a] * wyz;
                const int i = row + a;
                const float gx = w * gvx[i], gy = w * gvy[i], gz = w * gvz[i];
                ux += gx;
                uy += gy;
                uz += gz;
                B00 += gx * ddx;
                B01 += gx * dy;
                B02 += gx * dz;
                B10 += gy * ddx;
                B11 += gy * dy;
                B12 += gy * dz;
                B20 += gz * ddx;
                B21 += gz * dy;
                B22 += gz * dz;
            }
        }
    }
    // C = (4/dx^2) B_dx, with B_dx accumulated in units of dx: C = 4/dx * B
    const float k = 4.f * inv_dx;
    const float c00 = k * B00, c01 = k * B01, c02 = k * B02, c10 = k * B10, c11 = k * B11, c12 = k * B12;
    const float c20 = k * B20, c21 = k * B21, c22 = k * B22;
    C[p] = c00, C[np + p] = c01, C[2 * np + p] = c02, C[3 * np + p] = c10, C[4 * np + p] = c11;
    C[5 * np + p] = c12, C[6 * np + p] = c20, C[7 * np + p] = c21, C[8 * np + p] = c22;
    const float f00 = F[p], f01 = F[np + p], f02 = F[2 * np + p], f10 = F[3 * np + p], f11 = F[4 * np + p];
    const float f12 = F[5 * np + p], f20 = F[6 * np + p], f21 = F[7 * np + p], f22 = F[8 * np + p];
    ft[0] = f00 + dt * (c00 * f00 + c01 * f10 + c02 * f20);
    ft[ld] = f01 + dt * (c00 * f01 + c01 * f11 + c02 * f21);
    ft[2 * ld] = f02 + dt * (c00 * f02 + c01 * f12 + c02 * f22);
    ft[3 * ld] = f10 + dt * (c10 * f00 + c11 * f10 + c12 * f20);
    ft[4 * ld] = f11 + dt * (c10 * f01 + c11 * f11 + c12 * f21);
    ft[5 * ld] = f12 + dt * (c10 * f02 + c11 * f12 + c12 * f22);
    ft[6 * ld] = f20 + dt * (c20 * f00 + c21 * f10 + c22 * f20);
    ft[7 * ld] = f21 + dt * (c20 * f01 + c21 * f11 + c22 * f21);
    ft[8 * ld] = f22 + dt * (c20 * f02 + c21 * f12 + c22 * f22);
    v[p] = ux;
    v[np + p] = uy;
    v[2 * np + p] = uz;
    x[p] = mpm_clamp_axis(xp + dt * ux, nx, dx);
    x[np + p] = mpm_clamp_axis(yp + dt * uy, ny, dx);
    x[2 * np + p] = mpm_clamp_axis(zp + dt * uz, nz, dx);
}

// Stage c: the constitutive update of mpm_constitutive (mpm_model.cuh) given the SVD of the trial F
// (ft, U, sig, V at [k * ld]): principal Hencky strains, return mapping, elastic F, Kirchhoff stress;
// writes F, tau, q, vc of particle p.
MPM_INLINE void mpm_g2p_finish(const long long p, const long long np, float* RESTRICT F, float* RESTRICT tau,
                               float* RESTRICT q, float* RESTRICT vc, const float* RESTRICT saturation,
                               const float* ft, const float* Us, const float* sig, const float* Vs,
                               const long long ld, const float mu, const float lambda, const float h0,
                               const float h1, const float h2, const float h3, const float c_max, const float S1,
                               const float S2, const float S3) {
    float U[9], Fn[9];
    for (int j = 0; j < 9; ++j) U[j] = Us[j * ld];
    for (int j = 0; j < 9; ++j) Fn[j] = ft[j * ld];
    float e0 = logf(fmaxf(fabsf(sig[0]), MPM_SIGMA_MIN));
    float e1 = logf(fmaxf(fabsf(sig[ld]), MPM_SIGMA_MIN));
    float e2 = logf(fmaxf(fabsf(sig[2 * ld]), MPM_SIGMA_MIN));
    float qp = q[p], vcp = vc[p];
#if MPM_PLASTICITY
    const float alpha = mpm_dp_alpha(mpm_friction_angle(qp, h0, h1, h2, h3));
#if MPM_COHESION
    const float cC = mpm_cohesion(saturation[p], c_max, S1, S2, S3);
#else
    const float cC = 0.f;
#endif
    qp += mpm_return_map(e0, e1, e2, vcp, alpha, cC, mu, lambda);
    const float s0 = expf(e0), s1 = expf(e1), s2 = expf(e2);
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
            Fn[3 * r + c] = U[3 * r] * s0 * Vs[(3 * c) * ld] + U[3 * r + 1] * s1 * Vs[(3 * c + 1) * ld] +
                            U[3 * r + 2] * s2 * Vs[(3 * c + 2) * ld];
#else
    (void)saturation, (void)Vs, (void)h0, (void)h1, (void)h2, (void)h3, (void)c_max, (void)S1, (void)S2, (void)S3;
#endif
    float t[6];
    mpm_kirchhoff(U, e0, e1, e2, mu, lambda, t);
    for (int j = 0; j < 9; ++j) F[j * np + p] = Fn[j];
    for (int j = 0; j < 6; ++j) tau[j * np + p] = t[j];
    q[p] = qp;
    vc[p] = vcp;
}

KERNEL void mpm_g2p(const long long n, float* RESTRICT x, float* RESTRICT v, float* RESTRICT C,
                    float* RESTRICT F, float* RESTRICT tau, float* RESTRICT q, float* RESTRICT vc,
                    const float* RESTRICT saturation, const float* RESTRICT grid_v, const int nx, const int ny,
                    const int nz, const float dx, const float dt, const float mu, const float lambda,
                    const float h0, const float h1, const float h2, const float h3, const float c_max,
                    const float S1, const float S2, const float S3) {
    const long long np = n;
    const long long ncell = (long long)nx * ny * nz;
    const float inv_dx = 1.f / dx;
#if CK_ON_GPU
    FOR_EACH(p, n) {
        float ft[9], U[9], sig[3], V[9];
        mpm_g2p_transfer(p, np, x, v, C, F, grid_v, nx, ny, nz, ncell, dx, inv_dx, dt, ft, 1);
        mpm_svd3(ft, U, sig, V);
        mpm_g2p_finish(p, np, F, tau, q, vc, saturation, ft, U, sig, V, 1, mu, lambda, h0, h1, h2, h3, c_max, S1,
                       S2, S3);
    }
#else
    // Batches of particles: the transfer and the SVD run one particle per SIMD lane (`omp simd`: the grid
    // reads become gathers, the SVD's serial rotation chain is spread over the lanes), the constitutive
    // finish (libm logs / exps, branches of the return mapping) is a scalar loop over the batch.
    CK_PRAGMA(omp parallel for schedule(static) if (n > MPM_SERIAL_PARTICLES))
    for (long long p0 = 0; p0 < n; p0 += MPM_G2P_BATCH) {
        const int cnt = (int)(n - p0 < MPM_G2P_BATCH ? n - p0 : MPM_G2P_BATCH);
        alignas(64) float ft[9 * MPM_G2P_BATCH], U[9 * MPM_G2P_BATCH], sig[3 * MPM_G2P_BATCH],
            V[9 * MPM_G2P_BATCH];
        CK_PRAGMA(omp simd)
        for (int j = 0; j < cnt; ++j) {
            mpm_g2p_transfer(p0 + j, np, x, v, C, F, grid_v, nx, ny, nz, ncell, dx, inv_dx, dt, ft + j,
                             MPM_G2P_BATCH);
            mpm_svd3_strided(ft + j, MPM_G2P_BATCH, U + j, sig + j, V + j, MPM_G2P_BATCH);
        }
        for (int j = 0; j < cnt; ++j)
            mpm_g2p_finish(p0 + j, np, F, tau, q, vc, saturation, ft + j, U + j, sig + j, V + j, MPM_G2P_BATCH,
                           mu, lambda, h0, h1, h2, h3, c_max, S1, S2, S3);
    }
#endif
}
