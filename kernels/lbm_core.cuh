// Shared pieces of the LBM flow kernels: padded-grid indexing, cell flags, the AA-pattern load/store rules
// with their boundary rules, the isotropic stencils.  Mirrors couplekit/fluid/reference.py (the spec).
//
// Shifted storage: the arrays hold f_j - w_j, not f_j (w_j the D3Q27 weight; as lbmpy's and FluidX3D's
// "delta" populations).  At low viscosity and low speed the non-equilibrium part of f that carries the viscous
// stress is ~1e-7 of w_j, below float32 round-off of f itself (docs/precision.md).  Streaming, bounce-back
// (w_opp j = w_j), halo copies and sum f c are the same for f - w; the collision works on the deviations
// (lbm_collide.cu) and the pressure update takes 1 - sum f = -sum (f - w).
// Storage type: ck_store_t (common.cuh, CK_STORAGE_FP16): float32, or binary16 holding (f - w) * CK_F_SCALE;
// every access goes through CK_LOAD / CK_STORE, the arithmetic is float32 either way.
//
// Grid: every field has one ghost layer: interior nx*ny*nz, padded Px = nx+2, Py = ny+2, Pz = nz+2, linear
// padded index x + Px*(y + Py*z).  Distributions are SoA: slot j of cell c is f[j*N + c], N = Px*Py*Pz.
//
// AA pattern (one copy of f).  Even parity: f_j = F[j][c]; store F[opp j][c] = f*_j (local).
// Odd parity: f_j = F[opp j][c - c_j] (pull), store F[j][c + c_j] = f*_j (push).  Boundary rules, odd only:
//   neighbour c - c_j is WALL/INFLOW: f_j = F[j][c] + 6 w_j c_j.u_w  (u_w = velocity stored at the wall cell)
//   push to WALL/INFLOW c + c_j:      F[opp j][c] = f*_j - 6 w_j c_j.u_w
// The kernels implement them with a link list (lbm_halo.cu): before the odd step lbm_wall_prefill parks the
// bounced value in the wall cell's slot the pull reads, after it lbm_wall_bounce moves the value pushed into
// the wall cell back; so the bulk loops carry no per-link flag test.
// OUTFLOW ghosts are read and pushed to like fluid cells: lbm_halo_copy fills them from their nearest interior
// cell before an odd step (zero-gradient f*), lbm_outflow_fix sets what they would have pushed after it.
#pragma once
#include "common.cuh"
#include "lattice.cuh"

#define FLAG_FLUID 0
#define FLAG_WALL 1
#define FLAG_INFLOW 2
#define FLAG_OUTFLOW 3

// helpers are force-inlined on the host too: an out-of-line call inside the `omp simd` x loop stops the
// vectoriser ("statement clobbers memory")
#if defined(__CUDACC__)
#define LBM_INLINE __device__ __forceinline__
#else
#define LBM_INLINE static inline __attribute__((always_inline))
#endif

// clamp to [0, 1] (NaN passes through, as with the selects it replaces)
LBM_INLINE float lbm_clamp01(const float v) {
    return ck_select((unsigned int)(v < 0.f), 0.f, ck_select((unsigned int)(v > 1.f), 1.f, v));
}

// a neighbour whose scalar values enter the stencils: fluid, or an outflow ghost;
// for f: cells that are pulled from / pushed to (outflow ghosts are refilled by lbm_halo_copy / lbm_outflow_fix) (which holds the outlet's
// reference value, e.g. p = 0: a pressure Dirichlet condition half a link beyond the last cell)
#define LBM_STENCIL_CELL(fl) ((fl) == FLAG_FLUID || (fl) == FLAG_OUTFLOW)

// straight-line repetition (no loops left for the host vectoriser, whose x loop must contain no inner loop)
#define LBM_REP9(M, b) M(b + 0) M(b + 1) M(b + 2) M(b + 3) M(b + 4) M(b + 5) M(b + 6) M(b + 7) M(b + 8)
#define LBM_FOR27(M) LBM_REP9(M, 0) LBM_REP9(M, 9) LBM_REP9(M, 18)
#define LBM_FOR26(M)                                                                                    \
    M(1) M(2) M(3) M(4) M(5) M(6) M(7) M(8) LBM_REP9(M, 9) LBM_REP9(M, 18)

