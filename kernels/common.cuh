// couplekit portability header: one kernel source for CUDA (nvcc / NVRTC) and for the host C++ compiler
// with OpenMP.  Every file in kernels/ includes it first.
//
// Conventions (checked by couplekit.backend when a kernel is called):
//   * a kernel is `KERNEL void name(const long long n, ...)`; `n` is the number of work items, the runtime
//     sizes the CUDA launch from it and the host path ignores it except inside the loop macros;
//   * parameters are pointers to float/double/int/unsigned int/long long/unsigned char (optionally const and
//     RESTRICT) or scalars of float/double/int/unsigned int/long long;
//   * a pointer parameter may carry a size annotation, checked before every launch: `float* f /* size: 27 * n */`
//     (exact element count) or `/* size >= nx * ny */` (at least), in terms of n and integer parameters;
//   * one stage per kernel; no shared memory and no __syncthreads (the host path has no equivalent).
//
// Loops:
//   FOR_EACH(i, n)                       i in [0, n): grid-stride loop on CUDA, `omp parallel for` on host.
//   FOR_EACH_CELL(x, y, z, nx, ny, nz)   every cell of an nx*ny*nz box (launch with n = nx*ny*nz): one
//                                        thread per cell on CUDA; on the host (z, y) rows run in parallel
//                                        and the inner x loop is an `omp simd` loop, so x must be the
//                                        contiguous index (linear index x + nx*(y + ny*z)).
//   REDUCE_SUM_BEGIN(i, n, acc) { acc += ...; } REDUCE_SUM_END(out, acc)
//                                        adds sum_i(...) in double to *out.  On the host the per-thread
//                                        partials are combined in thread order, so for a fixed thread count
//                                        the result is bitwise reproducible.
//   REDUCE_SUM2_BEGIN(i, n, a, b) ... REDUCE_SUM2_END(out, a, b): two such sums in one loop, into out[0], out[1].
// CK_PER_ITEM(v): v, hidden from the GPU compiler's common-subexpression and loop-invariant optimisations
// (register pressure; see the CUDA section).
// Atomics: atomic_add(float*|double*|int*|unsigned int*, value).
// CK_NANF: a quiet float NaN (to mark a result that cannot be computed, e.g. a particle whose position is not
// finite: it must stay visibly non-finite, never be turned into a valid-looking number).
// Tables:  CONSTANT float W[27] = {...};   (__constant__ on CUDA, static constexpr on the host)
//
// Device path: the host compiler with -DCK_DEVICE_PATH=1 builds the CK_ON_GPU branches (see the host section).
//
// Build variants: a kernel file whose code depends on -D flags lists the values each flag takes in a
// comment line  `// variants: CK_FLAG_A=0,1 CK_FLAG_B=0,1`; the build tests (nvcc sm_80/sm_90, NVRTC)
// compile every combination. Without such a line the file is compiled once, with no flags.
#pragma once

// Launch configuration: the cuda backend launches every kernel with CK_BLOCK_SIZE threads per block
// (couplekit/backend/cuda.py BLOCK_SIZE; tests/test_kernel_builds.py checks they agree), and every kernel
// carries __launch_bounds__(CK_BLOCK_SIZE, CK_MIN_BLOCKS_PER_SM): ptxas then keeps a kernel within
// 65536 / (CK_BLOCK_SIZE * CK_MIN_BLOCKS_PER_SM) = 128 registers per thread on sm_80 / sm_90 (at least 25 %
// theoretical occupancy, 2 blocks of 8 warps per SM), and a kernel that needs more spills, which the build
// test refuses.
#define CK_BLOCK_SIZE 256
#ifndef CK_MIN_BLOCKS_PER_SM  // -DCK_MIN_BLOCKS_PER_SM=1 measures a kernel's unbounded register count (255 max)
#define CK_MIN_BLOCKS_PER_SM 2
#endif

