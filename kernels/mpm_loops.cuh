// Loop macros of the MPM kernels: those of common.cuh, except that on the host small loops run on one
// thread.  An OpenMP fork/join costs microseconds on an idle machine but milliseconds when the cores are
// shared (a descheduled thread stalls the barrier), and a sand step has several; below the thresholds a
// loop is cheaper serial.  Results do not depend on the thread count (per-item work only).
#pragma once
#include "common.cuh"

#define MPM_SERIAL_PARTICLES 8192
#define MPM_SERIAL_CELLS 65536

#if CK_ON_GPU
#define MPM_FOR_EACH_PARTICLE(i, n) FOR_EACH(i, n)
#define MPM_FOR_EACH_CELL(x, y, z, nx, ny, nz) FOR_EACH_CELL(x, y, z, nx, ny, nz)
#else
#define MPM_FOR_EACH_PARTICLE(i, n)                                                         \
    CK_PRAGMA(omp parallel for schedule(static) if ((long long)(n) > MPM_SERIAL_PARTICLES)) \
    for (long long i = 0; i < (long long)(n); ++i)
#define MPM_FOR_EACH_CELL(x, y, z, nx, ny, nz)                                                              \
    CK_PRAGMA(omp parallel for collapse(2) schedule(static)                                                 \
                  if ((long long)(nx) * (long long)(ny) * (long long)(nz) > MPM_SERIAL_CELLS))               \
    for (int z = 0; z < (int)(nz); ++z)                                                                     \
        for (int y = 0; y < (int)(ny); ++y)                                                                 \
            CK_PRAGMA(omp simd) for (int x = 0; x < (int)(nx); ++x)
#endif