// neighbour offset of direction q in a padded grid with row length px and plane size pxy
#define LBM_OFFSET(q, px, pxy) ((long long)CX27[q] + (long long)(px) * CY27[q] + (long long)(pxy) * CZ27[q])

// index in f of population q of padded cell c under the read rule of the parity (ODD = parity & 1, a
// compile-time constant): F[q][c] even, F[opp q][c - c_q] odd
#define LBM_PULL_INDEX(ODD, q, c, N, px, pxy) \
    ((ODD) ? opposite_dir(q) * (N) + (c) - LBM_OFFSET(q, px, pxy) : (q) * (N) + (c))

// populations f_j(x, t) of padded cell c under the read rule of the parity (ODD = parity & 1).  The odd pull
// reads every neighbour alike: wall links were prepared by lbm_wall_prefill, outflow / periodic ghosts by
// lbm_halo_copy, so the host loop has contiguous loads only and vectorises.
// SCALAR = 1: for a loop the host does not vectorise (CK_LOAD_SCALAR, common.cuh); the same values
template <int ODD, int SCALAR = 0>
LBM_INLINE void lbm_load(const ck_store_t* RESTRICT f, const long long c, const long long N, const int px,
                         const long long pxy, float* RESTRICT fj) {
#define LBM_LD(p, i) (SCALAR ? CK_LOAD_SCALAR(p, i, CK_F_SCALE) : CK_LOAD(p, i, CK_F_SCALE))
#define LBM_LOAD(q) fj[q] = LBM_LD(f, LBM_PULL_INDEX(ODD, q, c, N, px, pxy));
    LBM_FOR27(LBM_LOAD)
#undef LBM_LOAD
#undef LBM_LD
}

// the same, without taking the storage scale out: fj = stored values (f - w) * CK_F_SCALE (fp32: f - w); the
// collision applies 1 / CK_F_SCALE to the 10 raw moments instead of to the 27 populations (fewer live values on
// the GPU: with the scale taken out at each load the fp16 single-phase variants spilled 12 B on sm_90)
template <int ODD>
LBM_INLINE void lbm_load_scaled(const ck_store_t* RESTRICT f, const long long c, const long long N, const int px,
                                const long long pxy, float* RESTRICT fj) {
#define LBM_LOAD(q) fj[q] = CK_LOAD(f, LBM_PULL_INDEX(ODD, q, c, N, px, pxy), 1.f);
    LBM_FOR27(LBM_LOAD)
#undef LBM_LOAD
}

// write post-collision populations of padded cell c under the write rule of the parity (ODD = parity & 1);
// pushes into wall cells are turned into bounce-back by lbm_wall_bounce, into ghosts by lbm_fold /
// lbm_outflow_fix
template <int ODD>
LBM_INLINE void lbm_store(ck_store_t* RESTRICT f, const long long c, const long long N, const int px,
                          const long long pxy, const float* RESTRICT fs) {
#define LBM_STORE(q)                                                      \
    if (ODD)                                                              \
        CK_STORE(f, (q) * N + c + LBM_OFFSET(q, px, pxy), fs[q], CK_F_SCALE); \
    else                                                                  \
        CK_STORE(f, opposite_dir(q) * N + c, fs[q], CK_F_SCALE);
    LBM_FOR27(LBM_STORE)
#undef LBM_STORE
}

