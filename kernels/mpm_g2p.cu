// MPM grid-to-particle transfer, constitutive update and advection (paper 000 Eq. 30; notes Secs. 1.5, 2):
//
//   v_p     = sum_i w_ip v_i                                   (Eq. 30)
//   C_p     = (4/dx^2) sum_i w_ip v_i (x_i - x_p)^T            (APIC affine velocity, B D^-1)
//   F_trial = (I + dt C_p) F_p                                 (MLS: grad v ~ C)
//   F_p, q_p, vc_p <- return mapping of F_trial (mpm_model.cuh; keep < 1: viscoplastic overstress)
//   tau_p   = Kirchhoff stress of the new F_p (for the next P2G)
//   x_p    += dt v_p
//
// Safety net: positions are clamped to [dx (1 + 1e-6), (n - 1) dx (1 - 1e-6)] per axis so the 3x3x3 stencil of
// the next P2G stays inside the grid (the domain walls keep sand inside this band; a bed on a wall with
// sand.wall_layers = 1 rests on its bound, otherwise the clamp only matters for a broken setup). A particle whose position is not finite, or whose stencil would leave the grid, gathers
// nothing (no memory outside the grid is read, whatever the values): its velocity and affine matrix become NaN
// and its position stays NaN (the clamp lets NaN through), so the simulation's finiteness check names it;
// clamping NaN into the domain once hid a diverged particle in a corner.  n = number of particles.  CUDA: one thread per particle.  Host: batches of
// MPM_G2P_BATCH particles through `omp simd` loops, one particle per SIMD lane (see the kernel body);
// the constitutive update after the SVD restates mpm_constitutive (mpm_model.cuh) in vectorisable form,
// pinned to it by tests/sand/test_g2p_batched.py.
// Without MPM_HARDENING there is no hardening state: q is neither read nor written (the caller passes a
// placeholder, the field is not allocated); without MPM_COHESION the saturation is not read (the same).
// variants: MPM_PLASTICITY=0,1 MPM_HARDENING=0,1 MPM_COHESION=0,1 MPM_VOLUME_CORRECTION=0,1
#include "common.cuh"
#include "mpm_model.cuh"
#include "mpm_loops.cuh"
#include "mpm_simd_math.cuh"

#if defined(__CUDACC__)
#define MPM_UNROLL _Pragma("unroll")
#define MPM_UNROLL_9 _Pragma("unroll")
#else
#define MPM_UNROLL _Pragma("GCC unroll 3")
#define MPM_UNROLL_9 _Pragma("GCC unroll 9")
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

// clamp with selects (fminf / fmaxf do not vectorise, and they turn NaN into the bound): NaN passes through
MPM_INLINE float mpm_clamp_axis(const float p, const int ncell, const float dx) {
    // lo a little above dx, as hi a little below (n - 1) dx: at x = dx itself the float32 product x / dx - 0.5
    // rounds to just under 0.5, the stencil test fails and the particle was poisoned as lost (a bed at a floor
    // with sand.wall_layers = 1: NaN at step 377)
    const float lo = dx * (1.f + 1e-6f);
    const float hi = ((float)ncell - 1.f) * dx * (1.f - 1e-6f);
    const float a = p < lo ? lo : p;
    return a > hi ? hi : a;
}

// A grid coordinate brought into the band where the 3x3x3 stencil stays inside the grid: the same value inside
// it, a bound outside it, and 0.5 for NaN (the comparisons fail), so the gather's indices are valid whatever
// the position (the caller poisons the result of a particle that was outside). Selects, as mpm_clamp_axis.
MPM_INLINE float mpm_stencil_coord(const float X, const int ncell) {
    const float hi = (float)ncell - 1.5f - 1e-3f;
    const float a = X > 0.5f ? X : 0.5f;
    return a < hi ? a : hi;
}

