#include "capture/procedural.h"

#include <cmath>

namespace headforge {

uint64_t Hash64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

double HashUnit(uint64_t seed, int64_t a, int64_t b, int64_t c) {
  uint64_t h = Hash64(seed);
  h = Hash64(h ^ static_cast<uint64_t>(a));
  h = Hash64(h ^ (static_cast<uint64_t>(b) * 0x632be59bd9b4e019ULL));
  h = Hash64(h ^ (static_cast<uint64_t>(c) * 0x85157af5ULL));
  return (h >> 11) * (1.0 / 9007199254740992.0);
}

namespace {
double Fade(double t) { return t * t * t * (t * (t * 6 - 15) + 10); }
double Lerp(double a, double b, double t) { return a + (b - a) * t; }
}  // namespace

double ValueNoise1(double x, uint64_t seed) {
  const double fx = std::floor(x);
  const int64_t i = static_cast<int64_t>(fx);
  const double t = Fade(x - fx);
  return 2.0 * Lerp(HashUnit(seed, i), HashUnit(seed, i + 1), t) - 1.0;
}

double ValueNoise3(double x, double y, double z, uint64_t seed) {
  const double fx = std::floor(x), fy = std::floor(y), fz = std::floor(z);
  const int64_t ix = static_cast<int64_t>(fx), iy = static_cast<int64_t>(fy), iz = static_cast<int64_t>(fz);
  const double tx = Fade(x - fx), ty = Fade(y - fy), tz = Fade(z - fz);
  auto h = [&](int dx, int dy, int dz) { return HashUnit(seed, ix + dx, iy + dy, iz + dz); };
  const double x00 = Lerp(h(0, 0, 0), h(1, 0, 0), tx), x10 = Lerp(h(0, 1, 0), h(1, 1, 0), tx);
  const double x01 = Lerp(h(0, 0, 1), h(1, 0, 1), tx), x11 = Lerp(h(0, 1, 1), h(1, 1, 1), tx);
  return 2.0 * Lerp(Lerp(x00, x10, ty), Lerp(x01, x11, ty), tz) - 1.0;
}

double Fbm3(double x, double y, double z, int octaves, uint64_t seed) {
  double sum = 0.0, amplitude = 1.0, total = 0.0, frequency = 1.0;
  for (int o = 0; o < octaves; ++o) {
    sum += amplitude * ValueNoise3(x * frequency, y * frequency, z * frequency, seed + o);
    total += amplitude;
    amplitude *= 0.5;
    frequency *= 2.0;
  }
  return sum / total;
}

}  // namespace headforge