// Eq. 18 isotropic gradient, g = 3 sum_j w_j c_j d_j with d_j = s(x + c_j) - s(x).  A wall / inflow / solid
// neighbour x + c_j takes, with EXTRAP = 0, the centre value (d_j = 0: zero normal gradient: phi, eps, v) and,
// with EXTRAP = 1, the linear extrapolation 2 s(x) - s(x - c_j) when x - c_j is a stencil cell (pressure:
// exact for the hydrostatic profile, whose wall-normal gradient is rho g, not 0), else the centre value.
// MODE says how the kind of neighbour x + c_j is known: LBM_NB_FLAGS reads its flag; LBM_NB_MASK takes bit j of
// `mask` (lbm_link_mask: stencil neighbour) and bit opp(j) for x - c_j, so the host x loop reads no byte data
// (which would make g++ choose 64 lanes, four zmm registers per float value); LBM_NB_BULK: the caller
// guarantees every neighbour is a stencil cell.  All three do the same arithmetic on the same cell.
// The sum is factorised by weight class: g_x = 2/9 (d_{+x} - d_{-x}) + 1/18 (4 edge differences) + 1/72 (4
// corner differences), and alike for y, z (3 w = 2/9, 1/18, 1/72): 60 flops instead of 26 multiply-adds per
// component; in the bulk the centre value cancels from the differences, so d_j = s(x + c_j) there (the
// results differ from the other modes by float32 round-off only).
#define LBM_NB_FLAGS 0
#define LBM_NB_BULK 1
#define LBM_NB_MASK 2
#define LBM_C3(x, y, z) (((x) + 1) * 9 + ((y) + 1) * 3 + ((z) + 1))
#if !CK_ON_GPU
// Host: the three components of lbm_gradient (the host form below) as a value.  A vector loop that keeps the result
// (lbm_phi_stencil_chunk) needs it so: g++ kept a local output array in memory there ("not suitable for scatter
// store").
struct LbmVec3 {
    float x, y, z;
};
template <int EXTRAP, int MODE>
static inline __attribute__((always_inline)) LbmVec3 lbm_gradient_host(const float* RESTRICT s,
                                                                       const unsigned char* RESTRICT flags,
                                                                       const long long c, const int px,
                                                                       const long long pxy, const unsigned int mask) {
    const float sc = s[c];
    // 0 / 1 as a 32-bit value (ck_select)
#define LBM_NB_STENCIL(q, cell)                                           \
    (MODE == LBM_NB_BULK ? 1u                                             \
                         : (MODE == LBM_NB_MASK ? ((mask >> (q)) & 1u)    \
                                                : (unsigned int)LBM_STENCIL_CELL(flags[cell])))
    // the 26 neighbour values, read whatever the neighbour's kind (every padded cell holds a value) and once
    // each: the extrapolation's s(x - c_j) is v[opp j].  With a second read of s(x - c_j) per link and float
    // selects g++ judged the masked collide x loop "not profitable" and left it scalar.
    float v[27];
#define LBM_GRAD_LD(q) v[q] = s[c + LBM_OFFSET(q, px, pxy)];
    LBM_FOR26(LBM_GRAD_LD)
#undef LBM_GRAD_LD
    float d[27];  // d_j by cube index (c_x + 1) * 9 + (c_y + 1) * 3 + (c_z + 1)
    d[13] = 0.f;
#define LBM_GRAD_LINK(q)                                                                                  \
    {                                                                                                    \
        const unsigned int snb = LBM_NB_STENCIL(q, c + LBM_OFFSET(q, px, pxy));                          \
        float dq = MODE == LBM_NB_BULK ? v[q] : ck_select(snb, v[q] - sc, 0.f);                         \
        if (EXTRAP && MODE != LBM_NB_BULK) {                                                             \
            const unsigned int smb = LBM_NB_STENCIL(opposite_dir(q), c - LBM_OFFSET(q, px, pxy));        \
            dq = ck_select((snb ^ 1u) & smb, sc - v[opposite_dir(q)], dq);                              \
        }                                                                                                \
        d[LBM_C3(CX27[q], CY27[q], CZ27[q])] = dq;                                                       \
    }
    LBM_FOR26(LBM_GRAD_LINK)
#undef LBM_GRAD_LINK
#undef LBM_NB_STENCIL
    // difference along x of the line (y, z) etc.
#define LBM_DX(b, cc) (d[LBM_C3(1, b, cc)] - d[LBM_C3(-1, b, cc)])
#define LBM_DY(a, cc) (d[LBM_C3(a, 1, cc)] - d[LBM_C3(a, -1, cc)])
#define LBM_DZ(a, b) (d[LBM_C3(a, b, 1)] - d[LBM_C3(a, b, -1)])
    LbmVec3 r;
    r.x = (2.f / 9.f) * LBM_DX(0, 0) +
           (1.f / 18.f) * ((LBM_DX(1, 0) + LBM_DX(-1, 0)) + (LBM_DX(0, 1) + LBM_DX(0, -1))) +
           (1.f / 72.f) * ((LBM_DX(1, 1) + LBM_DX(-1, -1)) + (LBM_DX(1, -1) + LBM_DX(-1, 1)));
    r.y = (2.f / 9.f) * LBM_DY(0, 0) +
           (1.f / 18.f) * ((LBM_DY(1, 0) + LBM_DY(-1, 0)) + (LBM_DY(0, 1) + LBM_DY(0, -1))) +
           (1.f / 72.f) * ((LBM_DY(1, 1) + LBM_DY(-1, -1)) + (LBM_DY(1, -1) + LBM_DY(-1, 1)));
    r.z = (2.f / 9.f) * LBM_DZ(0, 0) +
           (1.f / 18.f) * ((LBM_DZ(1, 0) + LBM_DZ(-1, 0)) + (LBM_DZ(0, 1) + LBM_DZ(0, -1))) +
           (1.f / 72.f) * ((LBM_DZ(1, 1) + LBM_DZ(-1, -1)) + (LBM_DZ(1, -1) + LBM_DZ(-1, 1)));
#undef LBM_DX
#undef LBM_DY
#undef LBM_DZ
    return r;
}
#endif

