// Float32 3x3 singular value decomposition for the MPM constitutive update, after McAdams, Selle,
// Tamstorf, Teran & Sifakis, "Computing the singular value decomposition of 3x3 matrices with minimal
// branching and elementary floating point operations", UW-Madison TR1690 (2011):
//
//   1. S = A^T A; cyclic Jacobi sweeps over the pairs (0,1), (0,2), (1,2) with the *approximate* Givens
//      rotation of McAdams Alg. 2 (half-angle from (2(s_pp - s_qq), s_pq), clamped to pi/8 when the
//      approximation would be poor), accumulated into V;
//   2. B = A V, columns sorted by decreasing norm (a swap negates one column so det V stays +1);
//   3. QR of B by three Givens rotations: U = Q, Sigma = diag(R).
//
// The result is a signed ("rotation-variant") SVD: U and V are rotations (det = +1) and sigma_3 carries the
// sign of det A, so an inverted F shows up as sigma_3 < 0.  Never produces NaN for finite input: A is
// scaled by its largest entry first (so A^T A cannot overflow or underflow), a zero matrix returns
// U = V = I, Sigma = 0, and every rotation whose norm vanishes falls back to the identity.
//
// Matrices are row-major float[9]: a[3*r + c].  All array indices are compile-time constants after
// inlining (no local-memory arrays on the GPU).
#pragma once
#include "common.cuh"

#ifndef MPM_SVD_SWEEPS
#define MPM_SVD_SWEEPS 5  // Taichi's sifakis_svd uses 5 in float32, Claymore 4
#endif

#define MPM_SVD_GAMMA 5.828427124746190f  // 3 + 2 sqrt(2): tan^2(pi/8) bound of McAdams Alg. 2
#define MPM_SVD_CSTAR 0.923879532511287f  // cos(pi/8)
#define MPM_SVD_SSTAR 0.382683432365090f  // sin(pi/8)
#define MPM_SVD_TINY 1.0e-30f

// One approximate Jacobi rotation of symmetric S on the pair (p, q), accumulated into V (V <- V G).
DEVICE void mpm_jacobi_pair(float S[9], float V[9], const int p, const int q) {
    const int k = 3 - p - q;
    const float app = S[3 * p + p], aqq = S[3 * q + q], apq = S[3 * p + q];
    const float apk = S[3 * p + k], aqk = S[3 * q + k];
    // cosine / sine of the half angle (McAdams Alg. 2)
    float ch = 2.f * (app - aqq);
    float sh = apq;
    const bool ok = MPM_SVD_GAMMA * sh * sh < ch * ch;
    const float w = 1.f / sqrtf(fmaxf(ch * ch + sh * sh, MPM_SVD_TINY));
    ch = ok ? w * ch : MPM_SVD_CSTAR;
    sh = ok ? w * sh : MPM_SVD_SSTAR;
    // full angle: G = [[c, -s], [s, c]] on (p, q); S <- G^T S G
    const float c = ch * ch - sh * sh;
    const float s = 2.f * ch * sh;
    const float cc = c * c, ss = s * s, cs = c * s;
    S[3 * p + p] = cc * app + 2.f * cs * apq + ss * aqq;
    S[3 * q + q] = ss * app - 2.f * cs * apq + cc * aqq;
    const float npq = (cc - ss) * apq + cs * (aqq - app);
    S[3 * p + q] = npq;
    S[3 * q + p] = npq;
    const float npk = c * apk + s * aqk;
    const float nqk = -s * apk + c * aqk;
    S[3 * p + k] = npk;
    S[3 * k + p] = npk;
    S[3 * q + k] = nqk;
    S[3 * k + q] = nqk;
    for (int r = 0; r < 3; ++r) {
        const float vp = V[3 * r + p], vq = V[3 * r + q];
        V[3 * r + p] = c * vp + s * vq;
        V[3 * r + q] = -s * vp + c * vq;
    }
}

