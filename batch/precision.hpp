// The floating-point precision a batch computes in, chosen at run time.
#pragma once

#include <cmath>
#include <limits>
#include <string>

namespace lockstep {

enum class Precision { Float, Double };
const char* precision_name(Precision precision);

// Finite in the arithmetic the copies run in: a float simulator would store
// a double beyond float's range (3.4e38) as inf.
inline bool finite_in(Precision p, double x) {
  return std::isfinite(x) && (p == Precision::Double || std::abs(x) <= std::numeric_limits<float>::max());
}

// What finite_in asks, for messages.
inline std::string finite_word(Precision p) {
  return p == Precision::Float ? "finite (in float, within 3.4e38)" : "finite";
}

}  // namespace lockstep
