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
// scaled by its largest entry first (so A^T A cannot overflow or underflow), a zero (or subnormal-sized)
// matrix returns Sigma = 0, and a rotation whose norm vanishes falls back to the identity.
//
// One addition to McAdams Alg. 2: the classic Jacobi threshold.  A pair whose off-diagonal entry is below
// the float32 round-off of its diagonal (|s_pq| <= 1e-7 |(s_pp, s_qq)|) is not rotated; without it, a nearly
// diagonal S (every F near a rotation: particles at rest, free fall) is rotated by the fixed pi/8
// half-angle on rounding noise in every sweep, which adds round-off to V and so to the re-synthesised
// F = U exp(e) V^T each step.  Measured: reconstruction error of rotated near-identity F 3.3e-7 -> 1.4e-7
// (mean), and in a free-falling block (tests/sand/test_solver.py) the velocity error after 100 steps fell
// from 1.4-4.3e-5 to 1.6-2.1e-6 relative over six seedings.
//
// Written branch-free on named scalars (the symmetric S as 6 values, V, B and U as 9 each), never on
// arrays indexed in loops: on the GPU everything lives in registers, and on the host the whole
// decomposition inlines into an `omp simd` loop over a batch of particles, which GCC vectorises (one
// particle per SIMD lane; the Jacobi rotations of one matrix are a serial dependency chain, so across
// particles is the only parallelism there is).  Entry points:
//   mpm_svd3(A, U, sig, V)                          row-major float[9] / float[3] arrays;
//   mpm_svd3_strided(A, lda, U, sig, V, ld)         element k of each matrix at [k * ld]: with a batch
//                                                   buffer float[9][B] and ld = B, a simd loop over the
//                                                   batch reads and writes contiguous vectors.
#pragma once
#include "common.cuh"

#ifndef MPM_SVD_SWEEPS
#define MPM_SVD_SWEEPS 5  // Taichi's sifakis_svd uses 5 in float32, Claymore 4
#endif

#define MPM_SVD_GAMMA 5.828427124746190f  // 3 + 2 sqrt(2): tan^2(pi/8) bound of McAdams Alg. 2
#define MPM_SVD_CSTAR 0.923879532511287f  // cos(pi/8)
#define MPM_SVD_SSTAR 0.382683432365090f  // sin(pi/8)
#define MPM_SVD_TINY 1.0e-30f
// (s_pq / s_pp)^2 below which a Jacobi pair counts as diagonal: |s_pq| < 1e-7 |s_pp|, float32 round-off
#define MPM_SVD_SKIP 1.0e-14f
// below this largest entry 1/amax would overflow (subnormal range): the matrix is treated as zero
#define MPM_SVD_AMIN 1.0e-36f

// helpers are force-inlined on the host: an out-of-line call inside an `omp simd` loop stops the vectoriser
#if defined(__CUDACC__)
#define MPM_INLINE __device__ __forceinline__
#else
#define MPM_INLINE static inline __attribute__((always_inline))
#endif

// max without fmaxf's NaN rules, which GCC cannot vectorise (inputs here are never NaN)
MPM_INLINE float mpm_max(const float a, const float b) { return a > b ? a : b; }

// One approximate Jacobi rotation of the symmetric S on the pair (p, q) (k the third index), with
// S <- G^T S G, V <- V G, G = [[c, -s], [s, c]] on (p, q).  spk = S[p][k], sqk = S[q][k]; v<r>p = V[r][p].
MPM_INLINE void mpm_jacobi_rotate(float& spp, float& sqq, float& spq, float& spk, float& sqk, float& v0p,
                                  float& v0q, float& v1p, float& v1q, float& v2p, float& v2q) {
    const float app = spp, aqq = sqq, apq = spq, apk = spk, aqk = sqk;
    // cosine / sine of the half angle (McAdams Alg. 2)
    float ch = 2.f * (app - aqq);
    float sh = apq;
    const bool ok = MPM_SVD_GAMMA * sh * sh < ch * ch;
    const float w = 1.f / sqrtf(mpm_max(ch * ch + sh * sh, MPM_SVD_TINY));
    ch = ok ? w * ch : MPM_SVD_CSTAR;
    sh = ok ? w * sh : MPM_SVD_SSTAR;
    // classic Jacobi threshold: an off-diagonal entry below the round-off of the diagonal is left alone
    // (rotating by the fixed pi/8 angle on noise only adds round-off to V)
    const bool rotate = apq * apq > MPM_SVD_SKIP * (app * app + aqq * aqq);
    ch = rotate ? ch : 1.f;
    sh = rotate ? sh : 0.f;
    // full angle
    const float c = ch * ch - sh * sh;
    const float s = 2.f * ch * sh;
    const float cc = c * c, ss = s * s, cs = c * s;
    spp = cc * app + 2.f * cs * apq + ss * aqq;
    sqq = ss * app - 2.f * cs * apq + cc * aqq;
    spq = (cc - ss) * apq + cs * (aqq - app);
    spk = c * apk + s * aqk;
    sqk = -s * apk + c * aqk;
    const float t0 = v0p, t1 = v1p, t2 = v2p;
    v0p = c * t0 + s * v0q;
    v0q = -s * t0 + c * v0q;
    v1p = c * t1 + s * v1q;
    v1q = -s * t1 + c * v1q;
    v2p = c * t2 + s * v2q;
    v2q = -s * t2 + c * v2q;
}