// Storage of the populations f (D3Q27) and h (D3Q7): CK_STORAGE_FP16 = 0 (float32, the default) or 1 (IEEE
// binary16 bits, arithmetic stays float32; docs/precision.md "fp16 storage").  Kernels declare the arrays as
// `ck_store_t*` (couplekit.backend.signature resolves it with the module's defines: float32, or a float16 /
// uint16 array) and read / write them only through
//   CK_LOAD(p, i, scale)      -> float value of element i  (stored / scale; fp32: p[i])
//   CK_STORE(p, i, v, scale)  stores v * scale rounded to the storage type  (fp32: p[i] = v)
//   CK_LOAD_SCALAR / CK_STORE_SCALAR: the same values, for loops the host does not vectorise (hardware F16C)
// scale: CK_F_SCALE for f - w, CK_H_SCALE for h - CK_H_REST w_q (powers of two, so the scaling is exact;
// CK_H_REST = 0: h is stored unshifted, chosen by measurement).
// Rounding is round-to-nearest-even on both paths (host: integer bit operations, exact; CUDA: cvt.rn.f16.f32),
// as NumPy's float16, so the reference rounds alike; a value beyond 65504 / scale
// becomes +-inf (not a clamp), which the divergence checks see.  The Python twins of the constants:
// couplekit.fluid.storage (a test reads them from here).
#ifndef CK_STORAGE_FP16
#define CK_STORAGE_FP16 0
#endif
#if CK_STORAGE_FP16
#define CK_F_SCALE 32768.f
#define CK_H_SCALE 32768.f
#ifndef CK_H_REST  // 0 or 1; 0 measured better than 1 (h - w stored): docs/precision.md "fp16 storage"
#define CK_H_REST 0
#endif
#else
#define CK_F_SCALE 1.f
#define CK_H_SCALE 1.f
#define CK_H_REST 0
// float32 storage, the same on CUDA and on the host (the fp16 conversions are per compiler: below)
typedef float ck_store_t;
#define CK_LOAD(p, i, scale) ((p)[i])
#define CK_STORE(p, i, v, scale) ((p)[i] = (v))
#define CK_LOAD_SCALAR(p, i, scale) ((p)[i])
#define CK_STORE_SCALAR(p, i, v, scale) ((p)[i] = (v))
#endif

#if defined(__CUDACC__)
// ---------------------------------------------------------------------------------------------- CUDA
// NVRTC has no host headers: nothing may be included here (math functions are built in).
#define KERNEL extern "C" __global__ __launch_bounds__(CK_BLOCK_SIZE, CK_MIN_BLOCKS_PER_SM)
#define DEVICE __device__ __forceinline__
#define CONSTANT __constant__ const
#define RESTRICT __restrict__
#define CK_ON_GPU 1
#define CK_NANF __int_as_float(0x7fc00000)

#if CK_STORAGE_FP16
// binary16 bits <-> float by the PTX conversions (no header: NVRTC has none); .rn = round to nearest even,
// out of range -> inf
typedef unsigned short ck_store_t;
DEVICE float ck_half_to_float_(const unsigned short b) {
    float v;
    asm("cvt.f32.f16 %0, %1;" : "=f"(v) : "h"(b));
    return v;
}
DEVICE unsigned short ck_float_to_half_(const float v) {
    unsigned short b;
    asm("cvt.rn.f16.f32 %0, %1;" : "=h"(b) : "f"(v));
    return b;
}
#define CK_LOAD(p, i, scale) (ck_half_to_float_((p)[i]) * (1.f / (scale)))
#define CK_STORE(p, i, v, scale) ((p)[i] = ck_float_to_half_((v) * (scale)))
#define CK_LOAD_SCALAR(p, i, scale) CK_LOAD(p, i, scale)
#define CK_STORE_SCALAR(p, i, v, scale) CK_STORE(p, i, v, scale)
#endif  // fp32 storage: the shared definitions above the CUDA / host sections

