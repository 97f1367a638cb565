// Fused collide + stream of the velocity-based D3Q27 NOCM-MRT flow (paper Eqs. 8-13, 15-20), AA pattern.
// Spec: couplekit/fluid/reference.py ReferenceOps.collide_stream.
// Defines: CK_TWO_PHASE (rho, mu from phi, Eq. 4; viscous correction F_mu), CK_SURFACE_TENSION (F_s = mu_phi
// grad phi, the chemical potential mu_phi of Eq. 22 computed here from phi with the coefficients beta, kappa),
// CK_MIXTURE (fluid fraction eps), CK_EXT_FORCE (force
// density input, e.g. drag), CK_LES (Smagorinsky subgrid viscosity, constant c_les), CK_ODD_RATE (odd-moment
// rate floor lambda_odd, in cells with nu < odd_nu_max), CK_ODD_RAMP (with CK_ODD_RATE: the floor blended with
// rate 1 by the per-cell weight odd_ramp, couplekit/fluid/odd_ramp.py).  Switched-off inputs may be any float array (they are
// not read); the closures' scalars are not read when their define is 0.  The closures are compile-time
// effects, not runtime branches: a branch around loads inside the host x loop stops g++ vectorising it
// (measured 3.5x slower collide-stream at 128^3 with the branches in).
//
// Because every relaxation rate except the shear rate r_s is 1, the post-collision central moments depend on
// the pre-collision state only through m0, u and the second-order central moments (lbm-method note §1b):
// the forward transform reduces to 10 raw sums, and only the backward chimera transform is done.
// variants: CK_TWO_PHASE=0,1 CK_SURFACE_TENSION=0,1 CK_MIXTURE=0,1 CK_EXT_FORCE=1
// variants: CK_LES=1 CK_ODD_RATE=1
// variants: CK_TWO_PHASE=1 CK_SURFACE_TENSION=1 CK_MIXTURE=1 CK_EXT_FORCE=1 CK_LES=1 CK_ODD_RATE=1
// variants: CK_TWO_PHASE=1 CK_SURFACE_TENSION=1 CK_MIXTURE=1 CK_EXT_FORCE=1 CK_LES=1 CK_ODD_RATE=1 CK_ODD_RAMP=1
// variants: CK_STORAGE_FP16=1 CK_TWO_PHASE=0,1 CK_SURFACE_TENSION=0,1 CK_MIXTURE=0,1 CK_EXT_FORCE=1
// variants: CK_STORAGE_FP16=1 CK_TWO_PHASE=1 CK_SURFACE_TENSION=1 CK_MIXTURE=1 CK_EXT_FORCE=1 CK_LES=1 CK_ODD_RATE=1
// variants: CK_STORAGE_FP16=1 CK_TWO_PHASE=1 CK_SURFACE_TENSION=1 CK_MIXTURE=1 CK_EXT_FORCE=1 CK_LES=1 CK_ODD_RATE=1 CK_ODD_RAMP=1
// (CK_EXT_FORCE=0 compiles a strict subset of the =1 code, so the GPU build checks only =1)
// CK_STORAGE_FP16 (common.cuh): f held as binary16 (f - w) * CK_F_SCALE, float32 arithmetic; the lines with it
// build the effect sets of the first line and the all-closures set
#include "common.cuh"
#include "lattice.cuh"
#include "lbm_core.cuh"

#ifndef CK_TWO_PHASE
#define CK_TWO_PHASE 0
#endif
#ifndef CK_SURFACE_TENSION
#define CK_SURFACE_TENSION 0
#endif
#ifndef CK_MIXTURE
#define CK_MIXTURE 0
#endif
#ifndef CK_EXT_FORCE
#define CK_EXT_FORCE 0
#endif
#ifndef CK_LES
#define CK_LES 0
#endif
#ifndef CK_ODD_RATE
#define CK_ODD_RATE 0
#endif
#ifndef CK_ODD_RAMP
#define CK_ODD_RAMP 0
#endif
#if CK_ODD_RAMP && !CK_ODD_RATE
#error "CK_ODD_RAMP ramps the odd-rate floor: it needs CK_ODD_RATE=1"
#endif

// Backward chimera step along one axis (Geier et al. 2015): central moments (k0, k1, k2) about u -> populations
// (f-, f0, f+), in place, scaled by 2.  With S = k0 u^2 + 2u k1 + k2 and T = k0 u + k1:
//   2 f0 = 2 (k0 - S),  2 f- = S - T,  2 f+ = S + T
// (f0 = k0 (1 - u^2) - 2u k1 - k2, f-+ = (k0 (u^2 -+ u) + k1 (2u -+ 1) + k2) / 2 expanded).  The factor 2 of
// the three passes is taken out once, by feeding in K / 8 (saves 54 multiplications per cell).  The variants
// drop the terms of moments that are zero by construction: IEEE arithmetic forbids the compiler to fold x * 0.
LBM_INLINE void chimera_backward2(float& a0, float& a1, float& a2, const float u, const float u2, const float uu) {
    const float k0 = a0, S = k0 * uu + (u2 * a1 + a2), T = k0 * u + a1, t = k0 - S;
    a1 = t + t;
    a0 = S - T;
    a2 = S + T;
}
// k1 = 0
LBM_INLINE void chimera_backward2_k1zero(float& a0, float& a1, float& a2, const float k0, const float k2,
                                         const float u, const float uu) {
    const float S = k0 * uu + k2, T = k0 * u, t = k0 - S;
    a1 = t + t;
    a0 = S - T;
    a2 = S + T;
}
// k1 = k2 = 0
LBM_INLINE void chimera_backward2_k0only(float& a0, float& a1, float& a2, const float k0, const float u,
                                         const float uu) {
    const float S = k0 * uu, T = k0 * u, t = k0 - S;
    a1 = t + t;
    a0 = S - T;
    a2 = S + T;
}

