// MPM grid update (paper 000 Eqs. 26, 29; notes Secs. 1.3-1.4): node velocity from momentum, explicit
// forces, then boundary conditions.  One thread per node; n = nx*ny*nz.
//
//   v_i = (mv)_i / m_i + dt g      (m_i > 0; empty nodes get v = 0)
//
// The elastic force is already in (mv)_i (fused P2G), and so are the coupling's forces: the drag impulse and
// dt times the buoyancy (Eq. 26), added by coupling_drag_buoyancy between P2G and this update.  No node
// force field is kept (12 B per cell less; issue 14's memory budget).
//
// In place: grid_v may be the same array as grid_mv (SandSolver allocates one array for both): each node's
// three momentum components are read before its velocity is written, and no other node's are read, so the
// two pointers carry no RESTRICT.
//
// Boundary conditions act on the velocity relative to the boundary, v_rel = v - v_obj(x_i), with n the
// outward normal of the solid (pointing into the sand):
//   mode 0 sticky:    v_rel = 0
//   mode 1 slip:      v_rel -= (v_rel . n) n
//   mode 2 separate:  if v_rel . n < 0: remove the normal part and reduce the tangential speed by
//                     mu |v_rel . n| (Coulomb friction, clamped at 0 = static friction)
// Domain walls: nodes within `bound` layers of each face of the grid, static, one mode/friction per face.
// Colliders (table of MPM_COLLIDER_STRIDE floats each, see couplekit/sand/boundaries.py): analytic
// half-spaces, spheres, boxes and capped cylinders with linear and angular velocity, optionally inverted
// (solid outside, for containers); a node is in contact when the signed distance is <= 0.
// Grid SDF collider: a node field of signed distance (has_sdf = 1), normal by central differences,
// parameters sdf_params = (mode, friction, vx, vy, vz); with node_friction = 1 the friction is read per node
// from sdf_friction (several obstacles in one SDF, each with its own friction: the nearest one's at a node),
// otherwise sdf_params[1] holds everywhere (sdf_friction is then a dummy of one element).
#include "common.cuh"
#include "mpm_loops.cuh"

#define MPM_COLLIDER_STRIDE 16
#define MPM_BC_STICKY 0
#define MPM_BC_SLIP 1
#define MPM_BC_SEPARATE 2

DEVICE void mpm_apply_bc(float& vx, float& vy, float& vz, const float nx_, const float ny_, const float nz_,
                         const int mode, const float mu, const float ox, const float oy, const float oz) {
    float rx = vx - ox, ry = vy - oy, rz = vz - oz;
    const float vn = rx * nx_ + ry * ny_ + rz * nz_;
    if (mode == MPM_BC_STICKY) {
        rx = ry = rz = 0.f;
    } else if (mode == MPM_BC_SLIP || vn < 0.f) {
        rx -= vn * nx_;
        ry -= vn * ny_;
        rz -= vn * nz_;
        if (mode == MPM_BC_SEPARATE && mu > 0.f) {
            const float vt = sqrtf(rx * rx + ry * ry + rz * rz);
            const float k = vt > 0.f ? fmaxf(0.f, 1.f + mu * vn / vt) : 0.f;
            rx *= k;
            ry *= k;
            rz *= k;
        }
    }
    vx = ox + rx;
    vy = oy + ry;
    vz = oz + rz;
}

// Signed distance (negative inside the solid) and outward unit normal of collider c at point (px, py, pz).
DEVICE float mpm_collider_sdf(const float* RESTRICT c, const float px, const float py, const float pz, float& gx,
                              float& gy, float& gz) {
    const int type = (int)c[0];
    const float rx = px - c[4], ry = py - c[5], rz = pz - c[6];
    float phi;
    if (type == 0) {  // half-space: solid where (x - c) . n < 0; params = unit normal
        gx = c[7];
        gy = c[8];
        gz = c[9];
        phi = rx * gx + ry * gy + rz * gz;
    } else if (type == 1) {  // sphere: params[0] = radius
        const float r = sqrtf(rx * rx + ry * ry + rz * rz);
        const float inv = r > 0.f ? 1.f / r : 0.f;
        gx = r > 0.f ? rx * inv : 0.f;
        gy = r > 0.f ? ry * inv : 0.f;
        gz = r > 0.f ? rz * inv : 1.f;
        phi = r - c[7];
    } else if (type == 2) {  // axis-aligned box: params = half extents
        const float qx = fabsf(rx) - c[7], qy = fabsf(ry) - c[8], qz = fabsf(rz) - c[9];
        const float mx = fmaxf(qx, 0.f), my = fmaxf(qy, 0.f), mz = fmaxf(qz, 0.f);
        const float out = sqrtf(mx * mx + my * my + mz * mz);
        const float in = fminf(fmaxf(qx, fmaxf(qy, qz)), 0.f);
        phi = out + in;
        const float sx = rx >= 0.f ? 1.f : -1.f, sy = ry >= 0.f ? 1.f : -1.f, sz = rz >= 0.f ? 1.f : -1.f;
        if (out > 0.f) {
            gx = sx * mx / out;
            gy = sy * my / out;
            gz = sz * mz / out;
        } else {  // inside: the face of least penetration
            const bool ax = qx >= qy && qx >= qz, ay = !ax && qy >= qz;
            gx = ax ? sx : 0.f;
            gy = ay ? sy : 0.f;
            gz = (!ax && !ay) ? sz : 0.f;
        }
    } else {  // capped cylinder along y: params = (radius, half height)
        const float rr = sqrtf(rx * rx + rz * rz);
        const float qr = rr - c[7], qh = fabsf(ry) - c[8];
        const float mr = fmaxf(qr, 0.f), mh = fmaxf(qh, 0.f);
        const float out = sqrtf(mr * mr + mh * mh);
        phi = out + fminf(fmaxf(qr, qh), 0.f);
        const float inv = rr > 0.f ? 1.f / rr : 0.f;
        const float ux = rr > 0.f ? rx * inv : 1.f, uz = rr > 0.f ? rz * inv : 0.f;
        const float sy = ry >= 0.f ? 1.f : -1.f;
        if (out > 0.f) {
            gx = ux * mr / out;
            gz = uz * mr / out;
            gy = sy * mh / out;
        } else {
            const bool radial = qr >= qh;
            gx = radial ? ux : 0.f;
            gz = radial ? uz : 0.f;
            gy = radial ? 0.f : sy;
        }
    }
    if (c[3] != 0.f) {  // inverted: solid outside
        phi = -phi;
        gx = -gx;
        gy = -gy;
        gz = -gz;
    }
    return phi;
}

