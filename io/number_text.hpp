// One number written as text, as the URDF and mesh readers take it.
#pragma once

#include <charconv>
#include <string>
#include <string_view>

namespace lockstep {

// Parses the whole of `word` (no surrounding whitespace) as a number; a
// leading '+' is allowed (std::from_chars takes none). Returns the reason
// when it is not one ("not a number", "number out of range"), else "".
inline std::string parse_number(std::string_view word, double& out) {
  if (!word.empty() && word.front() == '+') word.remove_prefix(1);
  const auto [end, ec] = std::from_chars(word.data(), word.data() + word.size(), out);
  if (ec == std::errc::result_out_of_range) return "number out of range";
  if (ec != std::errc() || end != word.data() + word.size() || word.empty()) return "not a number";
  return "";
}

}  // namespace lockstep