// The same step on shifted values (populations stored as f - w, lbm_core.cuh): inputs k0 - k0_rest, k1,
// k2 - k0_rest / 3, outputs 2 (f - f_rest) for the line whose rest state (u = 0, at equilibrium) has k0 = k0_rest
// (and k1 = 0, k2 = k0_rest / 3: its populations are k0_rest (1/6, 2/3, 1/6)).  From the step above with
// k0 = k0_rest + d0: S = k0 u^2 + 2u k1 + d2 (the rest k2 cancels against the rest f0 + f+-), 2 df0 = 2 (d0 - S),
// 2 df-+ = S -+ T.  The small non-equilibrium parts are never added to a number of order w: the float32
// round-off is that of the deviations, not of the populations.  `neg_rest` = -k0_rest (a literal: with 0 the
// compiler drops the subtraction, which it may not do for an addition of +0).
LBM_INLINE void chimera_backward2_shift(float& a0, float& a1, float& a2, const float u, const float u2,
                                        const float uu, const float neg_rest) {
    const float d0 = a0, k0 = d0 - neg_rest, S = k0 * uu + (u2 * a1 + a2), T = k0 * u + a1, t = d0 - S;
    a1 = t + t;
    a0 = S - T;
    a2 = S + T;
}
// rest k0 of the lines of the three backward passes (scaled by 1/8, 1/4, 1/2 for the scaled steps): products of
// the 1D rest moments (1, 0, 1/3) of the axes still in moment space and the 1D weights (1/6, 2/3, 1/6) of the
// axes already turned into populations.  Index by cube position: i = 0, 1, 2 <-> order 0, 1, 2 or c = -1, 0, +1.
#define LBM_M1(i) ((i) == 0 ? 1.f : ((i) == 1 ? 0.f : 1.f / 3.f))
#define LBM_W1(i) ((i) == 1 ? 2.f / 3.f : 1.f / 6.f)
#define LBM_REST_Y(i) (0.25f * LBM_W1((i) / 3) * LBM_M1((i) % 3))
#define LBM_REST_Z(ij) (0.5f * LBM_W1((ij) / 3) * LBM_W1((ij) % 3))

// Forward chimera step along one axis: populations (f-, f0, f+) -> central moments (k0, k1, k2) about u, in place:
//   k0 = f- + f0 + f+,  k1 = (f+ - f-) - u k0,  k2 = (f+ + f-) - 2u (f+ - f-) + u^2 k0.
LBM_INLINE void chimera_forward(float& a0, float& a1, float& a2, const float u) {
    const float s = a0 + a2, d = a2 - a0, k0 = s + a1;
    a0 = k0;
    a1 = d - u * k0;
    a2 = s - (u + u) * d + u * u * k0;
}

#define CUBE(q) ((CX27[q] + 1) * 9 + (CY27[q] + 1) * 3 + (CZ27[q] + 1))
// direction q of cube index (c_x + 1) * 9 + (c_y + 1) * 3 + (c_z + 1) (inverse of CUBE; lattice.cuh order)
CONSTANT int QOF27[27] = {20, 8, 22, 10, 2, 16, 24, 14, 25, 12, 4, 18, 6, 0,
                          5, 17, 3, 11, 26, 13, 23, 15, 1, 9, 21, 7, 19};
#define LBM_QOF(i) QOF27[i]

// all 27 central moments kc[a*9 + b*3 + c] about (ux, uy, uz) of the populations fj (by direction; must not
// alias kc): z, y, x passes
// (straight-line: an inner loop left in the host x loop stops it vectorising)
LBM_INLINE void lbm_central_moments(const float* RESTRICT fj, const float ux, const float uy, const float uz,
                                    float* RESTRICT kc) {
#define LBM_CM_LD(i) kc[i] = fj[QOF27[i]];
#define LBM_CM_Z(l) chimera_forward(kc[(l) * 3], kc[(l) * 3 + 1], kc[(l) * 3 + 2], uz);
#define LBM_CM_Y(l) chimera_forward(kc[(l) / 3 * 9 + (l) % 3], kc[(l) / 3 * 9 + 3 + (l) % 3], kc[(l) / 3 * 9 + 6 + (l) % 3], uy);
#define LBM_CM_X(l) chimera_forward(kc[l], kc[9 + (l)], kc[18 + (l)], ux);
    LBM_FOR27(LBM_CM_LD)
    LBM_REP9(LBM_CM_Z, 0)
    LBM_REP9(LBM_CM_Y, 0)
    LBM_REP9(LBM_CM_X, 0)
#undef LBM_CM_LD
#undef LBM_CM_Z
#undef LBM_CM_Y
#undef LBM_CM_X
}

// the same central moments from the x-line sums X0 = f- + f0 + f+, X1 = f+ - f-, X2 = f+ + f- of the 9 (y, z)
// lines (index (c_y + 1) * 3 + (c_z + 1)), which the collision has already formed: the x pass is
// k0 = X0, k1 = X1 - u X0, k2 = X2 - 2u X1 + u^2 X0 (chimera_forward's), then y and z as above.  Same terms as
// lbm_central_moments in another order (the passes along different axes commute): float32 round-off apart.
LBM_INLINE void lbm_central_moments_xlines(const float* RESTRICT X0, const float* RESTRICT X1,
                                           const float* RESTRICT X2, const float ux, const float uy, const float uz,
                                           float* RESTRICT kc) {
#define LBM_CM_XL(l) \
    kc[l] = X0[l], kc[9 + (l)] = X1[l] - ux * X0[l], kc[18 + (l)] = X2[l] - (ux + ux) * X1[l] + ux * ux * X0[l];
#define LBM_CM_Y(l) chimera_forward(kc[(l) / 3 * 9 + (l) % 3], kc[(l) / 3 * 9 + 3 + (l) % 3], kc[(l) / 3 * 9 + 6 + (l) % 3], uy);
#define LBM_CM_Z(l) chimera_forward(kc[(l) * 3], kc[(l) * 3 + 1], kc[(l) * 3 + 2], uz);
    LBM_REP9(LBM_CM_XL, 0)
    LBM_REP9(LBM_CM_Y, 0)
    LBM_REP9(LBM_CM_Z, 0)
#undef LBM_CM_XL
#undef LBM_CM_Y
#undef LBM_CM_Z
}

