// Lattice constants shared by every LBM kernel: D3Q27 (flow) and D3Q7 (phase field).
// Mirrors couplekit/lattice.py (tests/test_lattice.py checks they agree).
// Order: rest first, then opposite pairs adjacent (opposite of q is q+1 for odd q, q-1 for even q > 0):
// faces (+x,-x), (+y,-y), (+z,-z); 12 edges; 8 corners.
#pragma once
#include "common.cuh"

#define Q27 27
#define Q7 7
#define CS2 (1.f / 3.f)    // D3Q27 speed of sound squared
#define CS2_7 (1.f / 4.f)  // D3Q7 with weights W7

CONSTANT int CX27[27] = {0, 1, -1, 0, 0, 0, 0, 1, -1, 1, -1, 0, 0, 1, -1, 1, -1, 0, 0, 1, -1, 1, -1, 1, -1, -1, 1};
CONSTANT int CY27[27] = {0, 0, 0, 1, -1, 0, 0, 1, -1, 0, 0, 1, -1, -1, 1, 0, 0, 1, -1, 1, -1, 1, -1, -1, 1, 1, -1};
CONSTANT int CZ27[27] = {0, 0, 0, 0, 0, 1, -1, 0, 0, 1, -1, 1, -1, 0, 0, -1, 1, -1, 1, 1, -1, -1, 1, 1, -1, 1, -1};
CONSTANT float W27[27] = {8.f / 27, 2.f / 27, 2.f / 27, 2.f / 27, 2.f / 27, 2.f / 27, 2.f / 27, 1.f / 54, 1.f / 54, 1.f / 54, 1.f / 54, 1.f / 54, 1.f / 54, 1.f / 54, 1.f / 54, 1.f / 54, 1.f / 54, 1.f / 54, 1.f / 54, 1.f / 216, 1.f / 216, 1.f / 216, 1.f / 216, 1.f / 216, 1.f / 216, 1.f / 216, 1.f / 216};
CONSTANT int CX7[7] = {0, 1, -1, 0, 0, 0, 0};
CONSTANT int CY7[7] = {0, 0, 0, 1, -1, 0, 0};
CONSTANT int CZ7[7] = {0, 0, 0, 0, 0, 1, -1};
CONSTANT float W7[7] = {1.f / 4, 1.f / 8, 1.f / 8, 1.f / 8, 1.f / 8, 1.f / 8, 1.f / 8};

DEVICE int opposite_dir(int q) { return q == 0 ? 0 : ((q & 1) ? q + 1 : q - 1); }
