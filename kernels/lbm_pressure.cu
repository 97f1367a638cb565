// Mixture pressure evolution (paper Eqs. 37-39) and the 27-point local-average filter (Eq. 40).
// Spec: couplekit/fluid/reference.py ReferenceOps.macro_pressure / pressure_filter.
// Defines: CK_TWO_PHASE (rho from phi, else rho = rho_h), CK_MIXTURE (fluid fraction eps and sand velocity
// inputs; else eps = 1 and the sand terms vanish).
// variants: CK_TWO_PHASE=0,1 CK_MIXTURE=0,1 CK_STORAGE_FP16=0,1
// f is ck_store_t (common.cuh, CK_STORAGE_FP16), read through lbm_load.
#include "common.cuh"
#include "lattice.cuh"
#include "lbm_core.cuh"
#include "lbm_sand_terms.cuh"

#ifndef CK_TWO_PHASE
#define CK_TWO_PHASE 0
#endif
#ifndef CK_MIXTURE
#define CK_MIXTURE 0
#endif

// host rows are processed in chunks of this many cells (their link masks live on the stack)
#define LBM_P_CHUNK 512

// p <- p - cs2 rho [(1 - sum f) + (eps_s div v + (u - v).grad eps) / eps]   (Eq. 39, 1 - sum f ~ div u, Eq. 38;
// the sand terms: lbm_pressure_sand_terms).  One fluid cell c: ODD = parity & 1, MODE: how the four stencils learn the
// kind of a neighbour (lbm_gradient; `mask` = lbm_link_mask of c for LBM_NB_MASK), SCALAR: lbm_load's,
// `slip_on`: slip_cells[c] != 0 (on the host taken from a widened copy: no byte read in the x loop).
// GPU = 1 (the GPU loop): ODD is the runtime `odd` (a branch around the loads only), and the link mask and the
// slip flag are read here, where the stencils need them, not passed in: computed before the loads, they stayed
// live through them and the fp16 mixture variants spilled 4-8 B on sm_80 / sm_90 (measured).
// GUARD = 1 (host wall rows): every cell of the chunk goes through the arithmetic; p is written only where bit 0
// of the mask says FLUID, elsewhere its value is kept (a blend, no branch: lbm_collide_stream's scheme).
// FSUM = 1: s0 = Σ_j (f_j - w_j) is read from `fsum` (lbm_momentum wrote it from the same populations, in the
// same order, so bitwise the same value) instead of summed from the 27 loads: the coupled step's pressure update
// does not read f again (FluidSolver.current_velocity, keep_fsum).
// MIX = 0 in a CK_MIXTURE build: a host row without sand around it (lbm_rows_sand_free), whose mixture terms are
// exactly 0, or a step whose sand terms coupling_pressure_sand_terms already took out of `fsum` (fsum = s0 - terms,
// and 0 - (s0 - terms) is the (0 - s0) + terms computed here otherwise, bitwise: IEEE rounding is sign-symmetric);
// the single-fluid arithmetic, bitwise the same result.
template <int ODD, int MODE, int SCALAR, int GPU = 0, int GUARD = 0, int FSUM = 0, int MIX = CK_MIXTURE>
LBM_INLINE void lbm_pressure_cell(const long long c, const ck_store_t* RESTRICT f, const unsigned char* RESTRICT flags,
                                  const float* RESTRICT vel, const float* RESTRICT phi, const float* RESTRICT eps,
                                  const float* RESTRICT sand_v, const float* RESTRICT fsum, float* RESTRICT p,
                                  const int px, const long long pxy, const long long N, const float rho_h,
                                  const float rho_l, unsigned int mask, unsigned int slip_on, const int odd = 0,
                                  const unsigned char* RESTRICT slip_cells = nullptr) {
    float s0 = 0.f;
    if (FSUM) {
        s0 = fsum[c];
        (void)f, (void)odd;
    } else {
        float fj[27];
        if (GPU ? odd != 0 : ODD != 0)
            lbm_load<1, SCALAR>(f, c, N, px, pxy, fj);
        else
            lbm_load<0, SCALAR>(f, c, N, px, pxy, fj);
#define LBM_SUM(q) s0 += fj[q];
        LBM_FOR27(LBM_SUM)
#undef LBM_SUM
    }
    // 1 - sum f = -sum (f - w): the stored populations are f - w (lbm_core.cuh), sum w = 1.  Written
    // `0.f - s0`: with `-s0` (or a negative accumulation) ptxas spilled 8 B on sm_80 in the two-phase
    // mixture variant; this form builds with the registers of the former `1.f - s0` (124 / 128)
    float divergence = 0.f - s0;
#if CK_MIXTURE
    if (MIX) {
        divergence += lbm_pressure_sand_terms<MODE, CK_TWO_PHASE, GPU>(c, flags, vel, phi, eps, px, pxy, N, sand_v, c,
                                                                       px, pxy, N, mask, slip_on, slip_cells);
    } else {
        (void)vel, (void)eps, (void)sand_v, (void)slip_on, (void)slip_cells;
    }
#else
    (void)vel, (void)eps, (void)sand_v, (void)mask, (void)slip_on, (void)slip_cells;
#endif
#if CK_TWO_PHASE
    const float ph = lbm_clamp01(phi[c]);
    const float rho = rho_l + (rho_h - rho_l) * ph;
#else
    (void)phi, (void)rho_l;
    const float rho = rho_h;
#endif
    const float pc = p[c], pn = pc - CS2 * rho * divergence;
    p[c] = GUARD ? ck_select(mask & 1u, pn, pc) : pn;
}