// Stage a: gather v_p, C_p of particle p from the grid (Eq. 30, APIC) and form the trial
// F = (I + dt C) F_p.  Reads x, F of particle p (SoA, stride np); writes the advected position, v, C at
// [k * ldo] of xo, vo, Co and the trial F (row-major) at [k * ld] of ft.  Node indices are int: grids
// below 2^31 nodes.
MPM_INLINE void mpm_g2p_transfer(const long long p, const long long np, const float* x, const float* F,
                                 const float* RESTRICT grid_v, const int nx, const int ny, const int nz,
                                 const long long ncell, const float dx, const float inv_dx, const float dt,
                                 float* xo, float* vo, float* Co, const long long ldo, float* ft,
                                 const long long ld) {
    const float* RESTRICT gvx = grid_v;
    const float* RESTRICT gvy = grid_v + ncell;
    const float* RESTRICT gvz = grid_v + 2 * ncell;
    const float xp = x[p], yp = x[np + p], zp = x[2 * np + p];
    const float Xg = xp * inv_dx - 0.5f, Yg = yp * inv_dx - 0.5f, Zg = zp * inv_dx - 0.5f;
    // the stencil inside the grid (false for NaN): else gather within the band and poison the result below
    // bitwise & (no short-circuit: no branch in the `omp simd` loop; a select on the stencil coordinate, or a
    // branch, stopped the host's vectoriser and made G2P 4x slower)
    const bool inside = (Xg >= 0.5f) & (Xg < (float)nx - 1.5f) & (Yg >= 0.5f) & (Yg < (float)ny - 1.5f) &
                        (Zg >= 0.5f) & (Zg < (float)nz - 1.5f);
    float wx[3], wy[3], wz[3], fx, fy, fz;
    const int bx = mpm_bspline_g(mpm_stencil_coord(Xg, nx), wx, fx);
    const int by = mpm_bspline_g(mpm_stencil_coord(Yg, ny), wy, fy);
    const int bz = mpm_bspline_g(mpm_stencil_coord(Zg, nz), wz, fz);
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
    // a select and products, not a branch: the host batches this loop with `omp simd` (a branch here made G2P
    // 4.9x slower); 1 * x is x bitwise, NaN * x is NaN
    const float keep = inside ? 1.f : CK_NANF;
    ux *= keep, uy *= keep, uz *= keep;
    B00 *= keep, B01 *= keep, B02 *= keep, B10 *= keep, B11 *= keep, B12 *= keep, B20 *= keep, B21 *= keep;
    B22 *= keep;
    // C = (4/dx^2) B_dx, with B_dx accumulated in units of dx: C = 4/dx * B
    const float k = 4.f * inv_dx;
    const float c00 = k * B00, c01 = k * B01, c02 = k * B02, c10 = k * B10, c11 = k * B11, c12 = k * B12;
    const float c20 = k * B20, c21 = k * B21, c22 = k * B22;
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
    Co[0] = c00, Co[ldo] = c01, Co[2 * ldo] = c02, Co[3 * ldo] = c10, Co[4 * ldo] = c11;
    Co[5 * ldo] = c12, Co[6 * ldo] = c20, Co[7 * ldo] = c21, Co[8 * ldo] = c22;
    vo[0] = ux;
    vo[ldo] = uy;
    vo[2 * ldo] = uz;
    xo[0] = mpm_clamp_axis(xp + dt * ux, nx, dx);
    xo[ldo] = mpm_clamp_axis(yp + dt * uy, ny, dx);
    xo[2 * ldo] = mpm_clamp_axis(zp + dt * uz, nz, dx);
}

// Stage b: the yield-surface parameters of particle p before this step's projection: the Drucker-Prager
// coefficient from the hardening state (libm sinf / expf, scalar on the host) and the cohesion.
MPM_INLINE void mpm_g2p_yield(const float qp, const float S, const float h0, const float h1, const float h2,
                              const float h3, const float c_max, const float S1, const float S2, const float S3,
                              float& alpha, float& cC) {
    alpha = mpm_dp_alpha(mpm_friction_angle(qp, h0, h1, h2, h3));
#if MPM_COHESION
    cC = mpm_cohesion(S, c_max, S1, S2, S3);
#else
    cC = 0.f;
    (void)S, (void)c_max, (void)S1, (void)S2, (void)S3;
#endif
}

