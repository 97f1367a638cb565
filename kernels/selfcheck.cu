// Self-check kernels: one of each shape the solvers use (reduction, atomic scatter, periodic stencil).
// `couplekit info --selfcheck` and tests/test_kernels_selfcheck.py compare them with NumPy.
#include "common.cuh"

// 3x3x3 stencil weights, index (dz+1)*9 + (dy+1)*3 + (dx+1): the D3Q27 lattice weights
// (8/27 centre, 2/27 faces, 1/54 edges, 1/216 corners), so a constant field is left unchanged.
CONSTANT float STENCIL27[27] = {
    1.f / 216, 1.f / 54, 1.f / 216, 1.f / 54, 2.f / 27, 1.f / 54, 1.f / 216, 1.f / 54, 1.f / 216,
    1.f / 54,  2.f / 27, 1.f / 54,  2.f / 27, 8.f / 27, 2.f / 27, 1.f / 54,  2.f / 27, 1.f / 54,
    1.f / 216, 1.f / 54, 1.f / 216, 1.f / 54, 2.f / 27, 1.f / 54, 1.f / 216, 1.f / 54, 1.f / 216,
};

// *out += sum_i x[i]  (float32 data, float64 accumulation)
KERNEL void sum_reduce(const long long n, const float* RESTRICT x /* size: n */, double* RESTRICT out /* size: 1 */) {
    REDUCE_SUM_BEGIN(i, n, acc) { acc += (double)x[i]; }
    REDUCE_SUM_END(out, acc)
}

// out[idx[i]] += scale * val[i]  (float atomics: many i may hit one target)
KERNEL void scatter_add(const long long n, const int* RESTRICT idx /* size: n */,
                        const float* RESTRICT val /* size: n */, float* RESTRICT out, const float scale) {
    FOR_EACH(i, n) { atomic_add(&out[idx[i]], scale * val[i]); }
}

// out = sum over the 27 neighbours (periodic) of STENCIL27 * in; n = nx*ny*nz
KERNEL void stencil27_periodic(const long long n, const float* RESTRICT in /* size: nx * ny * nz */,
                               float* RESTRICT out /* size: nx * ny * nz */, const int nx, const int ny,
                               const int nz) {
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        float s = 0.f;
        for (int dz = -1; dz <= 1; ++dz) {
            const int zz = (z + dz + nz) % nz;
            for (int dy = -1; dy <= 1; ++dy) {
                const int yy = (y + dy + ny) % ny;
                for (int dx = -1; dx <= 1; ++dx) {
                    const int xx = (x + dx + nx) % nx;
                    s += STENCIL27[(dz + 1) * 9 + (dy + 1) * 3 + (dx + 1)] *
                         in[xx + (long long)nx * (yy + (long long)ny * zz)];
                }
            }
        }
        out[x + (long long)nx * (y + (long long)ny * z)] = s;
    }
}
