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

DEVICE int mpm_bspline_g(const float X, float w[3], float& f) {
    const int base = (int)floorf(X - 0.5f);
    f = X - (float)base;
    w[0] = 0.5f * (1.5f - f) * (1.5f - f);
    w[1] = 0.75f - (f - 1.f) * (f - 1.f);
    w[2] = 0.5f * (f - 0.5f) * (f - 0.5f);
    return base;
}

DEVICE float mpm_clamp_axis(const float p, const int ncell, const float dx) {
    const float lo = dx;
    const float hi = ((float)ncell - 1.f) * dx * (1.f - 1e-6f);
    return fminf(fmaxf(p, lo), hi);
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
    MPM_FOR_EACH_PARTICLE(p, n) {
        const float xp = x[p], yp = x[np + p], zp = x[2 * np + p];
        float wx[3], wy[3], wz[3], fx, fy, fz;
        const int bx = mpm_bspline_g(xp * inv_dx - 0.5f, wx, fx);
        const int by = mpm_bspline_g(yp * inv_dx - 0.5f, wy, fy);
        const int bz = mpm_bspline_g(zp * inv_dx - 0.5f, wz, fz);
        float ux = 0.f, uy = 0.f, uz = 0.f;
        float B00 = 0.f, B01 = 0.f, B02 = 0.f, B10 = 0.f, B11 = 0.f, B12 = 0.f, B20 = 0.f, B21 = 0.f, B22 = 0.f;
        for (int c = 0; c < 3; ++c) {
            const float dz = (float)c - fz;  // (x_i - x_p) / dx
            for (int b = 0; b < 3; ++b) {
                const float dy = (float)b - fy;
                const float wyz = wy[b] * wz[c];
                const long long row = (long long)nx * ((long long)(by + b) + (long long)ny * (bz + c)) + bx;
                for (int a = 0; a < 3; ++a) {
                    const float ddx = (float)a - fx;
                    const float w = wx[a] * wyz;
                    const long long i = row + a;
                    const float gvx = w * grid_v[i], gvy = w * grid_v[ncell + i], gvz = w * grid_v[2 * ncell + i];
                    ux += gvx;
                    uy += gvy;
                    uz += gvz;
                    B00 += gvx * ddx;
                    B01 += gvx * dy;
                    B02 += gvx * dz;
                    B10 += gvy * ddx;
                    B11 += gvy * dy;
                    B12 += gvy * dz;
                    B20 += gvz * ddx;
                    B21 += gvz * dy;
                    B22 += gvz * dz;
                }
            }
        }
        // C = (4/dx^2) B_dx, with B_dx accumulated in units of dx: C = 4/dx * B
        const float k = 4.f * inv_dx;
        float Cm[9] = {k * B00, k * B01, k * B02, k * B10, k * B11, k * B12, k * B20, k * B21, k * B22};
        float Fo[9], Ft[9];
        for (int j = 0; j < 9; ++j) Fo[j] = F[j * np + p];
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c)
                Ft[3 * r + c] = Fo[3 * r + c] + dt * (Cm[3 * r] * Fo[c] + Cm[3 * r + 1] * Fo[3 + c] + Cm[3 * r + 2] * Fo[6 + c]);
        float U[9], e0, e1, e2;
        float qp = q[p], vcp = vc[p];
        mpm_constitutive(Ft, U, e0, e1, e2, qp, vcp, saturation[p], mu, lambda, h0, h1, h2, h3, c_max, S1, S2, S3);
        float t[6];
        mpm_kirchhoff(U, e0, e1, e2, mu, lambda, t);
        for (int j = 0; j < 9; ++j) {
            F[j * np + p] = Ft[j];
            C[j * np + p] = Cm[j];
        }
        for (int j = 0; j < 6; ++j) tau[j * np + p] = t[j];
        q[p] = qp;
        vc[p] = vcp;
        v[p] = ux;
        v[np + p] = uy;
        v[2 * np + p] = uz;
        x[p] = mpm_clamp_axis(xp + dt * ux, nx, dx);
        x[np + p] = mpm_clamp_axis(yp + dt * uy, ny, dx);
        x[2 * np + p] = mpm_clamp_axis(zp + dt * uz, nz, dx);
    }
}
