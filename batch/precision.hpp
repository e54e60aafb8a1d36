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

// The smallest normal number of the precision: the step flushes smaller
// ones (denormals) to zero.
inline double smallest_normal(Precision p) {
  return p == Precision::Float ? std::numeric_limits<float>::min() : std::numeric_limits<double>::min();
}

// A spring-damper of stiffness k and damping c taken implicitly over a
// step h is a solver row with compliance 1 / (h (k h + c)): finite in the
// precision only where h (k h + c) is zero (no spring) or a normal number,
// with room for the rounding of the three factors (4 times the smallest).
// Gains below that, a units mistake, would make the compliance infinite.
inline bool compliance_finite_in(Precision p, double h, double k, double c) {
  const double x = h * (k * h + c);
  return x == 0.0 || x >= 4 * smallest_normal(p);
}

}  // namespace lockstep