// use_fsum != 0: s0 from `fsum` (padded, Σ_j (f_j - w_j) of these populations, lbm_momentum), f not read;
// use_fsum = 2 (CK_MIXTURE): `fsum` holds Σ_j (f_j - w_j) minus the sand terms (coupling_pressure_sand_terms), so
// the update adds none of its own and sand_v, slip_cells (and on the host eps) are not read.
// skip_sand_free != 0 (host, CK_MIXTURE): rows without sand around them skip the mixture's four stencils
// (lbm_rows_sand_free; bitwise the same p).  The GPU ignores it.
KERNEL void lbm_macro_pressure(const long long n, const ck_store_t* RESTRICT f /* size: 27 * (nx + 2) * (ny + 2) * (nz + 2) */,
                               const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                               const float* RESTRICT vel /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
                               const float* RESTRICT phi, const float* RESTRICT eps, const float* RESTRICT sand_v,
                               const unsigned char* RESTRICT slip_cells, const float* RESTRICT fsum,
                               float* RESTRICT p /* size: (nx + 2) * (ny + 2) * (nz + 2) */, const int parity,
                               const int use_fsum, const int skip_sand_free, const int nx, const int ny,
                               const int nz, const float rho_h, const float rho_l) {
#define LBM_P_ARGS(px, pxy, N) f, flags, vel, phi, eps, sand_v, fsum, p, px, pxy, N, rho_h, rho_l
#if CK_ON_GPU
    const int odd = parity & 1;
    (void)skip_sand_free;
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        // the grid sizes through CK_PER_ITEM (common.cuh): on the GPU the 27 load offsets and the 4 gradients'
        // 26 neighbour offsets derived from them are recomputed where used, not hoisted out of the loop or
        // shared between the stencils (189 registers before; the build report has the count now)
        const int px = CK_PER_ITEM(nx + 2);
        const long long pxy = (long long)px * (ny + 2);
        const long long N = pxy * (nz + 2);
        const long long c = (x + 1) + px * (long long)(y + 1) + pxy * (z + 1);
        if (flags[c] != FLAG_FLUID) continue;
#if CK_MIXTURE
        if (use_fsum == 2)
            lbm_pressure_cell<0, LBM_NB_MASK, 1, 1, 0, 1, 0>(c, LBM_P_ARGS(px, pxy, N), 0u, false, odd, slip_cells);
        else
#endif
        if (use_fsum)
            lbm_pressure_cell<0, LBM_NB_MASK, 1, 1, 0, 1>(c, LBM_P_ARGS(px, pxy, N), 0u, false, odd, slip_cells);
        else
            lbm_pressure_cell<0, LBM_NB_MASK, 1, 1>(c, LBM_P_ARGS(px, pxy, N), 0u, false, odd, slip_cells);
    }
#else
    // host: the row scheme of lbm_collide_stream.  A row whose cells are all fluid (with the mixture's stencils:
    // whose 9-row neighbourhood is) takes a flag-free `omp simd` x loop (LBM_NB_BULK), other rows a loop over
    // 32-bit link masks (lbm_link_masks, LBM_NB_MASK); the slip cells are widened to 32 bits first.  A byte
    // read inside the x loop makes g++ choose byte-wide vectors (4 registers per float value) and the loop
    // ran scalar before (the odd loads through CK_LOAD_SCALAR).  The parity is a template argument of each
    // loop.  Same arithmetic per cell in every path as on the GPU, except the bulk stencils' round-off.
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
    const long long N = pxy * (nz + 2);
