#include "capture/curves.h"

#include <algorithm>
#include <cmath>

#include "capture/procedural.h"

namespace headforge {
namespace {

constexpr double kPi = 3.14159265358979323846;

double Smooth(double t) { return t * t * (3 - 2 * t); }

// A raised-cosine pulse of width `width` centred at 0.
double Pulse(double t, double width) {
  if (std::abs(t) >= width / 2) return 0.0;
  return 0.5 * (1.0 + std::cos(2.0 * kPi * t / width));
}

double Keys(const CurveTerm& c, double t) {
  if (c.times.empty()) return 0.0;
  if (t <= c.times.front()) return c.values.front();
  if (t >= c.times.back()) return c.values.back();
  const auto it = std::upper_bound(c.times.begin(), c.times.end(), t);
  const size_t i = static_cast<size_t>(it - c.times.begin()) - 1;
  const double f = (t - c.times[i]) / (c.times[i + 1] - c.times[i]);
  return c.values[i] + (c.values[i + 1] - c.values[i]) * Smooth(f);
}

double Talking(const CurveTerm& c, double t) {
  // Syllables at jittered onsets, each a pulse with a random peak.
  const double spacing = 1.0 / c.rate;
  const int64_t k0 = static_cast<int64_t>(std::floor(t / spacing)) - 2;
  double v = 0.0;
  for (int64_t k = k0; k <= k0 + 4; ++k) {
    if (HashUnit(c.seed, k, 7) < 0.15) continue;  // pauses between words
    const double centre = (k + 0.5 + 0.3 * (HashUnit(c.seed, k, 1) - 0.5)) * spacing;
    const double peak = 0.4 + 0.6 * HashUnit(c.seed, k, 2);
    v = std::max(v, peak * Pulse(t - centre, 0.9 * spacing));
  }
  return c.amplitude * v;
}

double Blink(const CurveTerm& c, double t) {
  const int64_t k0 = static_cast<int64_t>(std::floor(t / c.period)) - 1;
  double v = 0.0;
  for (int64_t k = k0; k <= k0 + 2; ++k) {
    const double centre = (k + 0.5 + 0.4 * (HashUnit(c.seed, k, 3) - 0.5)) * c.period;
    v = std::max(v, Pulse(t - centre, c.duration));
  }
  return c.amplitude * v;
}

}  // namespace

Status CheckCurveTerm(const CurveTerm& c) {
  if (c.type == "constant" || c.type == "noise") return Status::Ok();
  if (c.type == "sine") {
    if (!(c.period > 0)) return Status::InvalidArgument("sine curve needs period > 0");
    return Status::Ok();
  }
  if (c.type == "keys") {
    if (c.times.empty() || c.times.size() != c.values.size())
      return Status::InvalidArgument("keys curve needs as many times as values (at least one)");
    if (!std::is_sorted(c.times.begin(), c.times.end()) ||
        std::adjacent_find(c.times.begin(), c.times.end()) != c.times.end())
      return Status::InvalidArgument("keys curve times must increase");
    return Status::Ok();
  }
  if (c.type == "talking") {
    if (!(c.rate > 0)) return Status::InvalidArgument("talking curve needs rate > 0");
    return Status::Ok();
  }
  if (c.type == "blink") {
    if (!(c.period > 0) || !(c.duration > 0) || c.duration >= c.period)
      return Status::InvalidArgument("blink curve needs 0 < duration < period");
    return Status::Ok();
  }
  return Status::InvalidArgument("unknown curve type '" + c.type +
                                 "' (constant, sine, keys, noise, talking, blink)");
}

double Curve::Evaluate(double t) const {
  double v = 0.0;
  for (const auto& c : terms) {
    if (c.type == "constant") v += c.value;
    else if (c.type == "sine") v += c.offset + c.amplitude * std::sin(2.0 * kPi * (t / c.period + c.phase));
    else if (c.type == "keys") v += Keys(c, t);
    else if (c.type == "noise") v += c.amplitude * ValueNoise1(t / c.timescale, c.seed);
    else if (c.type == "talking") v += Talking(c, t);
    else if (c.type == "blink") v += Blink(c, t);
  }
  return v;
}

}  // namespace headforge
