// Sand constitutive model (paper 000 Sec. 4.2; ../shared/notes/mpm-method.md Sec. 2):
//   Hencky (log-strain St. Venant-Kirchhoff) elasticity, Drucker-Prager return mapping in log-strain
//   space (Klar et al. 2016), hardening phi_F(q) = h0 + (h1 q - h3) exp(-h2 q), volume correction
//   (Tampubolon et al. 2017) and the cohesive yield of Eq. 28 as an isotropic shift of the cone apex.
//
// Compile-time switches (DESIGN "Effects"):
//   MPM_PLASTICITY   1: Drucker-Prager return mapping (sand); 0: purely elastic Hencky solid.
//   MPM_HARDENING    1: friction angle from the hardening state q; 0: constant angle h0.
//   MPM_COHESION     1: cohesion c_C(S) from the per-particle saturation; 0: cohesionless.
//   MPM_VOLUME_CORRECTION  1: Tampubolon volume correction (default); 0: off.
//
// Sign convention: tension positive; e = ln(sigma) are principal Hencky strains,
// tau_k = 2 mu e_k + lambda tr(e) are the principal Kirchhoff stresses.
#pragma once
#include "common.cuh"
#include "mpm_svd.cuh"

#ifndef MPM_PLASTICITY
#define MPM_PLASTICITY 1
#endif
#ifndef MPM_HARDENING
#define MPM_HARDENING 1
#endif
#ifndef MPM_COHESION
#define MPM_COHESION 0
#endif
#ifndef MPM_VOLUME_CORRECTION
#define MPM_VOLUME_CORRECTION 1
#endif

#define MPM_SIGMA_MIN 1.0e-4f  // |sigma_k| clamp before ln (taichi_elements, Genesis, Claymore)
#define MPM_DEG2RAD 0.017453292519943295f
#define MPM_SQRT_2_3 0.816496580927726f

// Drucker-Prager coefficient matching Mohr-Coulomb in triaxial compression (notes Sec. 2.2):
// alpha = sqrt(2/3) * 2 sin(phi) / (3 - sin(phi)).
DEVICE float mpm_dp_alpha(const float phi_rad) {
    const float s = sinf(phi_rad);
    return MPM_SQRT_2_3 * 2.f * s / (3.f - s);
}

// Klar et al. 2016 hardening: friction angle (radians) after accumulated plastic strain q;
// h0, h1, h3 in radians, h2 dimensionless.
DEVICE float mpm_friction_angle(const float q, const float h0, const float h1, const float h2, const float h3) {
#if MPM_HARDENING
    return h0 + (h1 * q - h3) * expf(-h2 * q);
#else
    return h0;
#endif
}

// Cohesion c_C(S) (stress units) as a trapezoid in the saturation S: 0 at S <= 0, rising linearly to
// c_max at S1, flat to S2, back to 0 at S3 (a triangle when S1 = S2).  See couplekit/sand/params.py for
// the sources of the breakpoints.
DEVICE float mpm_cohesion(const float S, const float c_max, const float S1, const float S2, const float S3) {
    const float up = S / fmaxf(S1, 1e-12f);
    const float down = (S3 - S) / fmaxf(S3 - S2, 1e-12f);
    return c_max * fminf(fmaxf(fminf(fminf(up, 1.f), down), 0.f), 1.f);
}