// If column j of B is longer than column i (i < j), swap them (and the same columns of V), negating the
// new column j of both so that det V is unchanged.  b<r>i = B[r][i].
MPM_INLINE void mpm_sort_columns(float& b0i, float& b1i, float& b2i, float& b0j, float& b1j, float& b2j,
                                 float& v0i, float& v1i, float& v2i, float& v0j, float& v1j, float& v2j) {
    const float ni = b0i * b0i + b1i * b1i + b2i * b2i;
    const float nj = b0j * b0j + b1j * b1j + b2j * b2j;
    const bool sw = nj > ni;
    float t;
    t = b0i, b0i = sw ? b0j : t, b0j = sw ? -t : b0j;
    t = b1i, b1i = sw ? b1j : t, b1j = sw ? -t : b1j;
    t = b2i, b2i = sw ? b2j : t, b2j = sw ? -t : b2j;
    t = v0i, v0i = sw ? v0j : t, v0j = sw ? -t : v0j;
    t = v1i, v1i = sw ? v1j : t, v1j = sw ? -t : v1j;
    t = v2i, v2i = sw ? v2j : t, v2j = sw ? -t : v2j;
}

// Givens rotation of rows (j, i) of B zeroing B[i][j] against the pivot B[j][j] (= bjj, bij); Q <- Q G^T.
// The rows' other entries are passed as (bjx, bix) pairs; q<r>j = Q[r][j].
MPM_INLINE void mpm_qr_rotate(float& bjj, float& bij, float& bj1, float& bi1, float& bj2, float& bi2, float& q0j,
                              float& q0i, float& q1j, float& q1i, float& q2j, float& q2i) {
    const float a = bjj, b = bij;
    const float r2 = a * a + b * b;
    const bool ok = r2 > MPM_SVD_TINY;
    const float inv = 1.f / sqrtf(mpm_max(r2, MPM_SVD_TINY));
    const float c = ok ? a * inv : 1.f;
    const float s = ok ? b * inv : 0.f;
    float t;
    t = bjj, bjj = c * t + s * bij, bij = -s * t + c * bij;
    t = bj1, bj1 = c * t + s * bi1, bi1 = -s * t + c * bi1;
    t = bj2, bj2 = c * t + s * bi2, bi2 = -s * t + c * bi2;
    t = q0j, q0j = c * t + s * q0i, q0i = -s * t + c * q0i;
    t = q1j, q1j = c * t + s * q1i, q1i = -s * t + c * q1i;
    t = q2j, q2j = c * t + s * q2i, q2i = -s * t + c * q2i;
}

