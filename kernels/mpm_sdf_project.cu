// Particles deeper than `depth` in the grid SDF collider pulled back to that depth after G2P (position only): a
// particle where the trilinear interpolation d of the node SDF is below -depth moves along the normal to
// d = -depth, x_p -= (d + depth) grad d / |grad d|.
// Spec: couplekit/sand/reference.py ReferenceOps.sdf_project.
//
// Why: the grid's boundary condition (mpm_grid.cu) removes the inward normal velocity at nodes with d <= 0, the
// layer half a cell inside a face on a grid line, but never moves a particle back out; a particle up to a cell
// inside still takes part of its velocity from the free layer above it. On a flat face where the sand comes to
// rest that stops at ~0.24 dx, but sand spilling over a box obstacle's edge ratcheted into it (the inside nodes
// below the edge take the side face's normal, so downward motion there is only resisted by friction): 368
// particles inside, up to 1.1 dx deep after 2 s, and still growing (session 20; tests/sand/test_sdf_project.py).
// The velocity is left as the grid gave it: also removing its inward part took away the basal friction of a pile.
// Why a depth (SandSolver passes a quarter cell): sand resting on a flat face settles ~0.24 dx inside it, as on
// the domain walls, and the basal friction it feels comes with that; put on the surface itself it slid more (the
// far half of Fig. 5's bailey, on a floor slab, slumped 1 cm more at dx = 0.025 m). Only the ratchet beyond is
// taken back.
//
// Nodes sit at ((i + 1/2) dx, ...) (couplekit.sand.boundaries.node_positions); a particle outside the node
// lattice's hull, or not finite, is left as it is (the comparisons fail for NaN). n = particles.
#include "common.cuh"

KERNEL void mpm_sdf_project(const long long n, float* RESTRICT x /* size: 3 * n */,
                            const float* RESTRICT sdf /* size: nx * ny * nz */, const int nx, const int ny,
                            const int nz, const float dx, const float depth) {
    const float inv_dx = 1.f / dx;
    FOR_EACH(p, n) {
        const float gx = x[p] * inv_dx - 0.5f, gy = x[n + p] * inv_dx - 0.5f, gz = x[2 * n + p] * inv_dx - 0.5f;
        if (!(gx >= 0.f && gx <= (float)(nx - 1) && gy >= 0.f && gy <= (float)(ny - 1) && gz >= 0.f &&
              gz <= (float)(nz - 1)))
            continue;
        const int i = gx < (float)(nx - 1) ? (int)gx : nx - 2;  // the cell of nodes around the particle
        const int j = gy < (float)(ny - 1) ? (int)gy : ny - 2;
        const int k = gz < (float)(nz - 1) ? (int)gz : nz - 2;
        const float fx = gx - (float)i, fy = gy - (float)j, fz = gz - (float)k;
        const long long sy = nx, sz = (long long)nx * ny;
        const long long c = i + sy * j + sz * k;
        const float d000 = sdf[c], d100 = sdf[c + 1], d010 = sdf[c + sy], d110 = sdf[c + sy + 1];
        const float d001 = sdf[c + sz], d101 = sdf[c + sz + 1], d011 = sdf[c + sz + sy], d111 = sdf[c + sz + sy + 1];
        // trilinear value and its gradient (per grid unit)
        const float a00 = d000 + fx * (d100 - d000), a10 = d010 + fx * (d110 - d010);
        const float a01 = d001 + fx * (d101 - d001), a11 = d011 + fx * (d111 - d011);
        const float b0 = a00 + fy * (a10 - a00), b1 = a01 + fy * (a11 - a01);
        const float d = b0 + fz * (b1 - b0);
        if (!(d < -depth)) continue;
        const float ex00 = d100 - d000, ex10 = d110 - d010, ex01 = d101 - d001, ex11 = d111 - d011;
        const float ey0 = a10 - a00, ey1 = a11 - a01;
        const float ddx = (ex00 + fy * (ex10 - ex00)) + fz * ((ex01 + fy * (ex11 - ex01)) - (ex00 + fy * (ex10 - ex00)));
        const float ddy = ey0 + fz * (ey1 - ey0);
        const float ddz = b1 - b0;
        const float len = sqrtf(ddx * ddx + ddy * ddy + ddz * ddz);
        if (!(len > 0.f)) continue;
        const float s = -(d + depth) / len;  // d in metres; the unit normal is the gradient over its length
        x[p] += s * ddx;
        x[n + p] += s * ddy;
        x[2 * n + p] += s * ddz;
    }
}