// Drucker-Prager return mapping of the principal Hencky strains e (in/out), Klar et al. 2016 Sec. 7.3.
//   alpha: DP coefficient (before this step's projection), cC: cohesion (stress units, Eq. 28),
//   vc: volume-correction log-volume (in/out), returns the plastic increment dq for the hardening.
//   keep: the fraction of the Case III return applied this step, 1 / (1 + t_r / dt) with the relaxation
//   time t_r = eta / mu of a viscosity eta (Duvaut-Lions viscoplasticity; 1 = rate-independent Klar).
//   In steady flow the deviator left outside the cone is the overstress 2 eta D (eta * shear rate in
//   simple shear), for any dt: a rate dependence that makes the flowing sand's problem well-posed, so
//   that a collapse converges with the grid (docs/sand-validation.md).  The apex (Case II) is still
//   projected at once.
// Cohesion shifts the apex of the cone into tension by delta_c = cC / (3 alpha (3 lambda + 2 mu)) in each
// principal strain (exact for Hencky: a hydrostatic shift of the stress by cC / (3 alpha)).
DEVICE float mpm_return_map(float& e0, float& e1, float& e2, float& vc, const float alpha, const float cC,
                            const float mu, const float lambda, const float keep) {
    const float tr_trial = e0 + e1 + e2;
    const float kappa3 = 3.f * lambda + 2.f * mu;
#if MPM_VOLUME_CORRECTION
    const float shift_vc = vc * (1.f / 3.f);
#else
    const float shift_vc = 0.f;
#endif
    const float dc = (cC > 0.f && alpha > 0.f) ? cC / (3.f * alpha * kappa3) : 0.f;
    const float a0 = e0 + shift_vc - dc, a1 = e1 + shift_vc - dc, a2 = e2 + shift_vc - dc;
    const float tr = a0 + a1 + a2;
    const float m = tr * (1.f / 3.f);
    const float d0 = a0 - m, d1 = a1 - m, d2 = a2 - m;
    const float dnorm = sqrtf(d0 * d0 + d1 * d1 + d2 * d2);
    float dq;
    float n0, n1, n2;
    if (tr >= 0.f) {
        // Case II: expansion beyond the apex -> stress-free (apex) state.  The plastic increment is the
        // trial elastic strain about the apex, e - delta_c (Klar: ||eps||_F), NOT ||a||: a also holds the
        // stored volume-correction gain vc/3, which is no plastic flow of this step; with it a loose
        // particle at rest (vc > 0, e = delta_c) gained |vc|/sqrt(3) of hardening every step.
        const float b0 = e0 - dc, b1 = e1 - dc, b2 = e2 - dc;
        dq = sqrtf(b0 * b0 + b1 * b1 + b2 * b2);
        n0 = n1 = n2 = 0.f;
    } else {
        const float dgamma = dnorm + (kappa3 / (2.f * mu)) * alpha * tr;
        if (dgamma <= 0.f) {
            // Case I: inside the cone
            dq = 0.f;
            n0 = a0;
            n1 = a1;
            n2 = a2;
        } else {
            // Case III: shrink the deviatoric part onto the cone (trace kept), by the fraction keep of the
            // way (viscoplastic overstress); dnorm > 0 here
            dq = keep * dgamma;
            const float k = dq / dnorm;
            n0 = a0 - k * d0;
            n1 = a1 - k * d1;
            n2 = a2 - k * d2;
        }
    }
    e0 = n0 + dc;
    e1 = n1 + dc;
    e2 = n2 + dc;
#if MPM_VOLUME_CORRECTION
    // v_c += ln det F_trial - ln det F_new
    vc = vc + tr_trial - (e0 + e1 + e2);
#endif
    return dq;
}

// F (in, row-major) -> the elastic F after plasticity (out), its principal strains and rotation U
// (for the Kirchhoff stress).  q, vc are the hardening / volume-correction states, S the saturation.
DEVICE void mpm_constitutive(float F[9], float U[9], float& e0, float& e1, float& e2, float& q, float& vc,
                             const float S, const float mu, const float lambda, const float h0, const float h1,
                             const float h2, const float h3, const float c_max, const float S1, const float S2,
                             const float S3, const float keep) {
    float sig[3], V[9];
    mpm_svd3(F, U, sig, V);
    e0 = logf(fmaxf(fabsf(sig[0]), MPM_SIGMA_MIN));
    e1 = logf(fmaxf(fabsf(sig[1]), MPM_SIGMA_MIN));
    e2 = logf(fmaxf(fabsf(sig[2]), MPM_SIGMA_MIN));
#if !MPM_PLASTICITY
    (void)keep;
#endif
#if MPM_PLASTICITY
    const float alpha = mpm_dp_alpha(mpm_friction_angle(q, h0, h1, h2, h3));
#if MPM_COHESION
    const float cC = mpm_cohesion(S, c_max, S1, S2, S3);
#else
    const float cC = 0.f;
#endif
    q += mpm_return_map(e0, e1, e2, vc, alpha, cC, mu, lambda, keep);
    const float s0 = expf(e0), s1 = expf(e1), s2 = expf(e2);
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
            F[3 * r + c] = U[3 * r] * s0 * V[3 * c] + U[3 * r + 1] * s1 * V[3 * c + 1] + U[3 * r + 2] * s2 * V[3 * c + 2];
#endif
}

// Kirchhoff stress tau = U diag(2 mu e_k + lambda tr e) U^T as (xx, yy, zz, yz, xz, xy).
DEVICE void mpm_kirchhoff(const float U[9], const float e0, const float e1, const float e2, const float mu,
                          const float lambda, float tau[6]) {
    const float lt = lambda * (e0 + e1 + e2);
    const float t0 = 2.f * mu * e0 + lt, t1 = 2.f * mu * e1 + lt, t2 = 2.f * mu * e2 + lt;
    tau[0] = U[0] * U[0] * t0 + U[1] * U[1] * t1 + U[2] * U[2] * t2;
    tau[1] = U[3] * U[3] * t0 + U[4] * U[4] * t1 + U[5] * U[5] * t2;
    tau[2] = U[6] * U[6] * t0 + U[7] * U[7] * t1 + U[8] * U[8] * t2;
    tau[3] = U[3] * U[6] * t0 + U[4] * U[7] * t1 + U[5] * U[8] * t2;
    tau[4] = U[0] * U[6] * t0 + U[1] * U[7] * t1 + U[2] * U[8] * t2;
    tau[5] = U[0] * U[3] * t0 + U[1] * U[4] * t1 + U[2] * U[5] * t2;
}
