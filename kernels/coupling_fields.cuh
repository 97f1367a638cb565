// The coupling's per-node quantities that more than one coupling kernel needs, defined once: kernels that need
// them recompute them from the fields they come from instead of reading a stored copy (paper 000 Sec. 4;
// spec: couplekit/coupling/reference.py).
//
//   coupling_sand_fraction   eps_s = min(eps_max, V_i / V_cell)          (Eq. 25; coupling_fractions, the drag)
//   coupling_water_phase     phi clamped to [0, 1] (the pores' water fraction; single-phase water: 1)
//   coupling_water           water = R' + eps_f phi  (Eq. 59 summand; R' = 0 without retention: the text after
//                            Eq. 28)                                 (coupling_fractions, the moisture G2P)
//   coupling_source_index    the MPM node a padded fluid cell takes its values from: its own, or for a ghost the
//                            periodic image / the nearest interior node (coupling_fractions, the sand's
//                            pressure terms)
#pragma once

// interior source index (0-based) of padded coordinate X (0 .. n + 1) along an axis of n interior cells
DEVICE int coupling_source_index(const int X, const int n, const int periodic) {
    if (X < 1) return periodic ? n - 1 : 0;
    if (X > n) return periodic ? 0 : n - 1;
    return X - 1;
}

DEVICE float coupling_sand_fraction(const float volume, const float inv_cell_volume, const float eps_max) {
    return ck_fminf(eps_max, volume * inv_cell_volume);
}

DEVICE float coupling_water_phase(const float phi) { return ck_fminf(ck_fmaxf(phi, 0.f), 1.f); }

DEVICE float coupling_water(const float bound, const float eps_fluid, const float phase) {
    return bound + eps_fluid * phase;
}