#if CK_MIXTURE
#define LBM_P_ROWS(row) lbm_rows_all_fluid(flags, row, 0, nx + 1, px, pxy)
#define LBM_P_SLIP(i) slipw[i]
#define LBM_P_MIX(row) (use_fsum != 2 && (!skip_sand_free || !lbm_rows_sand_free(eps, sand_v, row, nx, px, pxy, N)))
#else
#define LBM_P_ROWS(row) lbm_row_fluid(flags, row, 1, nx)
#define LBM_P_SLIP(i) 0u
#define LBM_P_MIX(row) false
#endif
// the chunks of one row, MIX: the mixture's terms (1) or a sand-free row's (0, lbm_pressure_cell)
#define LBM_P_CHUNKS(ODD, FSUM, MIX)                                                                      \
    for (int x0 = lo; x0 <= hi;) {                                                                        \
        int len;                                                                                          \
        long long c0;                                                                                     \
        const int tail = lbm_row_chunk(x0, hi, rem, LBM_P_CHUNK, row, len, c0);                           \
        if (MIX) {                                                                                        \
            CK_SIMD_SHORT                                                                                 \
            for (int i = 0; i < len; ++i) slipw[i] = slip_cells[c0 + i] != 0 ? 1u : 0u;                   \
        }                                                                                                 \
        if (bulk && !tail) {                                                                              \
            CK_PRAGMA(omp simd)                                                                           \
            for (int i = 0; i < len; ++i)                                                                 \
                lbm_pressure_cell<ODD, LBM_NB_BULK, 0, 0, 0, FSUM, MIX>(c0 + i, LBM_P_ARGS(px, pxy, N),       \
                                                                        LBM_FULL_MASK, LBM_P_SLIP(i));    \
            continue;                                                                                     \
        }                                                                                                 \
        if (tail)                                                                                         \
            lbm_tail_masks(flags, c0, rem, px, pxy, masks, scratch);                                      \
        else                                                                                              \
            lbm_link_masks(flags, c0, len, px, pxy, masks, scratch);                                      \
        CK_PRAGMA(omp simd)                                                                               \
        for (int i = 0; i < len; ++i)                                                                     \
            lbm_pressure_cell<ODD, LBM_NB_MASK, 0, 0, 1, FSUM, MIX>(c0 + i, LBM_P_ARGS(px, pxy, N), masks[i], \
                                                                    LBM_P_SLIP(i));                       \
    }
#define LBM_P_LOOP(ODD, FSUM)                                                                             \
    CK_PRAGMA(omp parallel for collapse(2) schedule(static))                                              \
    for (int z = 0; z < nz; ++z)                                                                          \
        for (int y = 0; y < ny; ++y) {                                                                    \
            const long long row = px * (long long)(y + 1) + pxy * (z + 1);                                \
            const bool bulk = LBM_P_ROWS(row);                                                            \
            unsigned int masks[LBM_P_CHUNK], scratch[10 * (LBM_P_CHUNK + 2)], slipw[LBM_P_CHUNK];         \
            (void)slipw;                                                                                  \
            int lo = 1, hi = nx;                                                                          \
            if (!bulk) lbm_row_fluid_span(flags, row, nx, lo, hi);                                        \
            const int rem = lbm_row_tail(lo, hi);                                                         \
            if (LBM_P_MIX(row)) {                                                                         \
                LBM_P_CHUNKS(ODD, FSUM, CK_MIXTURE)                                                       \
            } else {                                                                                      \
                LBM_P_CHUNKS(ODD, FSUM, 0)                                                                \
            }                                                                                             \
        }
    if (use_fsum) {
        if (parity & 1) {
            LBM_P_LOOP(1, 1)
        } else {
            LBM_P_LOOP(0, 1)
        }
    } else if (parity & 1) {
        LBM_P_LOOP(1, 0)
    } else {
        LBM_P_LOOP(0, 0)
    }
#undef LBM_P_LOOP
#undef LBM_P_CHUNKS
#undef LBM_P_ROWS
#undef LBM_P_SLIP
#undef LBM_P_MIX
#endif
#undef LBM_P_ARGS
}