#define CK_THREAD_INDEX ((long long)blockIdx.x * (long long)blockDim.x + (long long)threadIdx.x)
#define CK_THREAD_STRIDE ((long long)blockDim.x * (long long)gridDim.x)

#define FOR_EACH(i, n) for (long long i = CK_THREAD_INDEX; i < (long long)(n); i += CK_THREAD_STRIDE)

#define FOR_EACH_CELL(x, y, z, nx, ny, nz)                                                               \
    for (long long ck_cell_ = CK_THREAD_INDEX, ck_ncell_ = (long long)(nx) * (long long)(ny) * (nz);      \
         ck_cell_ < ck_ncell_; ck_cell_ += CK_THREAD_STRIDE)                                              \
        for (int x = (int)(ck_cell_ % (nx)), y = (int)((ck_cell_ / (nx)) % (ny)),                        \
                 z = (int)(ck_cell_ / ((long long)(nx) * (ny))), ck_once_ = 1;                            \
             ck_once_; ck_once_ = 0)

// CK_PER_ITEM(v): the value v, opaque to the optimiser.  Inside a grid-stride loop, a value derived only from
// kernel arguments is loop-invariant, and the compiler hoists it out of the loop and keeps it in a register for
// the whole loop: the 27 64-bit stream offsets q N +- (c_x + px c_y + pxy c_z) of the LBM loads and stores
// took 54-80 of lbm_collide_stream's 242 registers and most of lbm_momentum's 142 (measured with ptxas for
// sm_90: a one-pass copy of lbm_momentum used 64).  Taking the grid sizes through CK_PER_ITEM inside the loop
// makes everything derived from them per-iteration, so it is recomputed (one integer multiply-add) where it
// is used.  The empty asm emits no instruction.  Identity on the host.
DEVICE long long ck_per_item_(long long v) {
    asm volatile("" : "+l"(v));
    return v;
}
DEVICE int ck_per_item_(int v) {
    asm volatile("" : "+r"(v));
    return v;
}
DEVICE unsigned int ck_per_item_(unsigned int v) {
    asm volatile("" : "+r"(v));
    return v;
}
#define CK_PER_ITEM(v) ck_per_item_(v)

DEVICE void atomic_add(float* addr, float v) { atomicAdd(addr, v); }
DEVICE void atomic_add(double* addr, double v) { atomicAdd(addr, v); }
DEVICE void atomic_add(int* addr, int v) { atomicAdd(addr, v); }
DEVICE void atomic_add(unsigned int* addr, unsigned int v) { atomicAdd(addr, v); }

DEVICE double ck_warp_sum(double v) {
    for (int offset = 16; offset > 0; offset >>= 1) v += __shfl_down_sync(0xffffffffu, v, offset);
    return v;
}

#define REDUCE_SUM_BEGIN(i, n, acc) \
    {                               \
        double acc = 0.0;           \
        FOR_EACH(i, n)

// every thread leaves the grid-stride loop before the warp shuffle, so the whole warp takes part
#define REDUCE_SUM_END(out, acc)                             \
        acc = ck_warp_sum(acc);                              \
        if ((threadIdx.x & 31u) == 0u) atomicAdd((out), acc); \
    }
// two sums in one loop: REDUCE_SUM2_BEGIN(i, n, a, b) { a += ...; b += ...; } REDUCE_SUM2_END(out, a, b) adds
// them to out[0] and out[1]
#define REDUCE_SUM2_BEGIN(i, n, a, b) \
    {                                 \
        double a = 0.0, b = 0.0;      \
        FOR_EACH(i, n)
#define REDUCE_SUM2_END(out, a, b)                                 \
        a = ck_warp_sum(a);                                        \
        b = ck_warp_sum(b);                                        \
        if ((threadIdx.x & 31u) == 0u) {                           \
            atomicAdd((out), a);                                   \
            atomicAdd((out) + 1, b);                               \
        }                                                          \
    }

