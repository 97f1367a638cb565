// The sand's terms of the mixture pressure update (paper 000 Eq. 39), one function for the two kernels that add
// them: lbm_macro_pressure (lbm_pressure.cu, from the fluid's padded sand velocity) and
// coupling_pressure_sand_terms (coupling_pressure.cu, from the MPM grid velocity, into the kept population sum).
// Spec: couplekit/fluid/reference.py sand_pressure_terms.
#pragma once

// Eq. 39's sand terms of fluid cell c: ((1 - eps) div v + (u - v).grad eps) / eps, the slip term (u - v).grad eps
// only in the cells of slip_cells (couplekit.fluid.grid.slip_cells: not in the 1 or 3 layers next to a wall) and
// weighted by the water fraction phi in two-phase flow (u the velocity of Eq. 13 written by the last collision).
// The sand velocity v is read from `sv` around its own centre `sc` with its own strides (spx, spxy, sN): the
// fluid's padded sand_velocity (sc = c), or the local rows / block coupling_pressure.cu gathers from the MPM
// grid.  WITH_U = 0: the terms without the fluid velocity's part, ((1 - eps) div v + (0 - v).grad eps) / eps
// (`vel` not read): the lockstep step takes u's part out first (lbm_pressure_slip_fluid, while u's buffer still
// holds u) and this part later, from the MPM grid velocity (coupling_pressure.cu; the two sum to these terms up to
// float32 round-off).
// MODE, `mask`, `slip_on`, GPU: lbm_pressure_cell's.
template <int MODE, int TWO_PHASE, int GPU = 0, int WITH_U = 1>
LBM_INLINE float lbm_pressure_sand_terms(const long long c, const unsigned char* RESTRICT flags,
                                         const float* RESTRICT vel, const float* RESTRICT phi,
                                         const float* RESTRICT eps, const int px, const long long pxy,
                                         const long long N, const float* RESTRICT sv, const long long sc,
                                         const int spx, const long long spxy, const long long sN, unsigned int mask,
                                         unsigned int slip_on, const unsigned char* RESTRICT slip_cells) {
    static_assert(MODE != LBM_NB_FLAGS, "the sand velocity may have other strides than flags: pass a mask");
    // u: the fluid velocity of Eq. 13 (with its half-force shift) from the last collision, not sum f c:
    // sum f c = u - a/2 puts -(a/2).grad eps / eps = (grad p - rho g).grad eps / (2 rho eps) into the
    // update, which grows a grid-scale mode where eps changes next to a wall (reference docstring)
    const float ux = WITH_U ? vel[c] : 0.f, uy = WITH_U ? vel[N + c] : 0.f, uz = WITH_U ? vel[2 * N + c] : 0.f;
    if (!WITH_U) (void)vel;
    float ge[3], gvx[3], gvy[3], gvz[3];
    if (GPU) mask = lbm_link_mask(flags, c, px, pxy);  // the neighbours' kinds once, for the four stencils
    lbm_gradient<0, MODE>(eps, flags, c, px, pxy, ge, mask);
    lbm_gradient<0, MODE>(sv, flags, sc, spx, spxy, gvx, mask);
    lbm_gradient<0, MODE>(sv + sN, flags, sc, spx, spxy, gvy, mask);
    lbm_gradient<0, MODE>(sv + 2 * sN, flags, sc, spx, spxy, gvz, mask);
    const float e = eps[c];
    const float div_v = gvx[0] + gvy[1] + gvz[2];
    // the slip term only in the cells of slip_cells, not in the layers next to a wall (1, or 3 with the odd-rate
    // floor): there a porosity step grows a grid-scale mode (reference docstring)
    if (GPU) slip_on = slip_cells[c] != 0 ? 1u : 0u;
#if CK_ON_GPU
    const float slip = slip_on ? (ux - sv[sc]) * ge[0] + (uy - sv[sN + sc]) * ge[1] +
                                     (uz - sv[2 * sN + sc]) * ge[2]
                               : 0.f;  // loads only where needed (as a blend: 124 -> 128 registers)
#else
    const float slip = ck_select(slip_on, (ux - sv[sc]) * ge[0] + (uy - sv[sN + sc]) * ge[1] +
                                               (uz - sv[2 * sN + sc]) * ge[2], 0.f);
    (void)slip_cells;
#endif
    // two-phase: weighted by the water fraction; in the light phase the slip's pressure, accelerated by 1/rho,
    // pumped the air through a sand ball at the interface upward (reference docstring)
    if (TWO_PHASE) return ((1.f - e) * div_v + lbm_clamp01(phi[c]) * slip) / e;
    (void)phi;
    return ((1.f - e) * div_v + slip) / e;
}

// The fluid velocity's part of Eq. 39's slip term in fluid cell c: phi u.grad eps / eps (single-phase: without
// phi) in the cells of slip_cells, else 0 -- the terms of lbm_pressure_sand_terms that read u, the rest being
// its WITH_U = 0 form.  The lockstep step computes this part before the exchange overwrites u's buffer (the fluid
// velocity, the exchange velocity Σ f c and the force share one buffer there: coupling_pressure.cu).
// MODE, `mask`, `slip_on`, GPU: lbm_pressure_cell's.
template <int MODE, int TWO_PHASE, int GPU = 0>
LBM_INLINE float lbm_pressure_slip_fluid(const long long c, const unsigned char* RESTRICT flags,
                                         const float* RESTRICT vel, const float* RESTRICT phi,
                                         const float* RESTRICT eps, const int px, const long long pxy,
                                         const long long N, unsigned int mask, unsigned int slip_on,
                                         const unsigned char* RESTRICT slip_cells) {
#if CK_ON_GPU
    if (GPU) slip_on = slip_cells[c] != 0 ? 1u : 0u;
    if (!slip_on) return 0.f;  // no stencil outside the slip cells
#else
    (void)slip_cells;
#endif
    float ge[3];
    if (GPU) mask = lbm_link_mask(flags, c, px, pxy);
    lbm_gradient<0, MODE>(eps, flags, c, px, pxy, ge, mask);
    const float ug = vel[c] * ge[0] + vel[N + c] * ge[1] + vel[2 * N + c] * ge[2];
#if CK_ON_GPU
    const float slip = ug;
#else
    const float slip = ck_select(slip_on, ug, 0.f);
#endif
    if (TWO_PHASE) return lbm_clamp01(phi[c]) * slip / eps[c];
    (void)phi;
    return slip / eps[c];
}
