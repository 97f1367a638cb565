// Memory-bandwidth probes for the fluid throughput benchmark (benchmarks/fluid_throughput.py): the roofline
// of an LBM step is bytes moved / bandwidth.  Not a solver stage; its NumPy twin is the expression in the
// docstring of each kernel (tests/fluid/test_lbm_kernels.py checks them).
#include "common.cuh"

// a[i] = s * a[i] + t   (in place: read + write of one stream, the pattern of in-place LBM streaming)
KERNEL void lbm_bw_update(const long long n, float* RESTRICT a /* size: n */, const float s, const float t) {
    FOR_EACH(i, n) { a[i] = s * a[i] + t; }
}

// c[i] = a[i] + s * b[i]   (STREAM triad: two read streams, one write stream)
KERNEL void lbm_bw_triad(const long long n, const float* RESTRICT a /* size: n */,
                         const float* RESTRICT b /* size: n */, float* RESTRICT c /* size: n */, const float s) {
    FOR_EACH(i, n) { c[i] = a[i] + s * b[i]; }
}
