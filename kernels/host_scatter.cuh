// Deterministic particle-to-grid scatter on the host, without per-thread copies of the grid.
//
// A particle scatters into the 3 x 3 x 3 nodes from its stencil's base node (bx, by, bz) on.  The (y, z) plane of
// base nodes is cut into tiles of HOST_SCATTER_TILE x HOST_SCATTER_TILE; a particle's tile is that of (by, bz).
// A tile's particles write nodes of layers [t T, t T + T + 1] in y and in z, so two tiles whose y or z tile
// indices differ by 2 or more never write the same node (T >= 2).  The tiles are coloured by the parity of their
// (y, z) tile indices; colour by colour, the tiles of one colour run in parallel, each tile's particles one after
// another in increasing particle index into a buffer of the thread's own, which is then added into the grid
// (plain, not atomic, additions).
//
// Every node therefore sums its contributions in one order that depends on the particles and the grid only: the
// colours in turn, for each the sum of the one tile of that colour that reaches the node, in particle index order.  The result is bitwise the same for any thread count and any
// schedule (the private grids it replaces were summed in thread order, so the result changed with the thread
// count), and the memory is the particle order (1 int per particle) and the tile counts (1 int per tile and
// thread) instead of a grid per thread (5 floats per node per thread for the MPM P2G: 160 B per node on 8 threads).
//
// The particles are grouped by tile with a stable counting sort: each thread counts its static block of particles
// per tile, the counts become offsets tile by tile and thread by thread, and each thread places its block.
//
// Host only (the CUDA builds scatter with atomics).  Used by mpm_p2g.cu and coupling_moisture.cu.
#pragma once
#include "common.cuh"

#if !CK_ON_GPU
#include <vector>

// base-node layers per tile along y and z (>= 2; see above).  Measured on the host P2G, one run, old/new against
// the private grids (a scratch timing of the kernel alone, session 23): 4 gives 0.97-0.99x on a dense column (Fig. 17 small, 32,768
// particles, 1 and 2 threads), 3 0.95x, 2 0.92x (a tile's buffer rows, (T + 2)^2 per T^2 base rows, are cleared and
// added once per tile); sparse sand in a larger grid gains (Fig. 13 small 1.7x, Fig. 16 small 1.16x).  Smaller tiles
// would give a small body more tiles per colour on many threads.
#define HOST_SCATTER_TILE 4

// tiles along an axis of n nodes
static inline int host_scatter_tiles_along(const int n) { return (n + HOST_SCATTER_TILE - 1) / HOST_SCATTER_TILE; }

// the stencil's first node along an axis, for grid coordinate X (node i at i): the quadratic B-spline's base
static inline int host_scatter_base(const float X) { return (int)floorf(X - 0.5f); }

// the tile of a particle at grid coordinates (Y, Z) (node i at i) whose stencil lies inside the grid: that of its
// base node (floor(Y - 1/2), floor(Z - 1/2)), the quadratic B-spline's first node
static inline long long host_scatter_tile(const float Y, const float Z, const int ny) {
    const int by = host_scatter_base(Y), bz = host_scatter_base(Z);
    return (long long)(by / HOST_SCATTER_TILE) + (long long)host_scatter_tiles_along(ny) * (bz / HOST_SCATTER_TILE);
}

// A tile's particles add into a buffer of the thread's own first, F floats per node side by side over the
// (T + 2) x (T + 2) node rows the tile reaches (36 rows of nx nodes: 28.8 KB for F = 5 and nx = 40),
// which is then added into the F grid arrays: scattered straight into five separate arrays the P2G of a dense
// column ran 0.8x the speed of the private grids (whose nodes also held their 5 floats side by side).
// body(p, row): particle p's additions, through row(z, y) = the buffer's F x nx floats of node row (y, z) of the
// grid, one its stencil reaches (float f + F x of that row: node x, field f).  A lambda capturing by value: with
// [&] its stores through float pointers could alias the captured floats, which were then reloaded after each
// store (1.15x slower).
#define HOST_SCATTER_ROWS (HOST_SCATTER_TILE + 2)

