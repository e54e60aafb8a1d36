// Hints for a misspelled name: the known name a user most likely meant.
#pragma once

#include <string>
#include <vector>

namespace lockstep {

// Edit distance between a and b, ignoring case: insertions, deletions,
// substitutions and swaps of two neighbouring characters each count one
// (the optimal string alignment distance).
int name_distance(const std::string& a, const std::string& b);

// The candidate closest to `name` when it is close enough to be a slip: at
// most one edit per three characters of `name`, and at least one allowed.
// Empty when nothing is that close. Ties go to the first candidate in order.
std::string closest_name(const std::string& name, const std::vector<std::string>& candidates);

// " (did you mean \"X\"?)" with X = closest_name(name, candidates), or empty.
std::string did_you_mean(const std::string& name, const std::vector<std::string>& candidates);

}  // namespace lockstep
