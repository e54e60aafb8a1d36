// FNV-1a, 64 bits (Fowler, Noll and Vo): a hash of a byte stream, for keys
// and checksums that must be the same on every machine (Simulator's scene
// key; the golden rollout test). Integers and doubles go in as their 8
// bytes, least significant first; a string as its length, then its bytes.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>

namespace lockstep {

class Fnv1a {
 public:
  void add(std::uint64_t x) {
    for (int k = 0; k < 8; ++k) add_byte(static_cast<unsigned char>(x >> (8 * k)));
  }
  void add(double x) {
    std::uint64_t bits;
    std::memcpy(&bits, &x, sizeof bits);
    add(bits);
  }
  void add(const std::string& s) {
    add(static_cast<std::uint64_t>(s.size()));
    for (unsigned char c : s) add_byte(c);
  }
  std::uint64_t value() const { return hash_; }

 private:
  void add_byte(unsigned char c) {
    hash_ ^= c;
    hash_ *= 0x100000001b3u;  // the FNV prime
  }
  std::uint64_t hash_ = 0xcbf29ce484222325u;  // the FNV offset basis
};

}  // namespace lockstep