// pbar = sum_j w_j p(x + c_j)   (Eq. 40); a wall / inflow / solid neighbour contributes the linear
// extrapolation 2 p(x) - p(x - c_j) (the centre value if x - c_j is not a stencil cell either).  MODE as in
// lbm_gradient: LBM_NB_FLAGS reads the neighbours' flags, LBM_NB_MASK takes them from `mask`, LBM_NB_BULK (all
// stencil cells) skips the tests; the same terms in the same order in all three (bitwise equal results).
// GUARD = 1 (host wall rows): pbar written only where bit 0 of the mask says FLUID (lbm_pressure_cell's).
// The neighbour values are read once each whatever their kind (p(x - c_j) is v[opp j]) and the selects are
// 32-bit blends (ck_select): with bool conditions and second reads g++ left the masked x loop scalar.
template <int MODE, int GUARD = 0>
LBM_INLINE void lbm_filter_cell(const long long c, const float* RESTRICT p, const unsigned char* RESTRICT flags,
                                float* RESTRICT pbar, const int px, const long long pxy, const unsigned int mask) {
#define LBM_F_STENCIL(q, cell) \
    (MODE == LBM_NB_BULK ? 1u : (MODE == LBM_NB_MASK ? ((mask >> (q)) & 1u) : (unsigned int)LBM_STENCIL_CELL(flags[cell])))
    const float pc = p[c];
    float acc = 0.f;
#if CK_ON_GPU
    // the GPU reads at the link and only where the value is used (with the host's form below, every value
    // read up front and blended: 56 -> 116 registers)
#define LBM_AVG(q)                                                                               \
    {                                                                                           \
        const long long nb = c + LBM_OFFSET(q, px, pxy), mb = c - LBM_OFFSET(q, px, pxy);       \
        const bool snb = LBM_F_STENCIL(q, nb);                                                  \
        float d = snb ? p[nb] - pc : 0.f;                                                       \
        if (MODE != LBM_NB_BULK) d = (!snb && LBM_F_STENCIL(opposite_dir(q), mb)) ? pc - p[mb] : d; \
        acc += W27[q] * d;                                                                      \
    }
#else
    float v[27];
#define LBM_F_LD(q) v[q] = p[c + LBM_OFFSET(q, px, pxy)];
    LBM_FOR26(LBM_F_LD)
#undef LBM_F_LD
#define LBM_AVG(q)                                                                               \
    {                                                                                           \
        const unsigned int snb = LBM_F_STENCIL(q, c + LBM_OFFSET(q, px, pxy));                  \
        float d = ck_select(snb, v[q] - pc, 0.f);                                               \
        if (MODE != LBM_NB_BULK) {                                                              \
            const unsigned int smb = LBM_F_STENCIL(opposite_dir(q), c - LBM_OFFSET(q, px, pxy)); \
            d = ck_select((snb ^ 1u) & smb, pc - v[opposite_dir(q)], d);                        \
        }                                                                                       \
        acc += W27[q] * d;                                                                      \
    }
#endif
    LBM_FOR26(LBM_AVG)
#undef LBM_AVG
#undef LBM_F_STENCIL
    pbar[c] = GUARD ? ck_select(mask & 1u, pc + acc, pbar[c]) : pc + acc;
}

KERNEL void lbm_pressure_filter(const long long n, const float* RESTRICT p /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                float* RESTRICT pbar /* size: (nx + 2) * (ny + 2) * (nz + 2) */, const int nx,
                                const int ny, const int nz) {
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
#if CK_ON_GPU
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        const long long c = (x + 1) + px * (long long)(y + 1) + pxy * (z + 1);
        if (flags[c] != FLAG_FLUID) continue;
        lbm_filter_cell<LBM_NB_FLAGS>(c, p, flags, pbar, px, pxy, 0u);
    }
#else
    // host: the row scheme of lbm_collide_stream (flag-free bulk rows, link masks elsewhere); with the 52 flag
    // reads per cell in the x loop this 9 B/cell stage took half the flow collide's time
    CK_PRAGMA(omp parallel for collapse(2) schedule(static))
    for (int z = 0; z < nz; ++z)
        for (int y = 0; y < ny; ++y) {
            const long long row = px * (long long)(y + 1) + pxy * (z + 1);
            const bool bulk = lbm_rows_all_fluid(flags, row, 0, nx + 1, px, pxy);
            unsigned int masks[LBM_P_CHUNK], scratch[10 * (LBM_P_CHUNK + 2)];
            int lo = 1, hi = nx;
            if (!bulk) lbm_row_fluid_span(flags, row, nx, lo, hi);
            const int rem = lbm_row_tail(lo, hi);
            for (int x0 = lo; x0 <= hi;) {
                int len;
                long long c0;
                const int tail = lbm_row_chunk(x0, hi, rem, LBM_P_CHUNK, row, len, c0);
                if (bulk && !tail) {
                    CK_PRAGMA(omp simd)
                    for (int i = 0; i < len; ++i)
                        lbm_filter_cell<LBM_NB_BULK>(c0 + i, p, flags, pbar, px, pxy, LBM_FULL_MASK);
                    continue;
                }
                if (tail)
                    lbm_tail_masks(flags, c0, rem, px, pxy, masks, scratch);
                else
                    lbm_link_masks(flags, c0, len, px, pxy, masks, scratch);
                CK_PRAGMA(omp simd)
                for (int i = 0; i < len; ++i) lbm_filter_cell<LBM_NB_MASK, 1>(c0 + i, p, flags, pbar, px, pxy, masks[i]);
            }
        }