// LAP = 1 (GPU, EXTRAP = 0 only): g[3] also receives the isotropic Laplacian's sum sum_j w_j d_j (Eq. 23 without
// its factor 2 / cs^2 = 6) with the same rule and the same reads: the flow's collide takes the chemical potential
// of Eq. 22 from it, so no mu field is stored (host: lbm_laplacian_sum).
template <int EXTRAP, int MODE = LBM_NB_FLAGS, int LAP = 0>
LBM_INLINE void lbm_gradient(const float* RESTRICT s, const unsigned char* RESTRICT flags, const long long c,
                             const int px, const long long pxy, float* RESTRICT g, const unsigned int mask = 0u) {
#if CK_ON_GPU
    const float sc = s[c];
#define LBM_NB_STENCIL(q, cell) \
    (MODE == LBM_NB_BULK ? true : (MODE == LBM_NB_MASK ? ((mask >> (q)) & 1u) != 0u : LBM_STENCIL_CELL(flags[cell])))
#define LBM_NB_STENCIL_G(q, cell)                                                                           \
    (MODE == LBM_NB_BULK ? true                                                                            \
                         : (MODE == LBM_NB_MASK ? ((gmask >> (q)) & 1u) != 0u : LBM_STENCIL_CELL(flags[cell])))
    // GPU: the sum by opposite pairs (q, q + 1 = opp q, q odd), g += 3 w_q c_q (d_q - d_opp q), accumulated as
    // each pair is read: 2 loaded values live per pair instead of the 26 differences the host's factorised sum
    // keeps until the end (measured on sm_90 under 128 registers, everything else as now: with the factorised
    // sum the two-phase collide-stream variants spilled 28-288 bytes, with this one none).  Same terms, other
    // summation order: float32 round-off from the host build.
    // The geometry and the mask pass through CK_PER_ITEM: two gradients of one cell (and the populations'
    // loads) share their 26 neighbour offsets, which the compiler otherwise computes once and keeps live
    // (52 registers) from the first stencil to the last; recomputing them costs one multiply-add each.
    const int gpx = CK_PER_ITEM(px);
    const long long gpxy = CK_PER_ITEM(pxy);
    const unsigned int gmask = CK_PER_ITEM(mask);
    float g0 = 0.f, g1 = 0.f, g2 = 0.f, lap = 0.f;
#define LBM_GRAD_PAIR(q)                                                                                 \
    {                                                                                                    \
        const long long o = LBM_OFFSET(q, gpx, gpxy);                                                    \
        const bool sp = LBM_NB_STENCIL_G(q, c + o), sm = LBM_NB_STENCIL_G((q) + 1, c - o);               \
        const float vp = s[c + o], vm = s[c - o];                                                        \
        float dp = MODE == LBM_NB_BULK ? vp : (sp ? vp - sc : 0.f);                                      \
        float dm = MODE == LBM_NB_BULK ? vm : (sm ? vm - sc : 0.f);                                      \
        if (EXTRAP && MODE != LBM_NB_BULK) {                                                             \
            const float ep = (!sp && sm) ? sc - vm : dp, em = (!sm && sp) ? sc - vp : dm;                \
            dp = ep;                                                                                     \
            dm = em;                                                                                     \
        }                                                                                                \
        if (LAP) lap += W27[q] * (MODE == LBM_NB_BULK ? (vp - sc) + (vm - sc) : dp + dm);             \
        const float dd = (3.f * W27[q]) * (dp - dm);                                                     \
        if (CX27[q] != 0) g0 = CX27[q] > 0 ? g0 + dd : g0 - dd;                                          \
        if (CY27[q] != 0) g1 = CY27[q] > 0 ? g1 + dd : g1 - dd;                                          \
        if (CZ27[q] != 0) g2 = CZ27[q] > 0 ? g2 + dd : g2 - dd;                                          \
    }
    LBM_GRAD_PAIR(1) LBM_GRAD_PAIR(3) LBM_GRAD_PAIR(5) LBM_GRAD_PAIR(7) LBM_GRAD_PAIR(9) LBM_GRAD_PAIR(11)
    LBM_GRAD_PAIR(13) LBM_GRAD_PAIR(15) LBM_GRAD_PAIR(17) LBM_GRAD_PAIR(19) LBM_GRAD_PAIR(21) LBM_GRAD_PAIR(23)
    LBM_GRAD_PAIR(25)
#undef LBM_GRAD_PAIR
#undef LBM_NB_STENCIL_G
#undef LBM_NB_STENCIL
    g[0] = g0;
    g[1] = g1;
    g[2] = g2;
    if (LAP) g[3] = lap;
#else
    static_assert(!LAP, "host: the Laplacian's sum is lbm_laplacian_sum, in a loop of its own");
    const LbmVec3 r = lbm_gradient_host<EXTRAP, MODE>(s, flags, c, px, pxy, mask);
    g[0] = r.x;
    g[1] = r.y;
    g[2] = r.z;
#endif
}

