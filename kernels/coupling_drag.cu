// Sand-fluid momentum exchange on the collocated grid (paper 000 Sec. 4.3): buoyancy (Eq. 31) and the drag
// of Gao et al. 2018 integrated implicitly per node in closed form (notes/mpm-method.md Sec. 3.4), equal and
// opposite on sand and fluid.  Spec: couplekit/coupling/reference.py ReferenceOps.drag_buoyancy.
//
// Called between the MPM P2G and the MPM grid update.  One pass over the interior cells, eps_s of Eq. 25 from
// the P2G's node volume (coupling_sand_fraction, as coupling_fractions computes it; not stored):
//   rho     = rho_l + (rho_h - rho_l) clamp(phi)             (lattice density; rho_h when CK_TWO_PHASE=0)
//   F_b     = -V_cell eps_s rho g                           (Eq. 31, SI newtons) -> dt F_b added to (mv)_i
//   v*      = ((mv)_i + dt F_b) / m_i + dt g                 (sand velocity after the explicit forces, SI;
//                                                             the elastic impulse is already in (mv)_i)
//   in lattice units (V_cell = 1, mass_scale = kg per lattice mass, velocity_scale = m/s per lattice
//   velocity, dt_lattice = dt / LBM step, 1 in lockstep):
//   m_s     = m_i / mass_scale,   m_f = rho eps_f            (eps_f: the porosity the fluid solver uses)
//   u*      = u, the fluid's CURRENT macroscopic velocity: sum_j f_j c_j of the populations as they are now
//             (after the last streaming, before this step's collision, without any force shift).  Not the
//             velocity field a Guo-forced collision leaves behind (m + a/2 before streaming): with that stale
//             value a strong drag over a sand block drives the LBM unstable within ~50 steps (measured with
//             couplekit.fluid.solver at c = 1e3, also with half of the last force added back), while with
//             sum_j f_j c_j it stays stable up to c = 1e6 (tests/coupling/test_coupling_coupler.py).
//   A       = pi (3 eps_s / (4 pi))^(2/3)                    (ball of the node's sand volume, Sec. 4.3)
//           or 1.5 eps_s / d_grain  when grain_diameter > 0  (total cross-section of grains of diameter d,
//                                                             notes Sec. 3.2 option)
//   beta    = 1/2 c (1 - eps_s)^(-chi) rho A,  drag force w (u - v) with w = beta |u - v|
//   backward Euler on the exchange, implicit in |u - v| too:   r' = r* / (1 + k |r'|),  k = dt beta (1/m_s + 1/m_f)
//           |r'| = 2 |r*| / (1 + sqrt(1 + 4 k |r*|)),  r* = u* - v*
//   J       = m_s m_f / (m_s + m_f) (r* - r')               (impulse on the sand; the fluid gets -J)
// u and force may be one buffer (SandFluidCoupler.fold_sand_velocity: Σ f c lives in the force's buffer): each
// cell reads its own u and nothing else of it before it writes its own force, so neither is RESTRICT.
// Outputs: (mv)_i += J + dt F_b (SI; the grid update then divides by m_i and adds dt g), force = -J / dt_lattice
// (lattice force density for the fluid's forcing term).  Nodes without sand mass, or whose cell is not a FLUID
// cell (flags != 0), get force = 0 and keep their momentum: there is no fluid there to exchange momentum with (a reaction written
// into an obstacle cell would be lost).  Sand spilling (B-spline weights) into obstacle cells therefore
// feels no buoyancy there; keep fluid obstacles and sand colliders on the same cells.
// variants: CK_TWO_PHASE=0,1
#include "common.cuh"
#include "coupling_fields.cuh"

#ifndef CK_TWO_PHASE
#define CK_TWO_PHASE 1
#endif

#define CK_PI_F 3.14159265358979f

// 1 - |r'|/|r*| of the quadratic implicit drag, = 4 k r / (1 + sqrt(1 + 4 k r))^2 (no cancellation)
DEVICE float coupling_drag_fraction(const float kr) {
    const float q = 1.f + sqrtf(1.f + 4.f * kr);
    return 4.f * kr / (q * q);
}

// the outputs of node i (padded cell c): force = -J / dt_lattice for the fluid, (mv)_i += J + dt F_b for the sand
// (force may be u's buffer: not RESTRICT, coupling_drag_buoyancy)
DEVICE void coupling_drag_store(float* force, float* RESTRICT grid_mv, const long long c, const long long i,
                                const long long N, const long long ncell, const float Jx, const float Jy,
                                const float Jz, const float fbx, const float fby, const float fbz,
                                const float inv_dtl, const float momentum_scale, const float dt) {
    force[c] = -Jx * inv_dtl;
    force[N + c] = -Jy * inv_dtl;
    force[2 * N + c] = -Jz * inv_dtl;
    grid_mv[i] += Jx * momentum_scale + dt * fbx;
    grid_mv[ncell + i] += Jy * momentum_scale + dt * fby;
    grid_mv[2 * ncell + i] += Jz * momentum_scale + dt * fbz;
}

