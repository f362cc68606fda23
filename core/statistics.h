// Small statistics shared by the solvers, the evaluation and the tests.
#pragma once

#include <algorithm>
#include <vector>

namespace headforge {

// The median of `values` (the upper one for an even count); 0 for none.
inline double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

}  // namespace headforge
