#include "runtime/core/rng.h"

#include <cmath>

namespace poseforest::core {

double CounterRng::Normal(uint64_t index) const {
  // 1 - u keeps the log argument in (0, 1].
  const double u1 = 1.0 - Uniform01(2 * index);
  const double u2 = Uniform01(2 * index + 1);
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
}

}  // namespace poseforest::core