// host rows are processed in chunks of this many cells (the link masks of a chunk live on the stack)
#define LBM_ROW_CHUNK 512

// second central moments (xx, yy, zz, xy, xz, yz) about velocity (ux, uy, uz) from the raw moments m0, m_a, m_ab
LBM_INLINE void lbm_central_second(const float m0, const float mx, const float my, const float mz, const float mxx,
                                   const float myy, const float mzz, const float mxy, const float mxz, const float myz,
                                   const float ux, const float uy, const float uz, float* RESTRICT k) {
    k[0] = mxx - 2.f * ux * mx + ux * ux * m0;
    k[1] = myy - 2.f * uy * my + uy * uy * m0;
    k[2] = mzz - 2.f * uz * mz + uz * uz * m0;
    k[3] = mxy - ux * my - uy * mx + ux * uy * m0;
    k[4] = mxz - ux * mz - uz * mx + ux * uz * m0;
    k[5] = myz - uy * mz - uz * my + uy * uz * m0;
}

// Host wall rows: GUARD = 1 runs every cell of a chunk through the same arithmetic and stores the results only
// where bit 0 of the mask says the cell is FLUID; elsewhere the old values are written back (read and blended:
// no branch, so the x loop vectorises; a `continue` past non-fluid cells left it scalar).  Each store address
// belongs to this cell alone in this pass (the AA pattern's push is one-to-one), so writing back the value
// already there races with nothing.  A non-fluid cell's arithmetic may produce inf / NaN (eps = 0 in a solid):
// the blend discards it.
#define LBM_STORE_GUARDED(p, i, v, live)               \
    {                                                  \
        ck_store_t n_;                                 \
        CK_STORE(&n_, 0, v, CK_F_SCALE);               \
        (p)[i] = ck_store_blend(live, n_, (p)[i]);     \
    }

// Eq. 22 from phi at the cell and the Laplacian's sum sum_j w_j d_j (lbm_gradient's LAP; Eq. 23's factor 6 here):
// mu_phi = 4 beta phi (phi - 1)(phi - 1/2) - kappa lap phi
LBM_INLINE float lbm_chemical_potential(const float pc, const float lap_sum, const float beta, const float kappa) {
    return 4.f * beta * pc * (pc - 1.f) * (pc - 0.5f) - kappa * (6.f * lap_sum);
}

#if !CK_ON_GPU
// Host: grad phi (Eq. 18, lbm_gradient's EXTRAP = 0 rule) and, with surface tension, mu_phi (Eq. 22) of the `len`
// cells from padded index c0 into gx, gy, gz, mu, by one vector loop (MODE as lbm_gradient's; `masks`: the chunk's
// lbm_link_masks, read with LBM_NB_MASK only).  The collide loop then reads them: with these stencils inside it,
// its loop body (populations, moments, two stencils) ran 10-25 % slower (1 thread, 64^3 / 128^3), and the mu
// Laplacian alone cost as much as the former phase_gradients pass.
template <int MODE>
static inline __attribute__((always_inline)) void lbm_phi_stencil_chunk(
    const float* RESTRICT phi, const unsigned char* RESTRICT flags, const long long c0, const int len, const int px,
    const long long pxy, const unsigned int* RESTRICT masks, const float beta, const float kappa,
    float* RESTRICT gx, float* RESTRICT gy, float* RESTRICT gz, float* RESTRICT mu) {
    CK_PRAGMA(omp simd)
    for (int i = 0; i < len; ++i) {
        const unsigned int m = MODE == LBM_NB_MASK ? masks[i] : LBM_FULL_MASK;
        const LbmVec3 g = lbm_gradient_host<0, MODE>(phi, flags, c0 + i, px, pxy, m);
        gx[i] = g.x;
        gy[i] = g.y;
        gz[i] = g.z;
#if CK_SURFACE_TENSION
        mu[i] = lbm_chemical_potential(phi[c0 + i], lbm_laplacian_sum<MODE>(phi, flags, c0 + i, px, pxy, m), beta,
                                       kappa);
#else
        mu[i] = 0.f;  // not read without surface tension; written so the collide gets no indeterminate value
        (void)beta, (void)kappa;
#endif
    }
}
#endif