// Stage c: mpm_constitutive (mpm_model.cuh) after its SVD, given the SVD of the trial F (ft, U, sig, V at
// [k * ld]) and the yield parameters: principal Hencky strains, return mapping, elastic F, Kirchhoff
// stress.  q, vc in/out at qo[0], vco[0]; F, tau out at [k * ldo] of Fo, to.  Branch-free apart from the
// return mapping's cases (which GCC if-converts), with mpm_logf / mpm_expf, so that on the host it
// vectorises over a batch.
MPM_INLINE void mpm_g2p_finish(const float* ft, const float* Us, const float* sig, const float* Vs,
                               const long long ld, const float alpha, const float cC, const float mu,
                               const float lambda, const float keep, float* Fo, float* to, float* qo, float* vco,
                               const long long ldo) {
    float U[9], Fn[9];
    MPM_UNROLL_9
    for (int j = 0; j < 9; ++j) U[j] = Us[j * ld];
    MPM_UNROLL_9
    for (int j = 0; j < 9; ++j) Fn[j] = ft[j * ld];
    float e0 = mpm_logf(mpm_max_nonneg(fabsf(sig[0]), MPM_SIGMA_MIN));
    float e1 = mpm_logf(mpm_max_nonneg(fabsf(sig[ld]), MPM_SIGMA_MIN));
    float e2 = mpm_logf(mpm_max_nonneg(fabsf(sig[2 * ld]), MPM_SIGMA_MIN));
    float vcp = vco[0];
#if MPM_HARDENING
    float qp = qo[0];
#else
    float qp = 0.f;  // the return map's increment is computed and dropped: no hardening state
    (void)qo;
#endif
#if MPM_PLASTICITY
    qp += mpm_return_map(e0, e1, e2, vcp, alpha, cC, mu, lambda, keep);
    const float s0 = mpm_expf(e0), s1 = mpm_expf(e1), s2 = mpm_expf(e2);
    MPM_UNROLL
    for (int r = 0; r < 3; ++r)
        MPM_UNROLL
        for (int c = 0; c < 3; ++c)
            Fn[3 * r + c] = U[3 * r] * s0 * Vs[(3 * c) * ld] + U[3 * r + 1] * s1 * Vs[(3 * c + 1) * ld] +
                            U[3 * r + 2] * s2 * Vs[(3 * c + 2) * ld];
#else
    (void)Vs, (void)alpha, (void)cC, (void)keep;
#endif
    float t[6];
    mpm_kirchhoff(U, e0, e1, e2, mu, lambda, t);
    MPM_UNROLL_9
    for (int j = 0; j < 9; ++j) Fo[j * ldo] = Fn[j];
    MPM_UNROLL_9
    for (int j = 0; j < 6; ++j) to[j * ldo] = t[j];
#if MPM_HARDENING
    qo[0] = qp;
#else
    (void)qp;
#endif
    vco[0] = vcp;
}

// the hardening state and saturation of particle p as the yield parameters read them (0 where compiled out)
#if MPM_HARDENING
#define MPM_Q_OF(qarr, p) (qarr)[p]
#else
#define MPM_Q_OF(qarr, p) 0.f
#endif
#if MPM_COHESION
#define MPM_S_OF(p) saturation[p]
#else
#define MPM_S_OF(p) 0.f
#endif

