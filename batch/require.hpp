// Argument checks that throw std::invalid_argument with a message naming
// what is wrong. The message may be a string or a function returning one;
// a function is called only when the check fails, so the per-copy setters
// (run for every copy at every reset) build no strings while their
// arguments are good.
#pragma once

#include <charconv>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace lockstep {

template <class Message>
inline void require(bool ok, Message&& message) {
  if (ok) return;
  if constexpr (std::is_invocable_v<Message>) throw std::invalid_argument(message());
  else throw std::invalid_argument(message);
}

// A number as the shortest text that reads back as it, for messages
// (-1e-09, not std::to_string's -0.000000).
inline std::string number_text(double x) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, x);
  return std::string(buffer, result.ptr);
}

// A copy index in [0, copies), or std::out_of_range naming the class and
// function asked: "VecEnv::fault: copy index 9 outside [0, 4)".
inline void require_copy_index(int copy, int copies, const char* type, const char* function) {
  if (copy >= 0 && copy < copies) return;
  throw std::out_of_range(std::string(type) + "::" + function + ": copy index " + std::to_string(copy) +
                          " outside [0, " + std::to_string(copies) + ")");
}

}  // namespace lockstep
