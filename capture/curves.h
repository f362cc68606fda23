// Time curves that animate a simulated scene: head rotation and translation,
// blendshape weights, camera shake, exposure drift.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/status.h"

namespace headforge {

// One curve term; a Curve sums its terms.
struct CurveTerm {
  // "constant" (value), "sine" (amplitude, period, phase in periods, offset),
  // "keys" (times, values; smooth between keys, held outside),
  // "noise" (amplitude, timescale: smooth random, seeded),
  // "talking" (amplitude, rate: syllable pulses per second, seeded),
  // "blink" (period, duration, amplitude: eyelid pulses with jittered timing, seeded).
  std::string type = "constant";
  double value = 0.0, amplitude = 1.0, period = 1.0, phase = 0.0, offset = 0.0;
  double timescale = 1.0, rate = 4.0, duration = 0.15;
  std::vector<double> times, values;
  uint64_t seed = 0;
};

struct Curve {
  std::vector<CurveTerm> terms;
  double Evaluate(double t) const;
  bool empty() const { return terms.empty(); }
};

// Checks a term's type and parameters.
Status CheckCurveTerm(const CurveTerm& term);

}  // namespace headforge
