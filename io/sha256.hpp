// SHA-256 (FIPS 180-4) of a byte string or a file, as lowercase hex: the
// model hash a rollout file records (compare with `sha256sum MODEL.urdf`).
#pragma once

#include <string>

namespace lockstep {

std::string sha256_hex(const std::string& bytes);
// Throws std::runtime_error naming the file when it cannot be read.
std::string sha256_file(const std::string& path);

}  // namespace lockstep
