// The floating-point precision a batch computes in, chosen at run time.
#pragma once

namespace lockstep {

enum class Precision { Float, Double };
const char* precision_name(Precision precision);

}  // namespace lockstep