#else
// ---------------------------------------------------------------------------------------------- host
#include <cmath>
#include <cstdint>
#include <omp.h>

#define KERNEL extern "C" __attribute__((visibility("default")))
#define DEVICE static inline
#define CONSTANT static constexpr
#define RESTRICT __restrict__
#define CK_NANF __builtin_nanf("")

#if CK_STORAGE_FP16
// binary16 bits <-> float with integer operations and selects, bit-exact round-to-nearest-even (F. Giesen's
// float_to_half_fast3_rtne; overflow -> inf, NaN -> quiet NaN; subnormals through one float addition, which
// rounds to nearest even).  Not _Float16: GCC 12 converts it correctly but, without AVX512-FP16, does not
// vectorise the conversions, and the collide-stream x loop then ran scalar (0.35x the fp32 throughput, measured
// with benchmarks/fluid_throughput.py --storage fp16); these vectorise as 32-bit lane operations.
typedef unsigned short ck_store_t;
static inline __attribute__((always_inline)) float ck_half_to_float_(const unsigned short b) {
    const uint32_t sign = (uint32_t)(b & 0x8000u) << 16, em = b & 0x7fffu;
    uint32_t n = (em << 13) + 0x38000000u;              // rebias the exponent (normal numbers)
    n += 0x38000000u & (0u - (uint32_t)(em >= 0x7c00u));  // inf / NaN: exponent all ones (a mask, not a select)
    // subnormal: em * 2^-24, exact; blended by a mask (a select between it and n stops g++ if-converting)
    const uint32_t sub = __builtin_bit_cast(uint32_t, (float)(int)em * 5.9604644775390625e-8f);
    const uint32_t m = 0u - (uint32_t)(em < 0x0400u);
    return __builtin_bit_cast(float, ((sub & m) | (n & ~m)) | sign);
}
static inline __attribute__((always_inline)) unsigned short ck_float_to_half_(const float f) {
    const uint32_t x = __builtin_bit_cast(uint32_t, f), sign = x & 0x80000000u, a = x ^ sign;
    // subnormal or zero: align the 10 mantissa bits at the bottom with a magic addition (0.5f)
    const uint32_t sub = __builtin_bit_cast(uint32_t, __builtin_bit_cast(float, a) + 0.5f) - 0x3f000000u;
    // normal: rebias, round to nearest even, take the bits (a carry into the exponent gives inf correctly)
    const uint32_t nrm = (a + 0xc8000fffu + ((a >> 13) & 1u)) >> 13;  // 0xc8000fff = ((15 - 127) << 23) + 0xfff
    // a >= 65520 (as bits): NaN -> quiet NaN 0x7e00, else inf 0x7c00; below 2^-14: subnormal; else normal.
    // Blended by masks: g++ 12 leaves the selects as branches, and the collide x loop with fp16 storage ran
    // scalar ("control flow in loop")
    const uint32_t big = 0x7c00u | (0x0200u & (0u - (uint32_t)(a > 0x7f800000u)));
    const uint32_t mbig = 0u - (uint32_t)(a >= 0x47800000u), msub = 0u - (uint32_t)(a < 0x38800000u);
    const uint32_t o = (big & mbig) | (((sub & msub) | (nrm & ~msub)) & ~mbig);
    return (unsigned short)(o | (sign >> 16));
}
#define CK_LOAD(p, i, scale) (ck_half_to_float_((p)[i]) * (1.f / (scale)))
#define CK_STORE(p, i, v, scale) ((p)[i] = ck_float_to_half_((v) * (scale)))
// the same conversions for loops the host runs scalar (the pressure update, the phase field's odd step): one
// F16C instruction each (vcvtph2ps / vcvtps2ph, round to nearest even under the default MXCSR) instead of the
// integer sequence, which only pays where it vectorises; both round alike (a test compares them with NumPy)
#define CK_LOAD_SCALAR(p, i, scale) ((float)__builtin_bit_cast(_Float16, (p)[i]) * (1.f / (scale)))
#define CK_STORE_SCALAR(p, i, v, scale) ((p)[i] = __builtin_bit_cast(unsigned short, (_Float16)((v) * (scale))))
#endif  // fp32 storage: the shared definitions above the CUDA / host sections
#define CK_MAX_THREADS 1024