#endif
}

// The filter's three-point wall rule, a list kernel run after lbm_pressure_filter: for every listed cell c
// (an interior fluid cell of a flat wall layer of a wall normal to gravity, couplekit.fluid.grid.wall_rule_axes)
// and every link j set in its mask (grid.three_point_links: x + c_j a wall, x - c_j, x - 2 c_j and the six axis
// neighbours of x - 2 c_j stencil cells),
// the wall neighbour takes p(x) + p(x - c_j) - p(x - 2 c_j) instead of the filter's two-point 2 p(x) - p(x - c_j):
// pbar[c] += w_j [(p(x - c_j) - p(x - 2 c_j)) - (p(x) - p(x - c_j))].  Both are exact for a linear profile; the
// three-point one filters the wall-normal period-2 mode a (-1)^k of the wall layer to a / 3 as in the interior
// (the two-point one leaves it at a: Fig. 4's colander diverged from it, docs/fluid-stability.md).  One item per
// cell, so no two items write one pbar; the masks and cells are built once per flags array, as the wall links.
KERNEL void lbm_filter_wall_rule(const long long n, const float* RESTRICT p /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                 float* RESTRICT pbar /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                 const long long* RESTRICT cell /* size: n */,
                                 const unsigned int* RESTRICT links /* size: n */, const int nx, const int ny,
                                 const int nz) {
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
    (void)nz;
    FOR_EACH(i, n) {
        const long long c = cell[i];
        const unsigned int m = links[i];
        const float pc = p[c];
        float acc = 0.f;
        for (int q = 1; q < 27; ++q) {
            if (!((m >> q) & 1u)) continue;
            const long long o = LBM_OFFSET(q, px, pxy);
            const float pm = p[c - o];
            acc += W27[q] * ((pm - p[c - 2 * o]) - (pc - pm));
        }
        pbar[c] += acc;
    }
}

// out = sum_j f_j c_j of the current populations (read rule of the parity, no force shift) in interior fluid
// cells: the fluid velocity "now", as the sand-fluid exchange needs it (odd parity: ghosts and wall links
// must have been prepared as before an odd step).  want_fsum != 0: also fsum = sum_j (f_j - w_j) there, summed
// in lbm_pressure_cell's order (q = 0 .. 26), so that the next pressure update can take it instead of reading
// f again (use_fsum of lbm_macro_pressure); fsum's other cells are left as they are.  want_fsum = 2: fsum = that
// sum minus the value fsum held there (the fluid velocity's part of Eq. 39's slip term, which
// coupling_pressure_slip_fluid put there: the lockstep step).  `out` may be the buffer that velocity's part was
// read from: it is written only after.
KERNEL void lbm_momentum(const long long n, const ck_store_t* RESTRICT f /* size: 27 * (nx + 2) * (ny + 2) * (nz + 2) */,
                         const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                         float* RESTRICT out /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */, float* RESTRICT fsum,
                         const int parity, const int want_fsum, const int nx, const int ny, const int nz) {
    const int odd = parity & 1;
#define LBM_MOM(q) ux += CX27[q] * fj[q], uy += CY27[q] * fj[q], uz += CZ27[q] * fj[q];
#if CK_ON_GPU
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        // CK_PER_ITEM: the 27 load offsets recomputed per cell, not hoisted (142 -> 72 registers on sm_90)
        const int px = CK_PER_ITEM(nx + 2);
        const long long pxy = (long long)px * (ny + 2);
        const long long N = pxy * (nz + 2);
        const long long c = (x + 1) + px * (long long)(y + 1) + pxy * (z + 1);
        if (flags[c] != FLAG_FLUID) continue;
        float fj[27];
        if (odd)
            lbm_load<1, 1>(f, c, N, px, pxy, fj);
        else
            lbm_load<0, 1>(f, c, N, px, pxy, fj);
        float ux = 0.f, uy = 0.f, uz = 0.f;
        LBM_FOR26(LBM_MOM)
        out[c] = ux;
        out[N + c] = uy;
        out[2 * N + c] = uz;
        if (want_fsum) {
            float s0 = 0.f;
#define LBM_FSUM(q) s0 += fj[q];
            LBM_FOR27(LBM_FSUM)
#undef LBM_FSUM
            fsum[c] = want_fsum == 2 ? s0 - fsum[c] : s0;
        }
    }
