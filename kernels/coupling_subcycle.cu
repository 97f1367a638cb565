// Multi-rate coupling: what the sand sees of the fluid between two fluid steps, and the running sums that hand
// the substeps' exchange back to the fluid once (schedulers/subcycle.py).  Spec: couplekit/coupling/reference.py
// ReferenceOps.fluid_view / accumulate.
//
// coupling_fluid_view: the fluid velocity a sand substep exchanges momentum with (lattice units, padded layout):
//   u_s = u0 + theta (u0 - u_prev) + A / (rho eps_f)                   on interior FLUID cells (flags == 0)
//   u_s = u0                                                            elsewhere (ghosts, solid cells)
// u0 = sum_j f_j c_j at the start of the fluid step (the lockstep exchange velocity), u_prev the same one step
// earlier, theta = s / k the substep's start time in fluid steps (theta = 0: the fluid held across the
// substeps; theta > 0 with u_prev: linear in time through the last two fluid states, extrapolated because the
// fluid's next state is computed after the sand's substeps).  A = -sum_{s' < s} J_s' is the drag impulse the
// earlier substeps took from the fluid (the running sum of the fluid force, lattice momentum per cell), and
// rho eps_f the fluid mass of the cell (rho from phi as in the drag, eps_f the substep's porosity): the fluid
// velocity as it will be once the fluid receives that impulse.  Without that term a strong drag pulls the
// sand to the held fluid velocity substep after substep (the implicit exchange of each substep assumes the
// fluid moves too) and, handed the summed impulse, the fluid overshoots and the slip reverses.
//
// coupling_accumulate: acc = w x (first = 1) or acc + w x: the substeps' average (w = 1/k) of the fluid
// force, porosity and sand grid velocity, and the sum (w = 1) of the absorbed water.  w x with w = 1 and
// first = 1 is x bitwise, so one substep is the lockstep step.
// variants: CK_TWO_PHASE=0,1
#include "common.cuh"

#ifndef CK_TWO_PHASE
#define CK_TWO_PHASE 1
#endif

// n = nx * ny * nz; the padded arrays are (nx + 2) * (ny + 2) * (nz + 2) per component.  u_prev is read only
// when extrapolate = 1 (else pass a 1-element array); phi only with CK_TWO_PHASE.  The ghosts of u_seen are not
// written (the exchange reads interior cells only).
KERNEL void coupling_fluid_view(const long long n, const float* RESTRICT u0 /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
                                const float* RESTRICT u_prev /* size >= 1 */,
                                const float* RESTRICT impulse /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */,
                                const float* RESTRICT phi /* size >= 1 */,
                                const float* RESTRICT eps_fluid /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                const unsigned char* RESTRICT flags /* size: (nx + 2) * (ny + 2) * (nz + 2) */,
                                float* RESTRICT u_seen /* size: 3 * (nx + 2) * (ny + 2) * (nz + 2) */, const int nx,
                                const int ny, const int nz, const int extrapolate, const float theta,
                                const float rho_h, const float rho_l) {
    const int PX = nx + 2;
    const long long PXY = (long long)PX * (ny + 2);
    const long long N = PXY * (nz + 2);
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        const long long c = (x + 1) + PX * (long long)(y + 1) + PXY * (z + 1);
        float ux = u0[c], uy = u0[N + c], uz = u0[2 * N + c];
        if (flags[c] == 0) {
#if CK_TWO_PHASE
            const float rho = rho_l + (rho_h - rho_l) * ck_fminf(ck_fmaxf(phi[c], 0.f), 1.f);
#else
            const float rho = rho_h;
#endif
            const float inv_mf = 1.f / (rho * eps_fluid[c]);
            if (extrapolate) {
                ux += theta * (ux - u_prev[c]);
                uy += theta * (uy - u_prev[N + c]);
                uz += theta * (uz - u_prev[2 * N + c]);
            }
            ux += impulse[c] * inv_mf;
            uy += impulse[N + c] * inv_mf;
            uz += impulse[2 * N + c] * inv_mf;
        }
        u_seen[c] = ux;
        u_seen[N + c] = uy;
        u_seen[2 * N + c] = uz;
    }
#if !CK_TWO_PHASE
    (void)phi;
    (void)rho_l;
#endif
}

// n: number of floats.
KERNEL void coupling_accumulate(const long long n, float* RESTRICT acc /* size: n */, const float* RESTRICT x /* size: n */,
                                const float w, const int first) {
    if (first) {
        FOR_EACH(i, n) { acc[i] = w * x[i]; }
    } else {
        FOR_EACH(i, n) { acc[i] += w * x[i]; }
    }
}