#define CK_PRAGMA(x) _Pragma(#x)
// host loops over runs of a row that are often shorter than g++'s vector: 8 lanes. Left to pick its own width,
// g++ 12 (AVX-512) takes 16 float / 32 byte lanes with a scalar epilogue, which ran every such loop on Fig. 13
// small's 26-cell rows scalar (perf): the flag widening to 32-bit words (45 % of the source term's time), and the
// phase field's odd bulk runs, chunk gradients and masks, which cannot re-run a cell as the row loops' tail vector
// does (lbm_row_tail)
#define CK_SIMD_SHORT CK_PRAGMA(omp simd simdlen(8))
#define CK_PER_ITEM(v) (v)

#define FOR_EACH(i, n) CK_PRAGMA(omp parallel for schedule(static)) for (long long i = 0; i < (long long)(n); ++i)

#if defined(CK_DEVICE_PATH) && CK_DEVICE_PATH
// Device-path host build (the cpu-device backend): the CUDA code paths (`#if CK_ON_GPU`) built by the host
// compiler, so that the algorithms a GPU runs are run and tested without one.  A CUDA thread's work item
// becomes an iteration of an `omp parallel for` over the same index space (FOR_EACH as above; FOR_EACH_CELL
// one flat cell index decoded into (x, y, z) exactly as the CUDA macro does), and atomicAdd becomes
// `omp atomic` (atomic_add below).  The warp-shuffle reduction has no host equivalent: REDUCE_SUM keeps the
// host's thread-order sum.  No kernel uses shared memory or __syncthreads.
#define CK_ON_GPU 1
#define FOR_EACH_CELL(x, y, z, nx, ny, nz)                                                                 \
    CK_PRAGMA(omp parallel for schedule(static))                                                           \
    for (long long ck_cell_ = 0; ck_cell_ < (long long)(nx) * (long long)(ny) * (nz); ++ck_cell_)           \
        for (int x = (int)(ck_cell_ % (nx)), y = (int)((ck_cell_ / (nx)) % (ny)),                          \
                 z = (int)(ck_cell_ / ((long long)(nx) * (ny))), ck_once_ = 1;                              \
             ck_once_; ck_once_ = 0)
#else
#define CK_ON_GPU 0
#define FOR_EACH_CELL(x, y, z, nx, ny, nz)                                   \
    CK_PRAGMA(omp parallel for collapse(2) schedule(static))                 \
    for (int z = 0; z < (int)(nz); ++z)                                      \
        for (int y = 0; y < (int)(ny); ++y)                                  \
            CK_PRAGMA(omp simd) for (int x = 0; x < (int)(nx); ++x)
#endif

DEVICE void atomic_add(float* addr, float v) {
    CK_PRAGMA(omp atomic)
    *addr += v;
}
DEVICE void atomic_add(double* addr, double v) {
    CK_PRAGMA(omp atomic)
    *addr += v;
}
DEVICE void atomic_add(int* addr, int v) {
    CK_PRAGMA(omp atomic)
    *addr += v;
}
DEVICE void atomic_add(unsigned int* addr, unsigned int v) {
    CK_PRAGMA(omp atomic)
    *addr += v;
}