#if !CK_ON_GPU
// Host: the Laplacian's sum of lbm_gradient's LAP (sum_j w_j d_j, the EXTRAP = 0 rule, MODE and `mask` as there)
// as a value, for a vector loop of its own (lbm_phi_stencil_chunk): g++ kept lbm_gradient's output array in
// memory inside such a loop ("not suitable for scatter store").
template <int MODE>
static inline __attribute__((always_inline)) float lbm_laplacian_sum(const float* RESTRICT s,
                                                                     const unsigned char* RESTRICT flags,
                                                                     const long long c, const int px,
                                                                     const long long pxy, const unsigned int mask) {
    const float sc = s[c];
    float sum = 0.f;
#define LBM_LAP_LINK(q)                                                                                  \
    {                                                                                                    \
        const long long cq = c + LBM_OFFSET(q, px, pxy);                                                 \
        const unsigned int snb = MODE == LBM_NB_BULK                                                     \
                                     ? 1u                                                                \
                                     : (MODE == LBM_NB_MASK ? ((mask >> (q)) & 1u)                       \
                                                            : (unsigned int)LBM_STENCIL_CELL(flags[cq])); \
        sum += W27[q] * ck_select(snb, s[cq] - sc, 0.f);                                                 \
    }
    LBM_FOR26(LBM_LAP_LINK)
#undef LBM_LAP_LINK
    return sum;
}
#endif

// Link mask of a padded cell c for LBM_NB_MASK: bit 0 = c is FLUID (updated), bit j (1..26) = x + c_j is a
// stencil cell.  LBM_FULL_MASK: a fluid cell whose every neighbour is a stencil cell.
#define LBM_FULL_MASK 0x7ffffffu