// If column j of B is longer than column i (i < j), swap them (and the same columns of V), negating the
// new column j of both so that det V is unchanged.
DEVICE void mpm_sort_pair(float B[9], float V[9], const int i, const int j) {
    const float ni = B[i] * B[i] + B[3 + i] * B[3 + i] + B[6 + i] * B[6 + i];
    const float nj = B[j] * B[j] + B[3 + j] * B[3 + j] + B[6 + j] * B[6 + j];
    const bool sw = nj > ni;
    for (int r = 0; r < 3; ++r) {
        const float bi = B[3 * r + i], bj = B[3 * r + j];
        B[3 * r + i] = sw ? bj : bi;
        B[3 * r + j] = sw ? -bi : bj;
        const float vi = V[3 * r + i], vj = V[3 * r + j];
        V[3 * r + i] = sw ? vj : vi;
        V[3 * r + j] = sw ? -vi : vj;
    }
}

// Givens rotation on rows (j, i) of B zeroing B[i][j] (pivot B[j][j]); Q <- Q G^T.
DEVICE void mpm_qr_givens(float B[9], float Q[9], const int j, const int i) {
    const float a = B[3 * j + j], b = B[3 * i + j];
    const float r2 = a * a + b * b;
    const bool ok = r2 > MPM_SVD_TINY;
    const float inv = ok ? 1.f / sqrtf(r2) : 0.f;
    const float c = ok ? a * inv : 1.f;
    const float s = ok ? b * inv : 0.f;
    for (int col = 0; col < 3; ++col) {
        const float bj = B[3 * j + col], bi = B[3 * i + col];
        B[3 * j + col] = c * bj + s * bi;
        B[3 * i + col] = -s * bj + c * bi;
    }
    for (int r = 0; r < 3; ++r) {
        const float qj = Q[3 * r + j], qi = Q[3 * r + i];
        Q[3 * r + j] = c * qj + s * qi;
        Q[3 * r + i] = -s * qj + c * qi;
    }
}

// A = U diag(sig) V^T; U, V rotations; sig[0] >= sig[1] >= |sig[2]| up to round-off, sig[2] signed.
DEVICE void mpm_svd3(const float A[9], float U[9], float sig[3], float V[9]) {
    float amax = 0.f;
    for (int k = 0; k < 9; ++k) amax = fmaxf(amax, fabsf(A[k]));
    const float scale = amax > 0.f ? 1.f / amax : 0.f;
    float As[9];
    for (int k = 0; k < 9; ++k) As[k] = A[k] * scale;
    // 1. S = As^T As, symmetric eigenproblem by Jacobi sweeps
    float S[9];
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
            S[3 * r + c] = As[r] * As[c] + As[3 + r] * As[3 + c] + As[6 + r] * As[6 + c];
    for (int k = 0; k < 9; ++k) V[k] = (k % 4 == 0) ? 1.f : 0.f;
    for (int sweep = 0; sweep < MPM_SVD_SWEEPS; ++sweep) {
        mpm_jacobi_pair(S, V, 0, 1);
        mpm_jacobi_pair(S, V, 0, 2);
        mpm_jacobi_pair(S, V, 1, 2);
    }
    // 2. B = As V, columns by decreasing norm
    float B[9];
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
            B[3 * r + c] = As[3 * r] * V[c] + As[3 * r + 1] * V[3 + c] + As[3 * r + 2] * V[6 + c];
    mpm_sort_pair(B, V, 0, 1);
    mpm_sort_pair(B, V, 0, 2);
    mpm_sort_pair(B, V, 1, 2);
    // 3. B = Q R
    for (int k = 0; k < 9; ++k) U[k] = (k % 4 == 0) ? 1.f : 0.f;
    mpm_qr_givens(B, U, 0, 1);
    mpm_qr_givens(B, U, 0, 2);
    mpm_qr_givens(B, U, 1, 2);
    sig[0] = B[0] * amax;
    sig[1] = B[4] * amax;
    sig[2] = B[8] * amax;
}
