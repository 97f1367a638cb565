// The constitutive pieces of mpm_g2p.cu as stand-alone kernels, so each can be checked against its NumPy
// reference on its own (and used by tools that need a stress from an F): the float32 SVD, and the
// constitutive update F_trial -> (F_new, tau, q, vc), and the vectorisable log / exp of the host G2P.
// Same defines as mpm_g2p.cu (see mpm_model.cuh); as there, q is not touched without MPM_HARDENING and the
// saturation not read without MPM_COHESION (placeholders).
// variants: MPM_PLASTICITY=0,1 MPM_HARDENING=0,1 MPM_COHESION=0,1
#include "common.cuh"
#include "mpm_model.cuh"
#include "mpm_loops.cuh"
#include "mpm_simd_math.cuh"

// A (9, n) row-major matrices -> U (9, n), sigma (3, n), V (9, n) with A = U diag(sigma) V^T.
KERNEL void mpm_svd3_batch(const long long n, const float* RESTRICT A, float* RESTRICT U, float* RESTRICT sigma,
                           float* RESTRICT V) {
#if CK_ON_GPU
    FOR_EACH(p, n) { mpm_svd3_strided(A + p, n, U + p, sigma + p, V + p, n); }
#else
    // one particle per SIMD lane: the SoA arrays give contiguous vector loads and stores
    CK_PRAGMA(omp parallel for simd schedule(simd : static) if (n > MPM_SERIAL_PARTICLES))
    for (long long p = 0; p < n; ++p) mpm_svd3_strided(A + p, n, U + p, sigma + p, V + p, n);
#endif
}

// F (9, n) in: trial deformation gradient; out: elastic F after plasticity.  tau (6, n) out: Kirchhoff
// stress (xx, yy, zz, yz, xz, xy).  q, vc (n) in/out: hardening and volume-correction states.  keep: the
// fraction of the Case III return applied (mpm_return_map; 1 = rate-independent).
KERNEL void mpm_constitutive_batch(const long long n, float* RESTRICT F, float* RESTRICT tau, float* RESTRICT q,
                                   float* RESTRICT vc, const float* RESTRICT saturation, const float mu,
                                   const float lambda, const float h0, const float h1, const float h2,
                                   const float h3, const float c_max, const float S1, const float S2,
                                   const float S3, const float keep) {
    FOR_EACH(p, n) {
        float f[9], U[9], e0, e1, e2, t[6];
        for (int j = 0; j < 9; ++j) f[j] = F[j * n + p];
#if MPM_HARDENING
        float qp = q[p];
#else
        float qp = 0.f;
#endif
#if MPM_COHESION
        const float S = saturation[p];
#else
        const float S = 0.f;
#endif
        float vcp = vc[p];
        mpm_constitutive(f, U, e0, e1, e2, qp, vcp, S, mu, lambda, h0, h1, h2, h3, c_max, S1, S2, S3, keep);
        mpm_kirchhoff(U, e0, e1, e2, mu, lambda, t);
        for (int j = 0; j < 9; ++j) F[j * n + p] = f[j];
        for (int j = 0; j < 6; ++j) tau[j * n + p] = t[j];
#if MPM_HARDENING
        q[p] = qp;
#endif
        vc[p] = vcp;
    }
}

// The host G2P's vectorisable logf / expf (mpm_simd_math.cuh; the built-ins on CUDA) on their own, to check
// them against libm: logx = mpm_logf(max(|x|, 1e-37)), expx = mpm_expf(x) (|x| <= 88).
MPM_MATH_INLINE void mpm_log_exp_one(const float* x, float* logx, float* expx, const long long i) {
    const float xi = x[i];
    logx[i] = mpm_logf(mpm_max_nonneg(fabsf(xi), 1.0e-37f));
    expx[i] = mpm_expf(xi);
}

KERNEL void mpm_simd_log_exp(const long long n, const float* RESTRICT x, float* RESTRICT logx,
                             float* RESTRICT expx) {
#if CK_ON_GPU
    FOR_EACH(i, n) { mpm_log_exp_one(x, logx, expx, i); }
#else
    CK_PRAGMA(omp parallel for simd schedule(simd : static) if (n > MPM_SERIAL_PARTICLES))
    for (long long i = 0; i < n; ++i) mpm_log_exp_one(x, logx, expx, i);
#endif
}