// Link mask of one padded cell c (bit 0: c is FLUID, bit j: x + c_j is a stencil cell), from 27 flag reads.
// The GPU loops take the stencils' neighbour kinds from it (LBM_NB_MASK): one 32-bit register instead of the
// 26 (or 52, with the extrapolation) flag reads of every gradient, the same arithmetic as LBM_NB_FLAGS.
LBM_INLINE unsigned int lbm_link_mask(const unsigned char* RESTRICT flags, const long long c, const int px,
                                      const long long pxy) {
    unsigned int m = flags[c] == FLAG_FLUID ? 1u : 0u;
#define LBM_MASK_LINK(q) m |= (LBM_STENCIL_CELL(flags[c + LBM_OFFSET(q, px, pxy)]) ? 1u : 0u) << (q);
    LBM_FOR26(LBM_MASK_LINK)
#undef LBM_MASK_LINK
    return m;
}

#if !CK_ON_GPU
// Host: true when the cells xa..xb of padded row `row` (index of x = 0) and of its 8 neighbour rows
// (y +- 1, z +- 1) are all FLUID.  With xa = 0, xb = nx + 1 (ghosts included) every interior cell of the row
// is a fluid cell whose neighbours are all fluid (LBM_NB_BULK applies).  9 (xb - xa + 1) byte reads.
LBM_INLINE bool lbm_rows_all_fluid(const unsigned char* RESTRICT flags, const long long row, const int xa,
                                   const int xb, const int px, const long long pxy) {
    uint64_t any = 0;
    for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
            any |= ck_or_bytes(flags + row + (long long)dy * px + (long long)dz * pxy + xa, xb - xa + 1);
    return any == 0;  // FLAG_FLUID == 0
}

// Host: whether the 9 padded rows around `row` (x in 0 .. nx + 1) hold no sand: fluid fraction exactly 1 and sand
// velocity exactly 0 in every cell.  There every stencil of the mixture's terms over such cells (grad eps, div v)
// is exactly 0 (lbm_gradient sums differences of equal values), so the mixture terms they feed add exactly 0:
// a row can take the stage's single-fluid arithmetic and give bitwise the same result.
#if !CK_ON_GPU
LBM_INLINE bool lbm_rows_sand_free(const float* RESTRICT eps, const float* RESTRICT sand_v, const long long row,
                                   const int nx, const int px, const long long pxy, const long long N) {
    // per field and row an 8-lane scan of the bit patterns (ck_any_differs): eps exactly 1, sand_v exactly +-0
    unsigned int any = 0;
    for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy) {
            const long long r = row + (long long)dy * px + (long long)dz * pxy;
            any |= ck_any_differs(eps + r, nx + 2, 1.f) | ck_any_differs(sand_v + r, nx + 2, 0.f) |
                   ck_any_differs(sand_v + N + r, nx + 2, 0.f) | ck_any_differs(sand_v + 2 * N + r, nx + 2, 0.f);
        }
    return any == 0;
}
#endif

// Host: the first (lo) and last (hi) interior x (1..nx) of padded row `row` whose cell is FLUID; lo > hi when
// the row has none.  The stages' masked rows loop over lo..hi only: every stage leaves a non-fluid cell as it is
// (the GPU path skips it; the host's GUARD writes its values back), so the cells outside the span need no
// work, and obstacles (Fig. 13's beaker: a third of its cells) and walls cost nothing there.
LBM_INLINE void lbm_row_fluid_span(const unsigned char* RESTRICT flags, const long long row, const int nx, int& lo,
                                   int& hi) {
    const unsigned char* r = flags + row;
    lo = 1;
    while (lo <= nx && r[lo] != FLAG_FLUID) ++lo;
    hi = nx;
    while (hi >= lo && r[hi] != FLAG_FLUID) --hi;
}

// Host: true when the cells xa..xb of padded row `row` (index of x = 0) are all FLUID (xb - xa + 1 byte reads)
LBM_INLINE bool lbm_row_fluid(const unsigned char* RESTRICT flags, const long long row, const int xa, const int xb) {
    return ck_or_bytes(flags + row + xa, xb - xa + 1) == 0;  // FLAG_FLUID == 0
}