#else
    // host: rows in parallel, each x loop over every cell of the row (`omp simd`, the parity a template
    // constant), a non-fluid cell keeping its values (a blend with flags widened to 32 bits first, as the
    // other row loops; with the flag test and the skip the loop ran scalar).  Same sums as the GPU path.
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
    const long long N = pxy * (nz + 2);
    // each population read and summed at once (a local fj[27] array was left in memory: "not suitable for
    // scatter store", scalar loop), by lbm_load's read rule
#define LBM_MOM_AT(q)                                                                       \
    {                                                                                       \
        const float v_ = CK_LOAD(f, LBM_PULL_INDEX(mom_odd, q, c, N, px, pxy), CK_F_SCALE); \
        ux += CX27[q] * v_, uy += CY27[q] * v_, uz += CZ27[q] * v_;                         \
        if (mom_fsum) s0 += v_;                                                             \
    }
#define LBM_MOM_LOOP(ODD, FSUM)                                                                    \
    CK_PRAGMA(omp parallel for collapse(2) schedule(static))                                       \
    for (int z = 0; z < nz; ++z)                                                                   \
        for (int y = 0; y < ny; ++y) {                                                             \
            const long long row = px * (long long)(y + 1) + pxy * (z + 1);                         \
            unsigned int live[LBM_P_CHUNK];                                                        \
            int lo, hi;                                                                            \
            lbm_row_fluid_span(flags, row, nx, lo, hi);                                            \
            const int rem = lbm_row_tail(lo, hi);                                                  \
            for (int x0 = lo; x0 <= hi;) {                                                         \
                int len;                                                                           \
                long long c0;                                                                      \
                /* the tail vector's first LBM_VEC - rem lanes are cells already done: kept */     \
                const int tail = lbm_row_chunk(x0, hi, rem, LBM_P_CHUNK, row, len, c0);            \
                const int kept = tail ? LBM_VEC - rem : 0;                                         \
                CK_SIMD_SHORT                                                                      \
                for (int i = 0; i < len; ++i)                                                      \
                    live[i] = flags[c0 + i] == FLAG_FLUID && i >= kept ? 1u : 0u;                  \
                CK_PRAGMA(omp simd)                                                                \
                for (int i = 0; i < len; ++i) {                                                    \
                    const long long c = c0 + i;                                                    \
                    constexpr int mom_odd = ODD, mom_fsum = FSUM;                                  \
                    float ux = 0.f, uy = 0.f, uz = 0.f, s0 = 0.f;                                  \
                    if (FSUM) s0 += CK_LOAD(f, LBM_PULL_INDEX(mom_odd, 0, c, N, px, pxy), CK_F_SCALE); \
                    LBM_FOR26(LBM_MOM_AT)                                                          \
                    out[c] = ck_select(live[i], ux, out[c]);                                       \
                    out[N + c] = ck_select(live[i], uy, out[N + c]);                               \
                    out[2 * N + c] = ck_select(live[i], uz, out[2 * N + c]);                       \
                    if (FSUM) fsum[c] = ck_select(live[i], FSUM == 2 ? s0 - fsum[c] : s0, fsum[c]);  \
                }                                                                                  \
            }                                                                                      \
        }
    if (want_fsum == 2) {
        if (odd) {
            LBM_MOM_LOOP(1, 2)
        } else {
            LBM_MOM_LOOP(0, 2)
        }
    } else if (want_fsum) {
        if (odd) {
            LBM_MOM_LOOP(1, 1)
        } else {
            LBM_MOM_LOOP(0, 1)
        }
    } else if (odd) {
        LBM_MOM_LOOP(1, 0)
    } else {
        LBM_MOM_LOOP(0, 0)
    }
#undef LBM_MOM_LOOP
#undef LBM_MOM_AT
#endif
#undef LBM_MOM
}