#define REDUCE_SUM_BEGIN(i, n, acc)                              \
    {                                                            \
        double ck_partial_[CK_MAX_THREADS];                      \
        int ck_nthreads_ = 1;                                    \
        CK_PRAGMA(omp parallel num_threads(ck_reduce_threads_())) \
        {                                                        \
            double acc = 0.0;                                    \
            CK_PRAGMA(omp for schedule(static))                  \
            for (long long i = 0; i < (long long)(n); ++i)

#define REDUCE_SUM_END(out, acc)                                     \
            ck_partial_[omp_get_thread_num()] = acc;                 \
            CK_PRAGMA(omp single) ck_nthreads_ = omp_get_num_threads(); \
        }                                                            \
        double ck_total_ = 0.0;                                      \
        for (int t = 0; t < ck_nthreads_; ++t) ck_total_ += ck_partial_[t]; \
        *(out) += ck_total_;                                         \
    }

// two sums in one loop (the GPU section's comment); each combined in thread order like REDUCE_SUM
#define REDUCE_SUM2_BEGIN(i, n, a, b)                            \
    {                                                            \
        double ck_partial_[2 * CK_MAX_THREADS];                  \
        int ck_nthreads_ = 1;                                    \
        CK_PRAGMA(omp parallel num_threads(ck_reduce_threads_())) \
        {                                                        \
            double a = 0.0, b = 0.0;                             \
            CK_PRAGMA(omp for schedule(static))                  \
            for (long long i = 0; i < (long long)(n); ++i)

#define REDUCE_SUM2_END(out, a, b)                                   \
            ck_partial_[2 * omp_get_thread_num()] = a;               \
            ck_partial_[2 * omp_get_thread_num() + 1] = b;           \
            CK_PRAGMA(omp single) ck_nthreads_ = omp_get_num_threads(); \
        }                                                            \
        double ck_total_a_ = 0.0, ck_total_b_ = 0.0;                 \
        for (int t = 0; t < ck_nthreads_; ++t) {                     \
            ck_total_a_ += ck_partial_[2 * t];                       \
            ck_total_b_ += ck_partial_[2 * t + 1];                   \
        }                                                            \
        (out)[0] += ck_total_a_;                                     \
        (out)[1] += ck_total_b_;                                     \
    }

DEVICE int ck_reduce_threads_() {
    const int t = omp_get_max_threads();
    return t < CK_MAX_THREADS ? t : CK_MAX_THREADS;
}

// Thread count of the host build; called by the runtime once after loading a module.
extern "C" __attribute__((visibility("default"))) void couplekit_set_num_threads(int n) {
    if (n > 0) omp_set_num_threads(n);
}
extern "C" __attribute__((visibility("default"))) int couplekit_get_num_threads(void) {
    return omp_get_max_threads();
}
#endif

// c ? a : b for c = 0 or 1.  On the host a bit-mask blend: g++ 12 if-converts neither float selects nor
// fminf / fmaxf calls inside the host x loops ("control flow in loop": the two-phase and odd-rate variants
// ran scalar); the blend is plain integer lane arithmetic and vectorises.  The condition is a 32-bit value,
// not a bool: a bool in the x loop makes g++ size its lanes for bytes (vectorisation factor 32, four ymm
// registers per float) and give up as unprofitable.  The GPU takes the select (one instruction).
#if defined(__CUDACC__)
__device__ __forceinline__
#else
static inline __attribute__((always_inline))  // an out-of-line call in an `omp simd` loop stops the vectoriser
#endif
float ck_select(const unsigned int c, const float a, const float b) {
#if CK_ON_GPU
    return c ? a : b;
#else
    const uint32_t m = 0u - c;
    return __builtin_bit_cast(float, (__builtin_bit_cast(uint32_t, a) & m) | (__builtin_bit_cast(uint32_t, b) & ~m));
#endif
}

