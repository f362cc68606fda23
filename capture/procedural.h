// Deterministic procedural noise for the simulator's textures and motion:
// lattice value noise in 1-3 dimensions and fractal sums of it. Every function
// is a pure function of its inputs and seed.
#pragma once

#include <cstdint>

namespace headforge {

// A 64-bit integer hash (splitmix64 finaliser) and one mapped to [0, 1).
uint64_t Hash64(uint64_t x);
double HashUnit(uint64_t seed, int64_t a, int64_t b = 0, int64_t c = 0);

// Smooth value noise in [-1, 1] with unit lattice spacing.
double ValueNoise1(double x, uint64_t seed);
double ValueNoise3(double x, double y, double z, uint64_t seed);
// Fractal sum of `octaves` octaves (each twice the frequency, half the
// amplitude), normalised to about [-1, 1].
double Fbm3(double x, double y, double z, int octaves, uint64_t seed);

}  // namespace headforge