// one fluid cell: load, forces, collision, store (ODD = parity & 1; MODE: how the stencils learn the kind of a
// neighbour, see lbm_gradient; `mask` = lbm_link_mask of c for LBM_NB_MASK; GUARD: see above, host only)
template <int ODD, int MODE, int GUARD = 0>
LBM_INLINE void lbm_collide_cell(const long long c, ck_store_t* RESTRICT f, const unsigned char* RESTRICT flags,
                                 float* RESTRICT vel, const float* RESTRICT phi, const float* RESTRICT eps,
                                 const float* RESTRICT force,
                                 const float* RESTRICT pbar, const float* RESTRICT odd_ramp, const int px,
                                 const long long pxy, const long long N, const float rho_h, const float rho_l, const float nu_h, const float nu_l,
                                 const float gx, const float gy, const float gz, const float c_les,
                                 const float lambda_odd, const float odd_nu_max, const float beta,
                                 const float kappa, const unsigned int mask, const float mu_host = 0.f,
                                 const float gphx = 0.f, const float gphy = 0.f, const float gphz = 0.f) {
    float fj[27];
    lbm_load_scaled<ODD>(f, c, N, px, pxy, fj);  // (f - w) * CK_F_SCALE: the moments take the scale out

    // raw moments of the stored deviations f - w (lbm_core.cuh): dm0 = m0 - 1, m_a, dm_aa = m_aa - 1/3, m_ab
    // (a != b) -- the weights' own moments are 1, 0, 1/3, 0 -- by a forward chimera-style pass (66 additions): along x the line sums
    // X0 = f- + f0 + f+, X1 = f+ - f-, X2 = f+ + f- of the 9 (y, z) lines, then along y, then along z
    float X0[9], X1[9], X2[9];
#define LBM_XLINE(l)                                                                   \
    {                                                                                 \
        const float fm = fj[LBM_QOF(0 * 9 + (l))], fp = fj[LBM_QOF(2 * 9 + (l))];      \
        X2[l] = fm + fp;                                                              \
        X0[l] = X2[l] + fj[LBM_QOF(9 + (l))];                                          \
        X1[l] = fp - fm;                                                              \
    }
    LBM_REP9(LBM_XLINE, 0)
#undef LBM_XLINE
    // line index l = (c_y + 1) * 3 + (c_z + 1); along y for each z index k
    float Y00[3], Y01[3], Y02[3], Y10[3], Y11[3], Y20[3];
#define LBM_YLINE(k)                                      \
    {                                                    \
        Y02[k] = X0[k] + X0[6 + (k)];                    \
        Y00[k] = Y02[k] + X0[3 + (k)];                   \
        Y01[k] = X0[6 + (k)] - X0[k];                    \
        Y10[k] = (X1[k] + X1[6 + (k)]) + X1[3 + (k)];    \
        Y11[k] = X1[6 + (k)] - X1[k];                    \
        Y20[k] = (X2[k] + X2[6 + (k)]) + X2[3 + (k)];    \
    }
    LBM_YLINE(0) LBM_YLINE(1) LBM_YLINE(2)
#undef LBM_YLINE
    // 1 / CK_F_SCALE: a power of two, exact (and 1, folded away, with fp32 storage)
#define LBM_UNSCALE(v) ((v) * (1.f / CK_F_SCALE))
    const float mzz = LBM_UNSCALE(Y00[0] + Y00[2]);  // dm_zz (deviation from 1/3), likewise myy, mxx below
    const float dm0 = mzz + LBM_UNSCALE(Y00[1]), mz = LBM_UNSCALE(Y00[2] - Y00[0]);
    const float m0 = 1.f + dm0;  // only where it multiplies u u (the central moments below)
    const float my = LBM_UNSCALE((Y01[0] + Y01[2]) + Y01[1]), myz = LBM_UNSCALE(Y01[2] - Y01[0]);
    const float myy = LBM_UNSCALE((Y02[0] + Y02[2]) + Y02[1]);
    const float mx = LBM_UNSCALE((Y10[0] + Y10[2]) + Y10[1]), mxz = LBM_UNSCALE(Y10[2] - Y10[0]);
    const float mxy = LBM_UNSCALE((Y11[0] + Y11[2]) + Y11[1]);
    const float mxx = LBM_UNSCALE((Y20[0] + Y20[2]) + Y20[1]);
#undef LBM_UNSCALE

    // material properties, Eq. 4
#if CK_TWO_PHASE
    const float ph = lbm_clamp01(phi[c]);
    const float rho = rho_l + (rho_h - rho_l) * ph;
    const float nu = (rho_l * nu_l + (rho_h * nu_h - rho_l * nu_l) * ph) / rho;
#else
    const float rho = rho_h;
    const float nu = nu_h;
#endif
    const float inv_rho = 1.f / rho;
#if CK_MIXTURE
    const float e = eps[c];
#else
    const float e = 1.f;
#endif

#if !(CK_TWO_PHASE && CK_SURFACE_TENSION)
    (void)beta, (void)kappa, (void)mu_host;
#endif
#if !CK_TWO_PHASE
    (void)gphx, (void)gphy, (void)gphz;
#endif
    // acceleration, Eq. 15: -grad pbar / rho + g (+ F_s / rho) (+ F_ext / (eps rho))
    float gp[3];
    lbm_gradient<1, MODE>(pbar, flags, c, px, pxy, gp, mask);
    float ax = gx - gp[0] * inv_rho, ay = gy - gp[1] * inv_rho, az = gz - gp[2] * inv_rho;
#if CK_TWO_PHASE
    // grad phi and, on the GPU with surface tension, the Laplacian's sum of mu_phi (lbm_gradient's LAP); the host
    // takes both from the row chunk's own vector loop (gphx.., mu_host: lbm_phi_stencil_chunk)
    float gphi[4];
#if CK_ON_GPU
    lbm_gradient<0, MODE, CK_SURFACE_TENSION>(phi, flags, c, px, pxy, gphi, mask);
    (void)gphx, (void)gphy, (void)gphz;
#else
    gphi[0] = gphx, gphi[1] = gphy, gphi[2] = gphz;
#endif
#if CK_SURFACE_TENSION
#if CK_ON_GPU
    const float mu_phi = lbm_chemical_potential(phi[c], gphi[3], beta, kappa);
    (void)mu_host;
#else
    const float mu_phi = mu_host;
    (void)beta, (void)kappa;
#endif
    const float chem = mu_phi * inv_rho;
    ax += chem * gphi[0];
    ay += chem * gphi[1];
    az += chem * gphi[2];
#endif
#endif
#if CK_EXT_FORCE
    const float inv_erho = 1.f / (e * rho);
    ax += force[c] * inv_erho;
    ay += force[N + c] * inv_erho;
    az += force[2 * N + c] * inv_erho;
#endif
    // pre-collision second central moments about the velocity shifted by the forces so far (all but F_mu);
    // from the deviations: the diagonal ones are kappa_aa - 1/3 (their equilibrium is 0), the rest kappa_ab
    float vk[6];
    lbm_central_second(m0, mx, my, mz, mxx, myy, mzz, mxy, mxz, myz, mx + 0.5f * ax, my + 0.5f * ay, mz + 0.5f * az, vk);
    const float vkxx = vk[0], vkyy = vk[1], vkzz = vk[2], vkxy = vk[3], vkxz = vk[4], vkyz = vk[5];
    const float vtr3 = (vkxx + vkyy + vkzz) * (1.f / 3.f);
    // Smagorinsky subgrid viscosity (Hou et al. 1996) from the deviatoric non-equilibrium stress
    // Q = |dev kappa_2| (its equilibrium is 0): tau = (tau0 + sqrt(tau0^2 + 18 sqrt(2) C^2 Q)) / 2, i.e.
    // nu_t = (C dx)^2 |S| with |S| = sqrt(2 S:S) taken from Q / (2 c_s^2 tau).  C = 0 (c_les) leaves nu.
    float tau = 3.f * nu + 0.5f;
#if CK_LES
    {
        const float dxx = vkxx - vtr3, dyy = vkyy - vtr3, dzz = vkzz - vtr3;
        const float q2 = dxx * dxx + dyy * dyy + dzz * dzz + 2.f * (vkxy * vkxy + vkxz * vkxz + vkyz * vkyz);
        tau = 0.5f * (tau + sqrtf(tau * tau + 25.455844f * c_les * c_les * sqrtf(q2)));
    }
#else
    (void)c_les;
#endif
    const float rs = 1.f / tau;
#if CK_TWO_PHASE || CK_MIXTURE
    {
        // viscous correction F_mu = nu grad^sym u . [grad rho + (rho/eps) grad eps]   (Eq. 16), with
        // grad^sym u ~ -3 r_s dev(kappa_2) + (2/3)(1 - m0) I from the pre-collision central moments
        // (nu and r_s include the subgrid viscosity); the acceleration is F_mu / rho, Eq. 15's
        // (nu / (eps rho)) grad^sym u . grad(eps rho): Eq. 16 already holds the 1 / eps (reference.py forces)
        const float kxx = vkxx, kyy = vkyy, kzz = vkzz, kxy = vkxy, kxz = vkxz, kyz = vkyz, tr3 = vtr3;
        const float iso = (-2.f / 3.f) * dm0;  // (2/3)(1 - m0)
        const float s = -3.f * rs;
        const float sxx = s * (kxx - tr3) + iso, syy = s * (kyy - tr3) + iso, szz = s * (kzz - tr3) + iso;
        const float sxy = s * kxy, sxz = s * kxz, syz = s * kyz;
        float g0 = 0.f, g1 = 0.f, g2 = 0.f;
#if CK_TWO_PHASE
        g0 += (rho_h - rho_l) * gphi[0];
        g1 += (rho_h - rho_l) * gphi[1];
        g2 += (rho_h - rho_l) * gphi[2];
#endif
#if CK_MIXTURE
        float ge[3];
        lbm_gradient<0, MODE>(eps, flags, c, px, pxy, ge, mask);
        g0 += rho / e * ge[0];
        g1 += rho / e * ge[1];
        g2 += rho / e * ge[2];
#endif
        const float k = (tau - 0.5f) * (1.f / 3.f) / rho;
        ax += k * (sxx * g0 + sxy * g1 + sxz * g2);
        ay += k * (sxy * g0 + syy * g1 + syz * g2);
        az += k * (sxz * g0 + syz * g1 + szz * g2);
    }
#endif
    // velocity with the half-force shift, Eq. 13
    const float ux = mx + 0.5f * ax, uy = my + 0.5f * ay, uz = mz + 0.5f * az;

    // post-collision central moments (rates 1 except r_s on the deviatoric second order; Guo forcing); the
    // diagonal k2 are deviations from 1/3, which kxx - kyy does not see
    float k2[6];
    lbm_central_second(m0, mx, my, mz, mxx, myy, mzz, mxy, mxz, myz, ux, uy, uz, k2);
    const float kxx = k2[0], kyy = k2[1], kzz = k2[2], kxy = k2[3], kxz = k2[4], kyz = k2[5];
    const float om = 1.f - rs;
    const float dxy = om * (kxx - kyy), dxz = om * (kxx - kzz);
    // post-collision central moments K_abc (a, b, c = orders in x, y, z; cube index a*9 + b*3 + c): rate 1
    // except r_s on the deviatoric second order, Guo forcing; the zeroth moment reset to 1:
    //   K000 = 1, K100 = ax/2, K120 = K102 = ax/6, K122 = ax/18 (alike for y, z), K110 = om kxy, K101 = om kxz,
    //   K011 = om kyz, K200 = (1 + dxy + dxz)/3, K020 = K200 - dxy, K002 = K200 - dxz, K220 = K202 = K022 = 1/9,
    //   K222 = 1/27, K111 = K112 = K121 = K211 = 0.
    // (all scaled by 1/8 for the scaled chimera steps).  They are fed in as deviations from the rest state
    // (K000 = 1, K200 = 1/3, K220 = 1/9, K222 = 1/27 -> 0; K200 -> (dxy + dxz)/3), and the shifted chimera steps
    // (chimera_backward2_shift with the rest k0 of each line) return f* - w, which is what is stored.
    const float k200 = (dxy + dxz) * (1.f / 24.f), dxy8 = 0.125f * dxy, dxz8 = 0.125f * dxz;
    const float hax = 0.0625f * ax, hay = 0.0625f * ay, haz = 0.0625f * az;
    const float sax = ax * (1.f / 48.f), say = ay * (1.f / 48.f), saz = az * (1.f / 48.f);
    const float om8 = 0.125f * om;
    const float ux2 = ux + ux, uy2 = uy + uy, uz2 = uz + uz;
    const float uxx = ux * ux, uyy = uy * uy, uzz = uz * uz;
    float K[27];
    // backward chimera transform: x (folding the known zeros), then y, then z; afterwards K holds the
    // populations by cube index (c_x + 1) * 9 + (c_y + 1) * 3 + (c_z + 1)
#if CK_ODD_RATE
    {
        // odd central moments (orders 3 and 5: K120, K102, K210, K012, K201, K021, K111, K122, K212, K221)
        // relax at r_o instead of 1, with Guo's forcing like every other moment (reference.collide):
        //   k* = k - r_o k + (1 - r_o/2) k^F = (1 - r_o) k + (2 - r_o) (k^F / 2)
        // (k^F / 2 is the rate-1 value above).  Under a steady acceleration a the central moments about the
        // next step's velocity start at k*_prev - a/3, and this keeps k* = a/6, the rate-1 value; the former
        // r_o k^F / 2 let them pile up to -(1 - r_o) a / (3 r_o), 16x larger at r_o = 0.02, which broke a 3 m/s
        // impact once the air relaxed slowly too (docs/fluid-stability.md, "Energy of a standing wave").
        // The two-relaxation-time "magic" product Lambda = (1/r_s - 1/2)(1/r_o - 1/2) is kept >= lambda_odd
        // (at r_o = 1 and nu_h = 1e-4, Lambda = 1.5e-4, the no-slip walls' edges and corners are linearly
        // unstable), with 1/r_s - 1/2 taken at the fluid's lowest molecular viscosity nu_ref plus this cell's
        // subgrid viscosity (reference.odd_rates): one rate wherever the flow is resolved, whatever the phase,
        // because a rate that follows each cell's viscosity across an interface fed energy into surface waves.
        // The populations are read again (same addresses, nothing stored yet) rather than kept live through the
        // force computation.
#if CK_TWO_PHASE
        const float nu_ref = ck_select((unsigned int)(nu_h < nu_l), nu_h, nu_l);  // not fminf: it stops g++ vectorising
#else
        const float nu_ref = nu_h;
#endif
        const float odd_tau = (tau - 0.5f) - 3.f * nu + 3.f * nu_ref;  // 3 (nu_ref + nu_t)
        float ro = 1.f / (0.5f + lambda_odd / odd_tau);
        ro = ck_select((unsigned int)(ro < 1.f) & (unsigned int)(nu_ref < odd_nu_max), ro, 1.f);  // no branch
#if CK_ODD_RAMP
        ro += (1.f - ro) * odd_ramp[c];  // reference.ramped_odd_rates: the weight s of rate 1 (0 at the walls)
#else
        (void)odd_ramp;
#endif
        const float co = 0.125f * (1.f - ro), rf = 2.f - ro;  // k* = (1 - r_o) k + (2 - r_o) k^F / 2
        // central moments of the populations: those of the stored deviations (the transform is linear) plus
        // those of the weights w about u, products of the 1D moments (1, -u, 1/3 + u^2) of (1/6, 2/3, 1/6)
        // (the host takes them from the x-line sums of the stored values, kept on its stack anyway, times
        // 1 / CK_F_SCALE, exact; the GPU reads the populations again rather than keep 27 sums live through the
        // force computation.  The re-read takes its cell and grid sizes through CK_PER_ITEM: with the plain
        // addresses the compiler merged it with the first loads and kept those 27 values live through the forces
        // (166 registers unbounded, a 4 B spill under 128 on sm_90 in the all-closures variants; 156 and none now)
        float kc[27];
#if CK_ON_GPU
        {
            float fr[27];
            lbm_load<ODD>(f, CK_PER_ITEM(c), CK_PER_ITEM(N), CK_PER_ITEM(px), CK_PER_ITEM(pxy), fr);
            lbm_central_moments(fr, ux, uy, uz, kc);
        }
#else
        lbm_central_moments_xlines(X0, X1, X2, ux, uy, uz, kc);
#define LBM_CM_UNSCALE(i) kc[i] *= 1.f / CK_F_SCALE;
        LBM_FOR27(LBM_CM_UNSCALE)
#undef LBM_CM_UNSCALE
#endif
        const float wx2 = 1.f / 3.f + uxx, wy2 = 1.f / 3.f + uyy, wz2 = 1.f / 3.f + uzz;
        kc[19] -= wx2 * uz, kc[11] -= ux * wz2, kc[21] -= wx2 * uy, kc[13] -= ux * uy * uz, kc[5] -= uy * wz2;
        kc[23] -= wx2 * uy * wz2, kc[15] -= ux * wy2, kc[7] -= wy2 * uz, kc[25] -= wx2 * wy2 * uz;
        kc[17] -= ux * wy2 * wz2;
        K[0] = 0.f, K[9] = hax, K[18] = k200;
        K[1] = haz, K[10] = om8 * kxz, K[19] = rf * saz + co * kc[19];
        K[2] = k200 - dxz8, K[11] = rf * sax + co * kc[11], K[20] = 0.f;
        K[3] = hay, K[12] = om8 * kxy, K[21] = rf * say + co * kc[21];
        K[4] = om8 * kyz, K[13] = co * kc[13], K[22] = 0.f;
        K[5] = rf * say + co * kc[5], K[14] = 0.f, K[23] = rf * ay * (1.f / 144.f) + co * kc[23];
        K[6] = k200 - dxy8, K[15] = rf * sax + co * kc[15], K[24] = 0.f;
        K[7] = rf * saz + co * kc[7], K[16] = 0.f, K[25] = rf * az * (1.f / 144.f) + co * kc[25];
        K[8] = 0.f, K[17] = rf * ax * (1.f / 144.f) + co * kc[17], K[26] = 0.f;
#define LBM_BACK_X(l) chimera_backward2_shift(K[l], K[9 + (l)], K[18 + (l)], ux, ux2, uxx, 0.f - 0.125f * LBM_M1((l) / 3) * LBM_M1((l) % 3));
        LBM_REP9(LBM_BACK_X, 0)
#undef LBM_BACK_X
    }
#else
    (void)lambda_odd;
    (void)odd_nu_max;
    (void)odd_ramp;
    {
        K[0] = 0.f, K[9] = hax, K[18] = k200;  // bc = 00
        chimera_backward2_shift(K[0], K[9], K[18], ux, ux2, uxx, -0.125f);
        K[1] = haz, K[10] = om8 * kxz, K[19] = saz;  // 01
        chimera_backward2(K[1], K[10], K[19], ux, ux2, uxx);
        K[2] = k200 - dxz8, K[11] = sax, K[20] = 0.f;  // 02
        chimera_backward2_shift(K[2], K[11], K[20], ux, ux2, uxx, -1.f / 24.f);
        K[3] = hay, K[12] = om8 * kxy, K[21] = say;  // 10
        chimera_backward2(K[3], K[12], K[21], ux, ux2, uxx);
        chimera_backward2_k0only(K[4], K[13], K[22], om8 * kyz, ux, uxx);                // 11
        chimera_backward2_k1zero(K[5], K[14], K[23], say, ay * (1.f / 144.f), ux, uxx);  // 12
        K[6] = k200 - dxy8, K[15] = sax, K[24] = 0.f;  // 20
        chimera_backward2_shift(K[6], K[15], K[24], ux, ux2, uxx, -1.f / 24.f);
        chimera_backward2_k1zero(K[7], K[16], K[25], saz, az * (1.f / 144.f), ux, uxx);  // 21
        K[8] = 0.f, K[17] = ax * (1.f / 144.f), K[26] = 0.f;  // 22
        chimera_backward2_shift(K[8], K[17], K[26], ux, ux2, uxx, -1.f / 72.f);
    }
#endif
#define LBM_BACK_Y(i) chimera_backward2_shift(K[(i) / 3 * 9 + (i) % 3], K[(i) / 3 * 9 + 3 + (i) % 3], K[(i) / 3 * 9 + 6 + (i) % 3], uy, uy2, uyy, 0.f - LBM_REST_Y(i));
    LBM_REP9(LBM_BACK_Y, 0)
#undef LBM_BACK_Y
    // z pass, each line stored as soon as it is final (fewer live values, fewer spills on the host).  The
    // store addresses of the AA pattern are the load addresses (of the opposite directions): computed from
    // CK_PER_ITEM copies of the geometry, so that the GPU compiler recomputes them here instead of keeping the
    // 27 64-bit indices of the loads live through the whole cell (measured on sm_90: that alone was the
    // difference between spilling and not under 128 registers)
    const int spx = CK_PER_ITEM(px);
    const long long spxy = CK_PER_ITEM(pxy), sN = CK_PER_ITEM(N);
    const unsigned int live = GUARD ? (mask & 1u) : 1u;  // 32-bit, not bool (ck_select)
#if CK_ON_GPU
#define LBM_PUT_AT(idx, v) CK_STORE(f, idx, v, CK_F_SCALE);
#else
#define LBM_PUT_AT(idx, v)                    \
    if (GUARD) {                              \
        LBM_STORE_GUARDED(f, idx, v, live)    \
    } else {                                  \
        CK_STORE(f, idx, v, CK_F_SCALE);      \
    }
#endif
#define LBM_PUT(i)                                                              \
    if (ODD) {                                                                  \
        LBM_PUT_AT(QOF27[i] * sN + c + LBM_OFFSET(QOF27[i], spx, spxy), K[i])   \
    } else {                                                                    \
        LBM_PUT_AT(opposite_dir(QOF27[i]) * sN + c, K[i])                       \
    }
#define LBM_BACK_Z(ij)                                                            \
    chimera_backward2_shift(K[(ij) * 3], K[(ij) * 3 + 1], K[(ij) * 3 + 2], uz, uz2, uzz, 0.f - LBM_REST_Z(ij)); \
    LBM_PUT((ij) * 3) LBM_PUT((ij) * 3 + 1) LBM_PUT((ij) * 3 + 2)
    LBM_REP9(LBM_BACK_Z, 0)
#undef LBM_BACK_Z
#undef LBM_PUT
#undef LBM_PUT_AT
    if (GUARD) {  // a wall cell's velocity is its wall velocity (the bounce-back reads it): kept
        vel[c] = ck_select(live, ux, vel[c]);
        vel[N + c] = ck_select(live, uy, vel[N + c]);
        vel[2 * N + c] = ck_select(live, uz, vel[2 * N + c]);
    } else {
        vel[c] = ux;
        vel[N + c] = uy;
        vel[2 * N + c] = uz;
    }
}