// fminf / fmaxf.  On the host as blends that give what glibc's x86-64 fminf / fmaxf return (minss / maxss:
// x < y ? x : y, so min(-0, +0) = +0; the other argument when one is NaN): g++ calls libm for fminf / fmaxf
// unless math is finite-only, and a call leaves the loop around it scalar (the coupling kernels: 1 % of Fig. 13
// small's step in __fminf alone).  The GPU takes its own fminf / fmaxf (NaN: the other argument as well).
#if CK_ON_GPU
#define ck_fminf fminf
#define ck_fmaxf fmaxf
#else
static inline __attribute__((always_inline)) float ck_fminf(const float x, const float y) {
    return ck_select((unsigned int)((x < y) | (y != y)), x, y);
}
static inline __attribute__((always_inline)) float ck_fmaxf(const float x, const float y) {
    return ck_select((unsigned int)((x > y) | (y != y)), x, y);
}
#endif

#if !CK_ON_GPU
// Host OR reductions over a short run of a row (9 rows of nx + 2 cells per row of a stage; 28 cells in Fig. 13
// small).  Written as 8-lane blocks and a scalar remainder of < 8: g++'s own vector loops (and `omp simd
// reduction`) take 16 or 32 lanes with a scalar epilogue, which ran a 28-cell run entirely scalar (perf: the
// flag scans were 10-20 % of the collide's and the filter's time, the float scan 80 % of the source term's).
// The bytes of a run OR-ed as 8-byte words.
static inline uint64_t ck_or_bytes(const unsigned char* RESTRICT r, const int n) {
    uint64_t any = 0;
    int i = 0;
    for (; i + 8 <= n; i += 8) {
        uint64_t w;
        __builtin_memcpy(&w, r + i, 8);
        any |= w;
    }
    for (; i < n; ++i) any |= r[i];
    return any;
}
// Floats compared with v as bit patterns (an integer OR): for v != 0 exactly one pattern equals v (a NaN
// equals nothing either way); for v = 0 the sign bit is masked (-0 == 0).  Nonzero when some r[i] != v.
static inline uint32_t ck_differs_bits(const float a, const uint32_t vbits, const uint32_t mask) {
    return (__builtin_bit_cast(uint32_t, a) & mask) ^ vbits;
}
static inline uint32_t ck_any_differs(const float* RESTRICT r, const int n, const float v) {
    const uint32_t mask = v == 0.f ? 0x7fffffffu : 0xffffffffu, vbits = __builtin_bit_cast(uint32_t, v) & mask;
    uint32_t acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    int i = 0;
    for (; i + 8 <= n; i += 8)
        for (int k = 0; k < 8; ++k) acc[k] |= ck_differs_bits(r[i + k], vbits, mask);
    uint32_t any = 0;
    for (; i < n; ++i) any |= ck_differs_bits(r[i], vbits, mask);
    for (int k = 0; k < 8; ++k) any |= acc[k];
    return any;
}
// host: whether every cell of the 9 padded rows around `row` (the row and its y, z neighbours; x in xa .. xb)
// holds exactly `v` in `s` (a row with no sand around it: fluid fraction 1, sand velocity 0; the row schemes of
// lbm_macro_pressure and coupling_phase_source take such rows without their mixture stencils)
static inline bool ck_rows_equal(const float* RESTRICT s, const long long row, const int xa, const int xb,
                                 const int px, const long long pxy, const float v) {
    uint32_t any = 0;
    for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
            any |= ck_any_differs(s + row + (long long)dy * px + (long long)dz * pxy + xa, xb - xa + 1, v);
    return any == 0;
}

// host: the stored value `new_` where live = 1, else `old_`, blended bit by bit without a branch (the guarded
// stores of the wall-row loops, which write a non-fluid cell's old value back); fp32 and fp16 storage
static inline __attribute__((always_inline)) ck_store_t ck_store_blend(const unsigned int live, const ck_store_t new_,
                                                                       const ck_store_t old_) {
#if CK_STORAGE_FP16
    const ck_store_t m = (ck_store_t)(0u - live);
    return (ck_store_t)((new_ & m) | (old_ & (ck_store_t)~m));
#else
    return ck_select(live, new_, old_);
#endif
}
#endif