KERNEL void mpm_grid_update(const long long n, const float* RESTRICT grid_m, const float* grid_mv,
                            float* grid_v, const int nx, const int ny,
                            const int nz, const float dx, const float dt, const float gx, const float gy,
                            const float gz, const int bound, const float* RESTRICT walls,
                            const float* RESTRICT colliders, const int ncolliders, const float* RESTRICT sdf,
                            const int has_sdf, const float* RESTRICT sdf_params,
                            const float* RESTRICT sdf_friction, const int node_friction) {
    const long long ncell = (long long)nx * ny * nz;
    MPM_FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        const long long i = x + (long long)nx * (y + (long long)ny * z);
        const float m = grid_m[i];
        float vx = 0.f, vy = 0.f, vz = 0.f;
        if (m > 0.f) {
            const float inv_m = 1.f / m;
            vx = grid_mv[i] * inv_m + dt * gx;
            vy = grid_mv[ncell + i] * inv_m + dt * gy;
            vz = grid_mv[2 * ncell + i] * inv_m + dt * gz;
            // domain walls: walls[2*face] = mode, walls[2*face+1] = friction; faces -x,+x,-y,+y,-z,+z
            if (x < bound) mpm_apply_bc(vx, vy, vz, 1.f, 0.f, 0.f, (int)walls[0], walls[1], 0.f, 0.f, 0.f);
            if (x >= nx - bound) mpm_apply_bc(vx, vy, vz, -1.f, 0.f, 0.f, (int)walls[2], walls[3], 0.f, 0.f, 0.f);
            if (y < bound) mpm_apply_bc(vx, vy, vz, 0.f, 1.f, 0.f, (int)walls[4], walls[5], 0.f, 0.f, 0.f);
            if (y >= ny - bound) mpm_apply_bc(vx, vy, vz, 0.f, -1.f, 0.f, (int)walls[6], walls[7], 0.f, 0.f, 0.f);
            if (z < bound) mpm_apply_bc(vx, vy, vz, 0.f, 0.f, 1.f, (int)walls[8], walls[9], 0.f, 0.f, 0.f);
            if (z >= nz - bound) mpm_apply_bc(vx, vy, vz, 0.f, 0.f, -1.f, (int)walls[10], walls[11], 0.f, 0.f, 0.f);
            const float px = (x + 0.5f) * dx, py = (y + 0.5f) * dx, pz = (z + 0.5f) * dx;
            for (int k = 0; k < ncolliders; ++k) {
                const float* RESTRICT c = colliders + MPM_COLLIDER_STRIDE * k;
                float nxc, nyc, nzc;
                const float phi = mpm_collider_sdf(c, px, py, pz, nxc, nyc, nzc);
                if (phi <= 0.f) {
                    const float rx = px - c[4], ry = py - c[5], rz = pz - c[6];
                    // v_obj = v_lin + omega x (x - centre)
                    const float ox = c[10] + c[14] * rz - c[15] * ry;
                    const float oy = c[11] + c[15] * rx - c[13] * rz;
                    const float oz = c[12] + c[13] * ry - c[14] * rx;
                    mpm_apply_bc(vx, vy, vz, nxc, nyc, nzc, (int)c[1], c[2], ox, oy, oz);
                }
            }
            if (has_sdf && sdf[i] <= 0.f) {
                const int xm = x > 0 ? x - 1 : x, xp = x < nx - 1 ? x + 1 : x;
                const int ym = y > 0 ? y - 1 : y, yp = y < ny - 1 ? y + 1 : y;
                const int zm = z > 0 ? z - 1 : z, zp = z < nz - 1 ? z + 1 : z;
                const long long row = (long long)nx * (y + (long long)ny * z);
                float sx = sdf[xp + row] - sdf[xm + row];
                float sy = sdf[x + (long long)nx * (yp + (long long)ny * z)] - sdf[x + (long long)nx * (ym + (long long)ny * z)];
                float sz = sdf[x + (long long)nx * (y + (long long)ny * zp)] - sdf[x + (long long)nx * (y + (long long)ny * zm)];
                const float len = sqrtf(sx * sx + sy * sy + sz * sz);
                if (len > 0.f) {
                    sx /= len;
                    sy /= len;
                    sz /= len;
                    const float mu = node_friction ? sdf_friction[i] : sdf_params[1];
                    mpm_apply_bc(vx, vy, vz, sx, sy, sz, (int)sdf_params[0], mu, sdf_params[2], sdf_params[3],
                                 sdf_params[4]);
                }
            }
        }
        grid_v[i] = vx;
        grid_v[ncell + i] = vy;
        grid_v[2 * ncell + i] = vz;
    }
}