// Host: the vector tail of a row's x loop.  An `omp simd` loop runs its last (len mod vector width) iterations
// in a scalar epilogue, which costs about as much per cell as a whole vector: a 31-cell row of the collide ran
// at half the speed of a 32-cell row (11.4 against 23.1 MLUPS per thread, walled box).  So a row's loops run
// the cells lo .. hi - rem in whole vectors, and the last rem cells as one more vector of LBM_VEC cells that
// ends at hi: its first LBM_VEC - rem lanes are cells the loop has already done (or non-fluid cells of the
// row), which it runs again as non-fluid (GUARD = 1, bit 0 of the mask cleared: each keeps the values it has).
// Spans of fewer than LBM_VEC cells get rem = 0 (their scalar loop as before); a longer span starts at lo >= 1,
// so its last vector lies inside the row.  The loops' chunk lengths are multiples of LBM_VEC.
#define LBM_VEC 16
LBM_INLINE int lbm_row_tail(const int lo, const int hi) {
    const int span = hi + 1 - lo;
    return span >= LBM_VEC ? span % LBM_VEC : 0;
}

// The next chunk of a row loop `for (int x0 = lo; x0 <= hi;)` with rem = lbm_row_tail(lo, hi): up to `chunk`
// cells while x0 <= hi - rem, then the tail, one vector of LBM_VEC cells ending at hi.  Sets len and c0 (the
// padded index of the chunk's first cell, `row` + its x), moves x0 on (past hi after the tail) and returns
// whether this chunk is the tail (whose first LBM_VEC - rem lanes the caller keeps).  One place for the chunk
// arithmetic of the collide, pressure, filter and phase-field row loops.
LBM_INLINE int lbm_row_chunk(int& x0, const int hi, const int rem, const int chunk, const long long row, int& len,
                             long long& c0) {
    const int tail = x0 > hi - rem;
    len = tail ? LBM_VEC : (hi - rem + 1 - x0 < chunk ? hi - rem + 1 - x0 : chunk);
    c0 = row + (tail ? hi - (LBM_VEC - 1) : x0);
    x0 = tail ? hi + 1 : x0 + len;
    return tail;
}

// Host: link masks of the `len` cells starting at padded index c0.  The flags of the 9 rows around them are
// first widened to one 32-bit word per cell in `scratch` (size >= 10 (len + 2)), so the mask loop itself
// reads no byte data and vectorises with 16 lanes (built straight from the flags g++ left it scalar: 26
// byte loads per cell cost as much as the whole collision).
LBM_INLINE void lbm_link_masks(const unsigned char* RESTRICT flags, const long long c0, const int len, const int px,
                               const long long pxy, unsigned int* RESTRICT masks, unsigned int* RESTRICT scratch) {
    const int w = len + 2;
    for (int r = 0; r < 9; ++r) {  // r = (c_y + 1) * 3 + (c_z + 1)
        const unsigned char* fr = flags + c0 - 1 + (long long)(r / 3 - 1) * px + (long long)(r % 3 - 1) * pxy;
        unsigned int* sr = scratch + r * w;
        CK_SIMD_SHORT
        for (int i = 0; i < w; ++i) sr[i] = LBM_STENCIL_CELL(fr[i]) ? 1u : 0u;
    }
    unsigned int* fluid = scratch + 9 * w;
    CK_SIMD_SHORT
    for (int i = 0; i < len; ++i) fluid[i] = flags[c0 + i] == FLAG_FLUID ? 1u : 0u;
    CK_PRAGMA(omp simd)
    for (int i = 0; i < len; ++i) {
        unsigned int m = fluid[i];
#define LBM_MASK_BIT(q) m |= scratch[((CY27[q] + 1) * 3 + (CZ27[q] + 1)) * w + i + 1 + CX27[q]] << (q);
        LBM_FOR26(LBM_MASK_BIT)
#undef LBM_MASK_BIT
        masks[i] = m;
    }
}

// Host: the link masks of the tail vector (lbm_row_tail): the LBM_VEC cells from c0, of which the last `rem`
// are new; the others are marked non-fluid (bit 0 cleared), so a GUARD loop keeps what they hold.
LBM_INLINE void lbm_tail_masks(const unsigned char* RESTRICT flags, const long long c0, const int rem, const int px,
                               const long long pxy, unsigned int* RESTRICT masks, unsigned int* RESTRICT scratch) {
    lbm_link_masks(flags, c0, LBM_VEC, px, pxy, masks, scratch);
    for (int i = 0; i < LBM_VEC - rem; ++i) masks[i] &= ~1u;
}
#endif