// Scatter n particles into the F grid arrays grid[0 .. F) (nx * ny * nz floats each), which it overwrites.
// tile_of(p): the tile of particle p (host_scatter_tile), or -1 to leave it out (counted in *skipped when skipped
// is not null); x_base(p): the x index of its stencil's first node (called for particles in a tile only);
// body(p, row) as above.  scratch: n + (nthreads + 1) tiles + 1 ints, the particle order, each thread's count per
// tile and the tiles' starts (couplekit/backend/host_scatter.py sizes it).  The team
// may be smaller than nthreads.
template <int F, class TileOf, class XBase, class Body>
static inline void host_scatter(const long long n, const int nx, const int ny, const int nz, const int nthreads,
                                int* RESTRICT scratch, int* RESTRICT skipped, float* const grid[F], TileOf tile_of,
                                XBase x_base, Body body) {
    const int tiles_y = host_scatter_tiles_along(ny), tiles_z = host_scatter_tiles_along(nz);
    const long long tiles = (long long)tiles_y * tiles_z;
    const long long ncell = (long long)nx * ny * nz;
    int* RESTRICT order = scratch;
    int* RESTRICT counts = scratch + n;                          // counts[t * tiles + tile]
    int* RESTRICT start = counts + (long long)nthreads * tiles;  // start[tile], start[tiles] = placed particles
    CK_PRAGMA(omp parallel num_threads(nthreads)) {
        const int t = omp_get_thread_num();
        const int team = omp_get_num_threads();
        const long long lo = n * t / team, hi = n * (t + 1) / team;
        int* RESTRICT mine = counts + (long long)t * tiles;
        for (long long k = 0; k < tiles; ++k) mine[k] = 0;
        int left_out = 0;
        for (long long p = lo; p < hi; ++p) {
            const long long k = tile_of(p);
            if (k < 0)
                ++left_out;
            else
                ++mine[k];
        }
        if (skipped != nullptr && left_out > 0) atomic_add(skipped, left_out);
        CK_PRAGMA(omp for schedule(static))
        for (long long i = 0; i < ncell; ++i)
            for (int f = 0; f < F; ++f) grid[f][i] = 0.f;
        // implicit barrier: every thread's counts are in
        CK_PRAGMA(omp single) {
            int run = 0;
            for (long long k = 0; k < tiles; ++k) {
                start[k] = run;
                for (int u = 0; u < team; ++u) {
                    const int c = counts[(long long)u * tiles + k];
                    counts[(long long)u * tiles + k] = run;
                    run += c;
                }
            }
            start[tiles] = run;
        }
        // implicit barrier: every thread's offsets are set
        for (long long p = lo; p < hi; ++p) {
            const long long k = tile_of(p);
            if (k >= 0) order[mine[k]++] = (int)p;
        }
        const long long row_floats = (long long)F * nx;
        std::vector<float> own((size_t)(HOST_SCATTER_ROWS * HOST_SCATTER_ROWS * row_floats));
        float* RESTRICT buf = own.data();
        CK_PRAGMA(omp barrier)
        for (int colour = 0; colour < 4; ++colour) {
            const int cy = colour & 1, cz = colour >> 1;
            const int ty_n = (tiles_y - cy + 1) / 2, tz_n = (tiles_z - cz + 1) / 2;
            CK_PRAGMA(omp for schedule(dynamic, 1))
            for (long long j = 0; j < (long long)ty_n * tz_n; ++j) {
                const int ty = 2 * (int)(j % ty_n) + cy, tz = 2 * (int)(j / ty_n) + cz;
                const long long k = ty + (long long)tiles_y * tz;
                if (start[k] == start[k + 1]) continue;
                const int y0 = ty * HOST_SCATTER_TILE, z0 = tz * HOST_SCATTER_TILE;
                // the nodes [x_lo, x_hi) along x that the tile's particles reach: the buffer is cleared and added
                // there only (a short column in a wide grid would otherwise pay for whole rows)
                int x_lo = nx, x_hi = 0;
                for (int q = start[k]; q < start[k + 1]; ++q) {
                    const int bx = x_base(order[q]);
                    x_lo = bx < x_lo ? bx : x_lo;
                    x_hi = bx + 3 > x_hi ? bx + 3 : x_hi;
                }
                for (int r = 0; r < HOST_SCATTER_ROWS * HOST_SCATTER_ROWS; ++r)
                    for (long long i = (long long)F * x_lo; i < (long long)F * x_hi; ++i) buf[row_floats * r + i] = 0.f;
                for (int q = start[k]; q < start[k + 1]; ++q) {
                    const long long p = order[q];
                    body(p, [=](const int z, const int y) -> float* {
                        return buf + row_floats * ((long long)HOST_SCATTER_ROWS * (z - z0) + (y - y0));
                    });
                }
                // the node rows the tile reaches, clipped to the grid (a particle's stencil stays inside it)
                for (int c = 0; c < HOST_SCATTER_ROWS && z0 + c < nz; ++c)
                    for (int b = 0; b < HOST_SCATTER_ROWS && y0 + b < ny; ++b) {
                        const float* RESTRICT src = buf + row_floats * ((long long)HOST_SCATTER_ROWS * c + b);
                        const long long row = (long long)nx * ((y0 + b) + (long long)ny * (z0 + c));
                        for (int f = 0; f < F; ++f) {
                            float* RESTRICT dst = grid[f] + row;
                            for (int x = x_lo; x < x_hi; ++x) dst[x] += src[(long long)F * x + f];
                        }
                    }
            }
            // implicit barrier: the next colour's tiles touch this colour's nodes
        }
    }
}

#endif
