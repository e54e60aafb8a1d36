#include "io/rollout_chunks.hpp"

#include <tbb/parallel_for.h>
#include <zlib.h>

#include <cstring>
#include <stdexcept>
#include <string>

namespace lockstep::rollout_chunks {

void shuffle(const unsigned char* in, std::size_t bytes, std::size_t element, unsigned char* out) {
  const std::size_t n = element > 0 ? bytes / element : 0;
  if (element <= 1 || n <= 1) {
    std::memcpy(out, in, bytes);
    return;
  }
  for (std::size_t b = 0; b < element; ++b)
    for (std::size_t j = 0; j < n; ++j) out[b * n + j] = in[j * element + b];
  std::memcpy(out + n * element, in + n * element, bytes - n * element);
}

void filter_chunks(std::vector<Chunk>& chunks, std::size_t count, int level) {
  tbb::parallel_for(std::size_t{0}, count, [&](std::size_t i) {
    Chunk& c = chunks[i];
    c.shuffled.resize(c.bytes);
    shuffle(c.in, c.bytes, c.element, c.shuffled.data());
    uLongf packed_bytes = compressBound(static_cast<uLong>(c.bytes));
    c.packed.resize(packed_bytes);
    const int status =
        compress2(c.packed.data(), &packed_bytes, c.shuffled.data(), static_cast<uLong>(c.bytes), level);
    if (status != Z_OK) throw std::runtime_error(std::string("zlib cannot compress a chunk: ") + zError(status));
    c.packed_bytes = packed_bytes;
  });
}

}  // namespace lockstep::rollout_chunks