// one interior cell (x, y, z) of coupling_drag_buoyancy (both paths)
DEVICE void coupling_drag_cell(
    const int x, const int y, const int z, const float* RESTRICT grid_m, float* RESTRICT grid_mv,
    float* force, const float* u, const float* RESTRICT phi, const float* RESTRICT grid_vol,
    const float* RESTRICT eps_fluid, const unsigned char* RESTRICT flags, const int nx, const int ny,
    const int nz, const float dt, const float dt_lattice, const float gx, const float gy, const float gz,
    const float mass_scale, const float velocity_scale, const float rho_h, const float rho_l, const float c_drag,
    const float chi, const float grain_diameter, const float inv_cell_volume, const float eps_max) {
    const long long ncell = (long long)nx * ny * nz;
    const int PX = nx + 2;
    const long long PXY = (long long)PX * (ny + 2);
    const long long N = PXY * (nz + 2);
    const float momentum_scale = mass_scale * velocity_scale;
    const long long i = x + (long long)nx * (y + (long long)ny * z);
    const long long c = (x + 1) + PX * (long long)(y + 1) + PXY * (z + 1);
    const float m = grid_m[i];
    float fbx = 0.f, fby = 0.f, fbz = 0.f, Jx = 0.f, Jy = 0.f, Jz = 0.f;
    if (m > 0.f && flags[c] == 0) {
#if CK_TWO_PHASE
        const float rho = rho_l + (rho_h - rho_l) * coupling_water_phase(phi[c]);
#else
        const float rho = rho_h;
#endif
        const float es = coupling_sand_fraction(grid_vol[i], inv_cell_volume, eps_max);  // Eq. 25
        const float ef = eps_fluid[c];
        // buoyancy, Eq. 31: -V_cell eps_s rho g in newtons (rho mass_scale = rho_SI V_cell)
        const float b = -es * rho * mass_scale;
        fbx = b * gx;
        fby = b * gy;
        fbz = b * gz;
        // sand velocity after the explicit forces (SI), then lattice units
        const float inv_m = 1.f / m;
        const float inv_vs = 1.f / velocity_scale;
        const float vx = ((grid_mv[i] + dt * fbx) * inv_m + dt * gx) * inv_vs;
        const float vy = ((grid_mv[ncell + i] + dt * fby) * inv_m + dt * gy) * inv_vs;
        const float vz = ((grid_mv[2 * ncell + i] + dt * fbz) * inv_m + dt * gz) * inv_vs;
        const float ms = m / mass_scale;
        const float mf = rho * ef;
        const float rx = u[c] - vx, ry = u[N + c] - vy, rz = u[2 * N + c] - vz;
        const float rn = sqrtf(rx * rx + ry * ry + rz * rz);
        const float area = grain_diameter > 0.f ? 1.5f * es / grain_diameter
                                                : CK_PI_F * powf(3.f * es / (4.f * CK_PI_F), 2.f / 3.f);
        const float beta = 0.5f * c_drag * powf(ck_fmaxf(1.f - es, 1e-6f), -chi) * rho * area;
        const float k = dt_lattice * beta * (1.f / ms + 1.f / mf);
        const float s = (ms * mf / (ms + mf)) * coupling_drag_fraction(k * rn);
        Jx = s * rx;
        Jy = s * ry;
        Jz = s * rz;
    }
    coupling_drag_store(force, grid_mv, c, i, N, ncell, Jx, Jy, Jz, fbx, fby, fbz, 1.f / dt_lattice, momentum_scale,
                        dt);
}

KERNEL void coupling_drag_buoyancy(
    const long long n, const float* RESTRICT grid_m /* size: nx * ny * nz */,
    float* RESTRICT grid_mv /* size: 3 * nx * ny * nz */,
    float* force /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
    const float* u /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */, const float* RESTRICT phi /* size >= 1 */,
    const float* RESTRICT grid_vol /* size: nx * ny * nz */,
    const float* RESTRICT eps_fluid /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
    const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */, const int nx, const int ny,
    const int nz, const float dt, const float dt_lattice, const float gx, const float gy, const float gz,
    const float mass_scale, const float velocity_scale, const float rho_h, const float rho_l, const float c_drag,
    const float chi, const float grain_diameter, const float inv_cell_volume, const float eps_max) {
    const long long ncell = (long long)nx * ny * nz;
    const int PX = nx + 2;
    const long long PXY = (long long)PX * (ny + 2);
    const long long N = PXY * (nz + 2);
    const float momentum_scale = mass_scale * velocity_scale;
#define CPL_DRAG_ARGS                                                                                      \
    x, y, z, grid_m, grid_mv, force, u, phi, grid_vol, eps_fluid, flags, nx, ny, nz, dt, dt_lattice, gx, gy, gz, \
        mass_scale, velocity_scale, rho_h, rho_l, c_drag, chi, grain_diameter, inv_cell_volume, eps_max
#if CK_ON_GPU
    FOR_EACH_CELL(x, y, z, nx, ny, nz) coupling_drag_cell(CPL_DRAG_ARGS);
#else
    // host: rows in parallel.  A row whose nodes hold no sand mass (most rows: the sand fills a small part of
    // the grid) takes the empty cell's arithmetic as a vector loop (J = F_b = 0: force -0 and mv + 0, what the
    // per-cell code writes there); a row with sand the per-cell code (its branch, sqrtf and powf run scalar)
    CK_PRAGMA(omp parallel for collapse(2) schedule(static))
    for (int z = 0; z < nz; ++z)
        for (int y = 0; y < ny; ++y) {
            const long long i0 = (long long)nx * (y + (long long)ny * z);
            if (ck_any_differs(grid_m + i0, nx, 0.f)) {
                for (int x = 0; x < nx; ++x) coupling_drag_cell(CPL_DRAG_ARGS);
                continue;
            }
            const long long c0 = 1 + PX * (long long)(y + 1) + PXY * (z + 1);
            const float inv_dtl = 1.f / dt_lattice;
            CK_PRAGMA(omp simd)
            for (int x = 0; x < nx; ++x)
                coupling_drag_store(force, grid_mv, c0 + x, i0 + x, N, ncell, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, inv_dtl,
                                    momentum_scale, dt);
        }
    (void)n;
#endif
#undef CPL_DRAG_ARGS
#if !CK_TWO_PHASE
    (void)phi;
    (void)rho_l;
#endif
}