KERNEL void mpm_g2p(const long long n, float* RESTRICT x, float* RESTRICT v, float* RESTRICT C,
                    float* RESTRICT F, float* RESTRICT tau, float* RESTRICT q, float* RESTRICT vc,
                    const float* RESTRICT saturation, const float* RESTRICT grid_v, const int nx, const int ny,
                    const int nz, const float dx, const float dt, const float mu, const float lambda,
                    const float h0, const float h1, const float h2, const float h3, const float c_max,
                    const float S1, const float S2, const float S3, const float keep) {
    const long long np = n;
    const long long ncell = (long long)nx * ny * nz;
    const float inv_dx = 1.f / dx;
#if CK_ON_GPU
    FOR_EACH(p, n) {
        float ft[9], U[9], sig[3], V[9], alpha = 0.f, cC = 0.f;
        mpm_g2p_transfer(p, np, x, F, grid_v, nx, ny, nz, ncell, dx, inv_dx, dt, x + p, v + p, C + p, np, ft, 1);
        mpm_svd3(ft, U, sig, V);
#if MPM_PLASTICITY
        mpm_g2p_yield(MPM_Q_OF(q, p), MPM_S_OF(p), h0, h1, h2, h3, c_max, S1, S2, S3, alpha, cC);
#endif
        mpm_g2p_finish(ft, U, sig, V, 1, alpha, cC, mu, lambda, keep, F + p, tau + p, q + p, vc + p, np);
    }
#else
    // Batches of B particles, one particle per SIMD lane in the `omp simd` loops: (a) transfer (the grid
    // reads become gathers) and SVD (its serial rotation chain spread over the lanes), (b) the yield
    // parameters (libm sinf / expf: scalar), (c) return mapping and stress.  Full batches read and write
    // the particle arrays in place; a short last batch is padded to B lanes (its last particle repeated in
    // local copies) and only its real lanes are stored.  So the compute loops always run all B lanes and no
    // particle goes through a vectoriser epilogue, whose FMA contractions may differ from the vector
    // body's: every particle's result is bitwise independent of its position in a batch (of the particle
    // order and of the thread count).
    CK_PRAGMA(omp parallel for schedule(static) if (n > MPM_SERIAL_PARTICLES))
    for (long long p0 = 0; p0 < n; p0 += MPM_G2P_BATCH) {
        constexpr int B = MPM_G2P_BATCH;
        const int cnt = (int)(n - p0 < B ? n - p0 : B);
        const bool full = cnt == B;
        alignas(64) float ft[9 * B], U[9 * B], sig[3 * B], V[9 * B], alpha[B], cC[B];
        // the short batch's particle data (in: x, F, q, vc; out: all)
        alignas(64) float xb[3 * B], vb[3 * B], Cb[9 * B], Fb[9 * B], tb[6 * B], qb[B], vcb[B];
        if (!full) {
            for (int j = 0; j < B; ++j) {
                const long long p = p0 + (j < cnt ? j : cnt - 1);
                for (int k = 0; k < 3; ++k) xb[k * B + j] = x[k * np + p];
                for (int k = 0; k < 9; ++k) Fb[k * B + j] = F[k * np + p];
#if MPM_HARDENING
                qb[j] = q[p];
#endif
                vcb[j] = vc[p];
            }
        }
        float* xs = full ? x + p0 : xb;
        float* vs = full ? v + p0 : vb;
        float* Cs = full ? C + p0 : Cb;
        float* Fs = full ? F + p0 : Fb;
        float* ts = full ? tau + p0 : tb;
#if MPM_HARDENING
        float* qs = full ? q + p0 : qb;
#else
        float* qs = qb;  // never read or written (mpm_g2p_finish); q is a placeholder
#endif
        float* vcs = full ? vc + p0 : vcb;
        const long long ld = full ? np : B;
        CK_PRAGMA(omp simd)
        for (int j = 0; j < B; ++j) {
            mpm_g2p_transfer(j, ld, xs, Fs, grid_v, nx, ny, nz, ncell, dx, inv_dx, dt, xs + j, vs + j, Cs + j, ld,
                             ft + j, B);
            mpm_svd3_strided(ft + j, B, U + j, sig + j, V + j, B);
        }
#if MPM_PLASTICITY
        for (int j = 0; j < B; ++j) {
            const long long p = p0 + (j < cnt ? j : cnt - 1);
            mpm_g2p_yield(MPM_Q_OF(qs, j), MPM_S_OF(p), h0, h1, h2, h3, c_max, S1, S2, S3, alpha[j], cC[j]);
            (void)p;
        }
#else
        for (int j = 0; j < B; ++j) alpha[j] = cC[j] = 0.f;
#endif
        CK_PRAGMA(omp simd)
        for (int j = 0; j < B; ++j)
            mpm_g2p_finish(ft + j, U + j, sig + j, V + j, B, alpha[j], cC[j], mu, lambda, keep, Fs + j, ts + j,
                           qs + j, vcs + j, ld);
        if (!full) {
            for (int j = 0; j < cnt; ++j) {
                const long long p = p0 + j;
                for (int k = 0; k < 3; ++k) x[k * np + p] = xb[k * B + j], v[k * np + p] = vb[k * B + j];
                for (int k = 0; k < 9; ++k) C[k * np + p] = Cb[k * B + j], F[k * np + p] = Fb[k * B + j];
                for (int k = 0; k < 6; ++k) tau[k * np + p] = tb[k * B + j];
#if MPM_HARDENING
                q[p] = qb[j];
#endif
                vc[p] = vcb[j];
            }
        }
    }
#endif
}
