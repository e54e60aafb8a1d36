// Argument checks that throw std::invalid_argument with a message naming
// what is wrong. The message may be a string or a function returning one;
// a function is called only when the check fails, so the per-copy setters
// (run for every copy at every reset) build no strings while their
// arguments are good.
#pragma once

#include <stdexcept>
#include <type_traits>

namespace lockstep {

template <class Message>
inline void require(bool ok, Message&& message) {
  if (ok) return;
  if constexpr (std::is_invocable_v<Message>) throw std::invalid_argument(message());
  else throw std::invalid_argument(message);
}

}  // namespace lockstep
