// Float32 logf / expf that the host compiler can vectorise, for the constitutive update of the batched
// host G2P (kernels/mpm_g2p.cu).  GCC vectorises a loop that calls libm's logf / expf only under
// -ffast-math (glibc declares the SIMD variants only then), so inside `omp simd` loops the host build uses
// these branch-free versions; CUDA uses its built-ins.
//
// Algorithms: Cephes (S. L. Moshier, Cephes Math Library 2.2, logf.c / expf.c, the single-precision
// minimax polynomials), with selects instead of branches and exponent / mantissa taken apart by bit
// operations.  Cephes gives a peak relative error of 7.6e-8 (logf) / 1.0e-7 (expf) over the IEEE range;
// the test (tests/sand/test_svd.py) checks <= 2 ulp against libm on the ranges used here.
//
//   mpm_logf(x)  x a positive normal float (callers clamp |sigma| >= 1e-4 first, with mpm_max_nonneg);
//   mpm_expf(x)  |x| <= 88 (beyond, 2^n is held in the normal range and the result is merely inaccurate;
//                the Hencky strains passed here are logs of clamped singular values, |x| < 89).
#pragma once
#include "common.cuh"

#if defined(__CUDACC__)
#define MPM_MATH_INLINE __device__ __forceinline__
MPM_MATH_INLINE float mpm_logf(const float x) { return logf(x); }
MPM_MATH_INLINE float mpm_max_nonneg(const float a, const float b) { return fmaxf(a, b); }
MPM_MATH_INLINE float mpm_expf(const float x) { return expf(x); }
#else
#define MPM_MATH_INLINE static inline __attribute__((always_inline))

MPM_MATH_INLINE int mpm_float_bits(const float f) {
    int i;
    __builtin_memcpy(&i, &f, sizeof i);
    return i;
}

MPM_MATH_INLINE float mpm_bits_float(const int i) {
    float f;
    __builtin_memcpy(&f, &i, sizeof f);
    return f;
}

// max(a, b) of non-negative floats by their bit patterns (ordered like the values): a float select with a
// constant arm in front of mpm_logf gets the constant's log folded into a separate path, i.e. control flow
MPM_MATH_INLINE float mpm_max_nonneg(const float a, const float b) {
    const int ia = mpm_float_bits(a), ib = mpm_float_bits(b);
    return mpm_bits_float(ia > ib ? ia : ib);
}

MPM_MATH_INLINE float mpm_logf(const float x) {
    const int ix = mpm_float_bits(x);
    int e = ((ix >> 23) & 0xff) - 126;                        // x = m 2^e, m in [0.5, 1)
    float m = mpm_bits_float((ix & 0x007fffff) | 0x3f000000);  // mantissa with exponent of 0.5
    // m in [sqrt(1/2), sqrt(2)) after the shift; arithmetic on the comparison instead of ?: (GCC's jump
    // threading turns the latter into control flow that the loop vectoriser refuses)
    const int low = m < 0.707106781186547524f;
    e -= low;
    m = m + (float)low * m - 1.f;
    const float z = m * m;
    float y = 7.0376836292E-2f;
    y = y * m - 1.1514610310E-1f;
    y = y * m + 1.1676998740E-1f;
    y = y * m - 1.2420140846E-1f;
    y = y * m + 1.4249322787E-1f;
    y = y * m - 1.6668057665E-1f;
    y = y * m + 2.0000714765E-1f;
    y = y * m - 2.4999993993E-1f;
    y = y * m + 3.3333331174E-1f;
    y = y * m * z;
    const float fe = (float)e;
    y += -2.12194440e-4f * fe;  // ln 2 = 0.693359375 - 2.12194440e-4 (split so fe * 0.693359375 is exact)
    y += -0.5f * z;
    return (m + y) + 0.693359375f * fe;
}

MPM_MATH_INLINE float mpm_expf(float x) {
    // n = round(x / ln 2) by truncation and a correction (floorf does not vectorise), kept in [-126, 127]
    // with integer min / max (float selects here become control flow the loop vectoriser refuses)
    const float t = 1.44269504088896341f * x + 0.5f;
    int n = (int)t;
    n -= (int)(t < (float)n);
    n = n < 127 ? n : 127;
    n = n > -126 ? n : -126;
    const float fn = (float)n;
    x = x - fn * 0.693359375f;
    x = x - fn * -2.12194440e-4f;
    const float z = x * x;
    float y = 1.9875691500E-4f;
    y = y * x + 1.3981999507E-3f;
    y = y * x + 8.3334519073E-3f;
    y = y * x + 4.1665795894E-2f;
    y = y * x + 1.6666665459E-1f;
    y = y * x + 5.0000001201E-1f;
    y = y * z + x + 1.f;
    return y * mpm_bits_float((n + 127) << 23);  // n in [-126, 127]: 2^n is a normal float
}
#endif