// A = U diag(sig) V^T; U, V rotations; sig[0] >= sig[1] >= |sig[2]| up to round-off, sig[2] signed.
// Element k of A / U / V at [k * lda] / [k * ld], of sig at [k * ld].
MPM_INLINE void mpm_svd3_strided(const float* A, const long long lda, float* U, float* sig, float* V,
                                 const long long ld) {
    const float i00 = A[0], i01 = A[lda], i02 = A[2 * lda];
    const float i10 = A[3 * lda], i11 = A[4 * lda], i12 = A[5 * lda];
    const float i20 = A[6 * lda], i21 = A[7 * lda], i22 = A[8 * lda];
    const float amax = mpm_max(mpm_max(mpm_max(mpm_max(fabsf(i00), fabsf(i01)), mpm_max(fabsf(i02), fabsf(i10))),
                                   mpm_max(mpm_max(fabsf(i11), fabsf(i12)), mpm_max(fabsf(i20), fabsf(i21)))),
                             fabsf(i22));
    const bool nonzero = amax > MPM_SVD_AMIN;
    const float scale = nonzero ? 1.f / mpm_max(amax, MPM_SVD_AMIN) : 0.f;
    const float a00 = i00 * scale, a01 = i01 * scale, a02 = i02 * scale;
    const float a10 = i10 * scale, a11 = i11 * scale, a12 = i12 * scale;
    const float a20 = i20 * scale, a21 = i21 * scale, a22 = i22 * scale;
    // 1. S = A^T A (symmetric), eigenvectors by Jacobi sweeps
    float s00 = a00 * a00 + a10 * a10 + a20 * a20;
    float s11 = a01 * a01 + a11 * a11 + a21 * a21;
    float s22 = a02 * a02 + a12 * a12 + a22 * a22;
    float s01 = a00 * a01 + a10 * a11 + a20 * a21;
    float s02 = a00 * a02 + a10 * a12 + a20 * a22;
    float s12 = a01 * a02 + a11 * a12 + a21 * a22;
    float v00 = 1.f, v01 = 0.f, v02 = 0.f, v10 = 0.f, v11 = 1.f, v12 = 0.f, v20 = 0.f, v21 = 0.f, v22 = 1.f;
#if defined(__CUDACC__)
#pragma unroll
#else
#pragma GCC unroll 8
#endif
    for (int sweep = 0; sweep < MPM_SVD_SWEEPS; ++sweep) {
        // (p, q, k) = (0, 1, 2), (0, 2, 1), (1, 2, 0); S[q][k] etc. by symmetry
        mpm_jacobi_rotate(s00, s11, s01, s02, s12, v00, v01, v10, v11, v20, v21);
        mpm_jacobi_rotate(s00, s22, s02, s01, s12, v00, v02, v10, v12, v20, v22);
        mpm_jacobi_rotate(s11, s22, s12, s01, s02, v01, v02, v11, v12, v21, v22);
    }
    // 2. B = A V, columns by decreasing norm
    float b00 = a00 * v00 + a01 * v10 + a02 * v20, b01 = a00 * v01 + a01 * v11 + a02 * v21,
          b02 = a00 * v02 + a01 * v12 + a02 * v22;
    float b10 = a10 * v00 + a11 * v10 + a12 * v20, b11 = a10 * v01 + a11 * v11 + a12 * v21,
          b12 = a10 * v02 + a11 * v12 + a12 * v22;
    float b20 = a20 * v00 + a21 * v10 + a22 * v20, b21 = a20 * v01 + a21 * v11 + a22 * v21,
          b22 = a20 * v02 + a21 * v12 + a22 * v22;
    mpm_sort_columns(b00, b10, b20, b01, b11, b21, v00, v10, v20, v01, v11, v21);
    mpm_sort_columns(b00, b10, b20, b02, b12, b22, v00, v10, v20, v02, v12, v22);
    mpm_sort_columns(b01, b11, b21, b02, b12, b22, v01, v11, v21, v02, v12, v22);
    // 3. B = Q R by Givens rotations zeroing (1,0), (2,0), (2,1)
    float u00 = 1.f, u01 = 0.f, u02 = 0.f, u10 = 0.f, u11 = 1.f, u12 = 0.f, u20 = 0.f, u21 = 0.f, u22 = 1.f;
    mpm_qr_rotate(b00, b10, b01, b11, b02, b12, u00, u01, u10, u11, u20, u21);
    mpm_qr_rotate(b00, b20, b01, b21, b02, b22, u00, u02, u10, u12, u20, u22);
    mpm_qr_rotate(b11, b21, b10, b20, b12, b22, u01, u02, u11, u12, u21, u22);
    U[0] = u00, U[ld] = u01, U[2 * ld] = u02, U[3 * ld] = u10, U[4 * ld] = u11, U[5 * ld] = u12;
    U[6 * ld] = u20, U[7 * ld] = u21, U[8 * ld] = u22;
    V[0] = v00, V[ld] = v01, V[2 * ld] = v02, V[3 * ld] = v10, V[4 * ld] = v11, V[5 * ld] = v12;
    V[6 * ld] = v20, V[7 * ld] = v21, V[8 * ld] = v22;
    const float back = nonzero ? amax : 0.f;
    sig[0] = b00 * back;
    sig[ld] = b11 * back;
    sig[2 * ld] = b22 * back;
}

// A = U diag(sig) V^T for row-major float[9] matrices (see mpm_svd3_strided).
MPM_INLINE void mpm_svd3(const float A[9], float U[9], float sig[3], float V[9]) {
    mpm_svd3_strided(A, 1, U, sig, V, 1);
}