KERNEL void lbm_collide_stream(const long long n, ck_store_t* RESTRICT f /* size: 27 * (nx + 2) * (ny + 2) * (nz + 2) */,
                               const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                               float* RESTRICT vel /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
                               const float* RESTRICT phi, const float* RESTRICT eps,
                               const float* RESTRICT force,
                               const float* RESTRICT pbar /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                               const float* RESTRICT odd_ramp,
                               const int parity, const int nx, const int ny, const int nz, const float rho_h,
                               const float rho_l, const float nu_h, const float nu_l, const float gx,
                               const float gy, const float gz, const float c_les,
                               const float lambda_odd, const float odd_nu_max, const float beta, const float kappa) {
    const int px = nx + 2;
    const long long pxy = (long long)px * (ny + 2);
    const long long N = pxy * (nz + 2);
#define LBM_CELL_ARGS(px, pxy, N) \
    f, flags, vel, phi, eps, force, pbar, odd_ramp, px, pxy, N, rho_h, rho_l, nu_h, nu_l, gx, gy, gz, c_les, lambda_odd, odd_nu_max, \
        beta, kappa
#if CK_ON_GPU
    // one thread per cell; the flag tests of the stencils cost little next to the memory traffic.  The grid
    // sizes pass through CK_PER_ITEM inside the loop (common.cuh): hoisted out of the grid-stride loop, the 27
    // load + 27 store offsets derived from them held ~100 registers (242 -> see the build report)
#define LBM_COLLIDE_LOOP(ODD)                                                                  \
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {                                                       \
        const int ipx = CK_PER_ITEM(px);                                                       \
        const long long ipxy = CK_PER_ITEM(pxy), iN = CK_PER_ITEM(N);                          \
        const long long c = (x + 1) + ipx * (long long)(y + 1) + ipxy * (z + 1);               \
        if (flags[c] != FLAG_FLUID) continue;                                                  \
        const unsigned int m = lbm_link_mask(flags, c, ipx, ipxy);                             \
        lbm_collide_cell<ODD, LBM_NB_MASK>(c, LBM_CELL_ARGS(ipx, ipxy, iN), m);                \
    }
#else
    // host: the FOR_EACH_CELL shape ((z, y) rows in parallel, x loop `omp simd`) written out, so that a row
    // can choose between two float-only x loops: LBM_NB_BULK when the row's 9-row neighbourhood is all fluid
    // (no flag logic, no masked lanes), else LBM_NB_MASK over the whole row with link masks gathered first
    // (lbm_link_masks).  A byte read inside the collide loop makes g++ pick 64 lanes (four zmm registers per
    // float) and spill the populations to the stack (measured 2-3x).  Splitting a wall row into bulk cells and
    // masked end cells was measured slower: the short loops cost more than the mask logic saves.  The masked
    // loop runs its non-fluid cells too and keeps their values (GUARD = 1).
    // Two-phase: the chunk's grad phi and mu_phi (Eq. 22) are computed first by their own vector loop into the
    // stack buffers gb*, mub (lbm_phi_stencil_chunk), then read by the collide loop.
#if CK_TWO_PHASE
#define LBM_PHI_CHUNK(MODE, c0, len, masks) \
    lbm_phi_stencil_chunk<MODE>(phi, flags, c0, len, px, pxy, masks, beta, kappa, gbx, gby, gbz, mub);
#define LBM_CHUNK_BUFFERS float mub[LBM_ROW_CHUNK], gbx[LBM_ROW_CHUNK], gby[LBM_ROW_CHUNK], gbz[LBM_ROW_CHUNK];
#define LBM_CHUNK_VALUES(i) mub[i], gbx[i], gby[i], gbz[i]
#else
#define LBM_PHI_CHUNK(MODE, c0, len, masks)
#define LBM_CHUNK_BUFFERS
#define LBM_CHUNK_VALUES(i) 0.f, 0.f, 0.f, 0.f
#endif
#define LBM_COLLIDE_LOOP(ODD)                                                                          \
    CK_PRAGMA(omp parallel for collapse(2) schedule(static))                                           \
    for (int z = 0; z < nz; ++z)                                                                       \
        for (int y = 0; y < ny; ++y) {                                                                 \
            const long long row = px * (long long)(y + 1) + pxy * (z + 1);                             \
            LBM_CHUNK_BUFFERS                                                                          \
            unsigned int masks[LBM_ROW_CHUNK], scratch[10 * (LBM_ROW_CHUNK + 2)];                      \
            const bool bulk = lbm_rows_all_fluid(flags, row, 0, nx + 1, px, pxy);                      \
            int lo = 1, hi = nx;                                                                       \
            if (!bulk) lbm_row_fluid_span(flags, row, nx, lo, hi);                                     \
            const int rem = lbm_row_tail(lo, hi);                                                      \
            for (int x0 = lo; x0 <= hi;) {                                                             \
                int len;                                                                               \
                long long c0;                                                                          \
                const int tail = lbm_row_chunk(x0, hi, rem, LBM_ROW_CHUNK, row, len, c0);              \
                if (bulk && !tail) {                                                                   \
                    LBM_PHI_CHUNK(LBM_NB_BULK, c0, len, masks)                                          \
                    CK_PRAGMA(omp simd)                                                                \
                    for (int i = 0; i < len; ++i)                                                      \
                        lbm_collide_cell<ODD, LBM_NB_BULK>(c0 + i, LBM_CELL_ARGS(px, pxy, N), LBM_FULL_MASK, \
                                                           LBM_CHUNK_VALUES(i));                       \
                    continue;                                                                          \
                }                                                                                      \
                if (tail)                                                                              \
                    lbm_tail_masks(flags, c0, rem, px, pxy, masks, scratch);                           \
                else                                                                                   \
                    lbm_link_masks(flags, c0, len, px, pxy, masks, scratch);                           \
                LBM_PHI_CHUNK(LBM_NB_MASK, c0, len, masks)                                              \
                CK_PRAGMA(omp simd)                                                                    \
                for (int i = 0; i < len; ++i)                                                          \
                    lbm_collide_cell<ODD, LBM_NB_MASK, 1>(c0 + i, LBM_CELL_ARGS(px, pxy, N), masks[i],          \
                                                          LBM_CHUNK_VALUES(i));                        \
            }                                                                                          \
        }
#endif
    // one loop per parity, so the parity is a compile-time constant inside the (vectorised) x loop
    if (parity & 1) {
        LBM_COLLIDE_LOOP(1)
    } else {
        LBM_COLLIDE_LOOP(0)
    }
#undef LBM_COLLIDE_LOOP
#undef LBM_CELL_ARGS
#if !CK_ON_GPU
#undef LBM_PHI_CHUNK
#undef LBM_CHUNK_BUFFERS
#undef LBM_CHUNK_VALUES
#endif
}
