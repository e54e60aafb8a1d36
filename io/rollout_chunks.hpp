// Whole chunks of a compressed step dataset, filtered as HDF5's shuffle and
// deflate filters filter them (H5Pset_shuffle, then H5Pset_deflate), so
// that the rollout writer can hand them to H5Dwrite_chunk as they are.
// HDF5 runs its filters on the one thread that holds its lock; with many
// stepping threads the data come faster than one thread deflates them
// (docs/rollout_files.md), so the chunks are filtered on the TBB threads.
#pragma once

#include <cstddef>
#include <vector>

namespace lockstep::rollout_chunks {

// HDF5's shuffle filter: of n elements of `element` bytes each, byte b of
// every element together, b = 0, ..., element - 1 (out[b n + j] =
// in[j element + b]); bytes past the last whole element are copied as they
// are. One-byte elements, or a single element, are copied unchanged.
void shuffle(const unsigned char* in, std::size_t bytes, std::size_t element, unsigned char* out);

// One chunk: `bytes` bytes at `in`, elements of `element` bytes. `packed`
// holds the filtered chunk, its first `packed_bytes`; both buffers are kept
// from one block to the next.
struct Chunk {
  const unsigned char* in = nullptr;
  std::size_t bytes = 0;
  std::size_t element = 1;
  std::vector<unsigned char> shuffled;
  std::vector<unsigned char> packed;
  std::size_t packed_bytes = 0;
};

// Filters chunks[0, count) on the TBB threads: shuffle, then zlib's
// compress2 at `level` (1-9), the zlib stream HDF5's deflate filter
// writes. Throws std::runtime_error with zlib's message if it fails.
void filter_chunks(std::vector<Chunk>& chunks, std::size_t count, int level);

}  // namespace lockstep::rollout_chunks
