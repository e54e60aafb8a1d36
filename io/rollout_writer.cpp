// RolloutWriter: the caller fills a block of steps while a background thread
// writes the previous block to the SWMR file (double buffering).
//
//   caller:  frame() ... commit() ... commit()  -- block full --> hand over
//   thread:  extend every dataset by the block, write it; flush when
//            flush_seconds have passed since the last flush
//
// Blocks end where the step count is a multiple of buffer_steps (by default
// the chunk length), so full blocks write whole chunks; commit() also hands
// over a partial block once flush_seconds have passed (a slow producer).
// After a failed write nothing more reaches the file: it keeps what its last
// successful flush wrote.
#include "io/rollout_chunks.hpp"
#include "io/rollout_file.hpp"
#include "io/rollout_hdf5.hpp"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <set>
#include <thread>

#include <unistd.h>

namespace lockstep {

using namespace rollout_hdf5;

namespace {

using Clock = std::chrono::steady_clock;

constexpr std::size_t kAutomaticChunkBytes = std::size_t{1} << 20;  // chunk_steps = 0: ~1 MiB chunks
constexpr std::size_t kMaxChunkBytes = std::size_t{4} << 20;        // unless a single frame is larger
constexpr std::size_t kMaxBufferBytes = std::size_t{1} << 30;       // the two in-memory blocks together
constexpr double kMaxFlushSeconds = 1e6;

// Argument checks ------------------------------------------------------------

std::size_t element_count(const std::vector<std::size_t>& shape) {
  std::size_t count = 1;
  for (std::size_t extent : shape) count *= extent;
  return count;
}

void check_name(const std::string& path, const std::string& kind, const std::string& name,
                std::set<std::string>& seen) {
  if (name.empty()) throw std::invalid_argument(path + ": a " + kind + " has an empty name");
  if (name.find('/') != std::string::npos || name == ".")
    throw std::invalid_argument(path + ": " + kind + " name '" + name + "' contains '/' or is '.'");
  if (!seen.insert(name).second) throw std::invalid_argument(path + ": duplicate " + kind + " name '" + name + "'");
}

void check_attributes(const std::string& path, const std::vector<Attribute>& attributes) {
  std::set<std::string> seen;
  for (const Attribute& attribute : attributes) {
    check_name(path, "attribute", attribute.name, seen);
    for (const char* reserved : {kFormatAttribute, kFormatVersionAttribute, kCompleteAttribute})
      if (attribute.name == reserved)
        throw std::invalid_argument(path + ": attribute name '" + attribute.name + "' is reserved");
  }
}

void check_arguments(const std::string& path, const std::vector<StepDataset>& steps,
                     const std::vector<StaticDataset>& statics, const std::vector<Attribute>& attributes,
                     const RolloutFileOptions& options) {
  if (steps.empty()) throw std::invalid_argument(path + ": a rollout file needs at least one step dataset");
  std::set<std::string> names;
  for (const StepDataset& dataset : steps) {
    check_name(path, "dataset", dataset.name, names);
  }
  for (const StaticDataset& dataset : statics) {
    check_name(path, "dataset", dataset.name, names);
    const std::size_t bytes = element_count(dataset.shape) * element_size(dataset.type);
    if (dataset.data.size() != bytes)
      throw std::invalid_argument(path + ": static dataset '" + dataset.name + "' has " +
                                  std::to_string(dataset.data.size()) + " bytes of data, its shape and type need " +
                                  std::to_string(bytes));
  }
  check_attributes(path, attributes);
  if (options.chunk_steps < 0) throw std::invalid_argument(path + ": chunk_steps must be >= 0");
  if (options.buffer_steps < 0) throw std::invalid_argument(path + ": buffer_steps must be >= 0");
  if (options.compression < 0 || options.compression > 9)
    throw std::invalid_argument(path + ": compression must be a gzip level in 0..9, got " +
                                std::to_string(options.compression));
  if (!(options.flush_seconds >= 0 && options.flush_seconds <= kMaxFlushSeconds))
    throw std::invalid_argument(path + ": flush_seconds must be in [0, 1e6]");
}

// Creating the file ------------------------------------------------------------

std::vector<hsize_t> to_hsize(const std::vector<std::size_t>& shape) { return {shape.begin(), shape.end()}; }

// Creates `file_name`; messages name `path`.
Handle create_file(const std::string& file_name, const std::string& path) {
  const std::string what = "cannot create the file";
  // Datasets list in creation order (RolloutReader::datasets()).
  const Handle creation = checked_handle(H5Pcreate(H5P_FILE_CREATE), H5Pclose, path, what);
  check(H5Pset_link_creation_order(creation.get(), H5P_CRT_ORDER_TRACKED | H5P_CRT_ORDER_INDEXED), path, what);
  // SWMR needs the latest file format.
  const Handle access = checked_handle(H5Pcreate(H5P_FILE_ACCESS), H5Pclose, path, what);
  check(H5Pset_libver_bounds(access.get(), H5F_LIBVER_LATEST, H5F_LIBVER_LATEST), path, what);
  return checked_handle(H5Fcreate(file_name.c_str(), H5F_ACC_TRUNC, creation.get(), access.get()), H5Fclose, path,
                        what);
}

void describe(hid_t dataset, const std::string& description, const std::string& path) {
  if (!description.empty()) write_attribute(dataset, kDescriptionAttribute, description, path);
}

void write_static_dataset(hid_t file, const StaticDataset& dataset, const std::string& path) {
  const std::string what = "cannot write static dataset '" + dataset.name + "'";
  const std::vector<hsize_t> dims = to_hsize(dataset.shape);
  const hid_t space_id = dims.empty() ? H5Screate(H5S_SCALAR)
                                      : H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr);
  const Handle space = checked_handle(space_id, H5Sclose, path, what);
  const Handle handle =
      checked_handle(H5Dcreate2(file, dataset.name.c_str(), file_type(dataset.type), space.get(), H5P_DEFAULT,
                                H5P_DEFAULT, H5P_DEFAULT),
                     H5Dclose, path, what);
  if (!dataset.data.empty())  // a zero extent: nothing to write
    check(H5Dwrite(handle.get(), memory_type(dataset.type), H5S_ALL, H5S_ALL, H5P_DEFAULT, dataset.data.data()), path,
          what);
  describe(handle.get(), dataset.description, path);
}

// One step dataset as the writer thread sees it.
struct StepSlot {
  std::string name;
  Handle dataset;
  hid_t memory_type = H5I_INVALID_HID;
  std::vector<hsize_t> extent;  // [T, shape...], T = steps written
  std::vector<hsize_t> start;   // where the next block goes: [T, 0...]
  std::vector<hsize_t> count;   // the block: [steps, shape...]
  hsize_t chunk_steps = 0;      // steps per chunk
};

// Chunks of [chunk_steps, shape...], unlimited along T, optional shuffle + gzip.
// A zero extent (a model without actions) is unlimited too, with chunks of
// 1 along it: HDF5 wants chunks of at least 1 within a fixed maximum.
StepSlot create_step_dataset(hid_t file, const StepDataset& dataset, std::size_t chunk_steps, int compression,
                             const std::string& path) {
  const std::string what = "cannot create step dataset '" + dataset.name + "'";
  StepSlot slot;
  slot.name = dataset.name;
  slot.memory_type = memory_type(dataset.type);
  slot.chunk_steps = chunk_steps;
  slot.extent = to_hsize(dataset.shape);
  slot.extent.insert(slot.extent.begin(), 0);
  slot.start.assign(slot.extent.size(), 0);
  slot.count = slot.extent;
  const int rank = static_cast<int>(slot.extent.size());

  std::vector<hsize_t> max_extent = slot.extent, chunk = slot.extent;
  max_extent[0] = H5S_UNLIMITED;
  chunk[0] = chunk_steps;
  for (int d = 1; d < rank; ++d)
    if (chunk[d] == 0) chunk[d] = 1, max_extent[d] = H5S_UNLIMITED;
  const Handle space = checked_handle(H5Screate_simple(rank, slot.extent.data(), max_extent.data()), H5Sclose,
                                      path, what);
  const Handle creation = checked_handle(H5Pcreate(H5P_DATASET_CREATE), H5Pclose, path, what);
  check(H5Pset_chunk(creation.get(), rank, chunk.data()), path, what);
  if (compression > 0) {
    check(H5Pset_shuffle(creation.get()), path, what);
    check(H5Pset_deflate(creation.get(), static_cast<unsigned>(compression)), path, what);
  }
  slot.dataset = checked_handle(H5Dcreate2(file, dataset.name.c_str(), file_type(dataset.type), space.get(),
                                           H5P_DEFAULT, creation.get(), H5P_DEFAULT),
                                H5Dclose, path, what);
  describe(slot.dataset.get(), dataset.description, path);
  return slot;
}

// Sets "complete" = 1 and the final attributes of a closed file. A reader
// that keeps the live file open (SWMR, as docs/rollout_files.md shows) holds
// HDF5's shared file lock, which refuses a read-write open; the writer, the
// file's only writer, then opens it without the lock. SWMR readers check
// the metadata they read and read it again when it changes under them.
void mark_complete(const std::string& path, const std::vector<Attribute>& final_attributes) {
  const Hdf5Lock lock = lock_hdf5();
  const std::string what = "cannot reopen the file to mark it complete";
  const Handle access = checked_handle(H5Pcreate(H5P_FILE_ACCESS), H5Pclose, path, what);
  check(H5Pset_libver_bounds(access.get(), H5F_LIBVER_LATEST, H5F_LIBVER_LATEST), path, what);
  hid_t id = H5Fopen(path.c_str(), H5F_ACC_RDWR, access.get());
  if (id < 0) {
    H5Eclear2(H5E_DEFAULT);
    check(H5Pset_file_locking(access.get(), false, true), path, what);
    id = H5Fopen(path.c_str(), H5F_ACC_RDWR, access.get());
  }
  Handle file = checked_handle(id, H5Fclose, path, what);
  try {
    for (const Attribute& attribute : final_attributes)
      write_attribute(file.get(), attribute.name, attribute.value, path);
    write_attribute(file.get(), kCompleteAttribute, std::int64_t{1}, path);  // last: only a finished file says 1
    check(H5Fflush(file.get(), H5F_SCOPE_LOCAL), path, "cannot write the final attributes");
  } catch (const RolloutFileError&) {
    discard_further_writes(file.get());  // so that closing cannot fail
    throw;
  }
  check(file.reset(), path, "cannot close the file after marking it complete");
}

}  // namespace

struct RolloutWriter::Impl {
  // Steps handed to the writer thread together: per step dataset,
  // buffer_steps frames (capacity) of which `steps` are filled.
  struct Block {
    std::vector<std::vector<unsigned char>> frames;
    int steps = 0;
  };

  // Fixed at construction.
  const std::string path;
  const std::vector<StepDataset> definitions;
  std::vector<std::size_t> frame_bytes;
  int buffer_steps = 0;
  int compression_level = 0;  // of the step datasets, 0: raw
  Clock::duration flush_interval{};

  // HDF5 objects: the constructor, then the writer thread, then close().
  Handle file;
  std::vector<StepSlot> slots;

  // The caller's side.
  Block blocks[2];
  int filling = 0;  // blocks[filling] is the caller's; blocks[1 - filling] the thread's
  Clock::time_point last_hand_over;
  double seconds_waiting = 0;
  bool closed = false;
  std::atomic<std::int64_t> committed{0};

  // The writer thread's side.
  std::int64_t written = 0;
  std::vector<rollout_chunks::Chunk> chunks;  // a block's whole chunks, filtered here (write_block)
  std::vector<int> first_chunk;               // (slots) a dataset's first in `chunks`, -1: through H5Dwrite
  Clock::time_point last_flush;
  std::atomic<std::int64_t> flushed{0};

  // Shared, under `mutex`.
  std::mutex mutex;
  std::condition_variable wake;
  bool block_pending = false;  // blocks[1 - filling] is waiting for or being written by the thread
  bool stopping = false;
  std::string error;                // the thread's first failure
  std::atomic<bool> failed{false};  // error is set (read without the mutex by commit())
  std::thread thread;

  Impl(const std::string& path_, std::vector<StepDataset> steps, const std::vector<StaticDataset>& statics,
       const std::vector<Attribute>& attributes, const RolloutFileOptions& options)
      : path(path_), definitions(std::move(steps)) {
    check_arguments(path, definitions, statics, attributes, options);
    for (const StepDataset& dataset : definitions)
      frame_bytes.push_back(element_count(dataset.shape) * element_size(dataset.type));
    const std::size_t largest_frame =
        std::max<std::size_t>(1, *std::max_element(frame_bytes.begin(), frame_bytes.end()));
    const std::size_t chunk_steps = options.chunk_steps > 0
                                        ? static_cast<std::size_t>(options.chunk_steps)
                                        : std::max<std::size_t>(1, kAutomaticChunkBytes / largest_frame);
    // by default a block is the largest dataset's chunk (its steps within kMaxChunkBytes)
    const std::size_t largest_chunk = std::clamp<std::size_t>(kMaxChunkBytes / largest_frame, 1, chunk_steps);
    buffer_steps = options.buffer_steps > 0 ? options.buffer_steps : static_cast<int>(largest_chunk);
    std::size_t step_bytes = 0;
    for (std::size_t bytes : frame_bytes) step_bytes += bytes;
    if (2.0 * buffer_steps * static_cast<double>(step_bytes) > static_cast<double>(kMaxBufferBytes))
      throw std::invalid_argument(path + ": buffer_steps " + std::to_string(buffer_steps) + " of " +
                                  std::to_string(step_bytes) + " bytes each, in two blocks, would hold " +
                                  std::to_string(2 * static_cast<std::size_t>(buffer_steps) * step_bytes) +
                                  " bytes in memory; at most " + std::to_string(kMaxBufferBytes) +
                                  " (give fewer buffer_steps)");
    compression_level = options.compression;
    flush_interval = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(options.flush_seconds));
    for (Block& block : blocks)
      for (std::size_t bytes : frame_bytes) block.frames.emplace_back(bytes * buffer_steps);

    create(statics, attributes, chunk_steps, options.compression);
    last_hand_over = last_flush = Clock::now();
    thread = std::thread([this] { run(); });
  }

  // The file with its attributes, static and (empty) step datasets, in SWMR
  // mode. It is set up as "<path>.creating" and renamed to `path` once
  // flushed: whenever the process is killed, `path` is the previous file or
  // one that opens.
  void create(const std::vector<StaticDataset>& statics, const std::vector<Attribute>& attributes,
              std::size_t chunk_steps, int compression) {
    const Hdf5Lock lock = lock_hdf5();
    std::error_code ignored;
    if (std::filesystem::is_directory(path, ignored))
      throw RolloutFileError(path + ": is a directory; the rollout file needs a file name");
    // the finished file is renamed over `path`: only a regular file may go
    const std::filesystem::file_status there = std::filesystem::symlink_status(path, ignored);
    if (std::filesystem::exists(there) && !std::filesystem::is_regular_file(there))
      throw RolloutFileError(path + ": is not a regular file (a link, device, FIFO or socket), which the rollout file "
                                    "would replace; give the path of a file");
    // renamed over, a file is replaced by whoever may write its folder: a
    // file its user may not write is refused, as writing it would be
    if (std::filesystem::exists(there) && ::access(path.c_str(), W_OK) != 0)
      throw RolloutFileError(path + ": cannot replace it: " + std::strerror(errno));
    const std::string creating = path + ".creating";
    // a leftover "<path>.creating" goes first: were it a link, creating the
    // file through it would truncate the link's target
    std::filesystem::remove(creating, ignored);
    file = create_file(creating, path);
    try {
      fill_new_file(statics, attributes, chunk_steps, compression);
    } catch (const RolloutFileError&) {
      discard_further_writes(file.get());  // so that closing cannot fail
      slots.clear();
      file.reset();
      std::remove(creating.c_str());
      throw;
    }
    if (std::rename(creating.c_str(), path.c_str()) != 0) {  // the file is whole: close it as usual
      const int rename_error = errno;
      slots.clear();
      file.reset();
      std::remove(creating.c_str());
      throw RolloutFileError(path + ": cannot rename " + creating + " to it: " + std::strerror(rename_error));
    }
  }

  void fill_new_file(const std::vector<StaticDataset>& statics, const std::vector<Attribute>& attributes,
                     std::size_t chunk_steps, int compression) {
    write_attribute(file.get(), kFormatAttribute, std::string(kFormatName), path);
    write_attribute(file.get(), kFormatVersionAttribute, kFormatVersion, path);
    write_attribute(file.get(), kCompleteAttribute, std::int64_t{0}, path);
    for (const Attribute& attribute : attributes) write_attribute(file.get(), attribute.name, attribute.value, path);
    for (const StaticDataset& dataset : statics) write_static_dataset(file.get(), dataset, path);
    for (std::size_t i = 0; i < definitions.size(); ++i) {
      // Each dataset's chunk stays within kMaxChunkBytes.
      const std::size_t steps = std::clamp<std::size_t>(kMaxChunkBytes / std::max<std::size_t>(1, frame_bytes[i]), 1,
                                                        chunk_steps);
      slots.push_back(create_step_dataset(file.get(), definitions[i], steps, compression, path));
    }
    check(H5Fstart_swmr_write(file.get()), path, "cannot start SWMR writing");
  }

  // The caller's side ----------------------------------------------------------

  void check_open(const char* operation) const {
    if (closed) throw RolloutFileError(path + ": " + operation + " after close()");
  }

  void check_index(int dataset) const {
    if (dataset < 0 || dataset >= static_cast<int>(definitions.size()))
      throw std::invalid_argument(path + ": step dataset index " + std::to_string(dataset) + " is out of range [0, " +
                                  std::to_string(definitions.size()) + ")");
  }

  void rethrow_thread_error() {
    if (!failed.load(std::memory_order_acquire)) return;
    const std::lock_guard<std::mutex> lock(mutex);
    throw RolloutFileError(error);
  }

  // Gives blocks[filling] to the thread (which is idle) and starts the other.
  void pass_block() {
    block_pending = true;
    filling = 1 - filling;
    blocks[filling].steps = 0;
    last_hand_over = Clock::now();
    wake.notify_all();
  }

  // A full block: waits for the thread to finish the previous one.
  void hand_over() {
    std::unique_lock<std::mutex> lock(mutex);
    if (block_pending) {
      const Clock::time_point start = Clock::now();
      wake.wait(lock, [&] { return !block_pending; });
      seconds_waiting += std::chrono::duration<double>(Clock::now() - start).count();
    }
    pass_block();
  }

  // A partial block, only if the thread is idle.
  void hand_over_if_idle() {
    const std::lock_guard<std::mutex> lock(mutex);
    if (!block_pending) pass_block();
  }

  // Hands over the last steps, lets the thread write and flush them, joins it.
  void stop_thread() noexcept {
    {
      std::unique_lock<std::mutex> lock(mutex);
      wake.wait(lock, [&] { return !block_pending; });
      if (blocks[filling].steps > 0) pass_block();
      stopping = true;
      wake.notify_all();
    }
    thread.join();
    closed = true;
  }

  // Closes the datasets and the file; throws the thread's error, if any, or a failure to close.
  void close_file() {
    if (failed) {
      slots.clear();
      file.reset();
      rethrow_thread_error();
    }
    const Hdf5Lock lock = lock_hdf5();
    for (StepSlot& slot : slots) check(slot.dataset.reset(), path, "cannot close dataset '" + slot.name + "'");
    check(file.reset(), path, "cannot close the file");
  }

  // The writer thread ------------------------------------------------------------

  bool unflushed() const { return !failed && written > flushed; }

  void run() {
    std::unique_lock<std::mutex> lock(mutex);
    for (;;) {
      const auto ready = [&] { return block_pending || stopping; };
      if (unflushed())
        wake.wait_until(lock, last_flush + flush_interval, ready);
      else
        wake.wait(lock, ready);
      if (block_pending) {
        const Block& block = blocks[1 - filling];
        lock.unlock();
        guarded([&] { write_block(block); });
        lock.lock();
        block_pending = false;
        wake.notify_all();
      }
      const bool finishing = stopping && !block_pending;
      if (unflushed() && (finishing || Clock::now() - last_flush >= flush_interval)) {
        lock.unlock();
        guarded([&] { flush(); });
        lock.lock();
      }
      if (finishing) return;
    }
  }

  // Runs an HDF5 task of the thread; its failure is kept for the caller, and
  // after one nothing more is written.
  template <class Task> void guarded(Task&& task) {
    if (failed) return;
    try {
      task();
    } catch (const std::exception& e) {
      discard_further_writes(file.get());
      const std::lock_guard<std::mutex> lock(mutex);
      error = e.what();
      failed.store(true, std::memory_order_release);
    }
  }

  // Extends every step dataset by the block and writes it. With
  // compression, a dataset whose block is whole chunks has them filtered
  // on the TBB threads (rollout_chunks) and written as they are; the
  // others, and a last block that ends inside a chunk, go through
  // H5Dwrite, which filters them here.
  void write_block(const Block& block) {
    const auto steps = static_cast<hsize_t>(block.steps);
    const std::string at_steps =
        " at steps [" + std::to_string(written) + ", " + std::to_string(written + block.steps) + ")";
    const std::size_t count = plan_chunks(block);
    try {
      rollout_chunks::filter_chunks(chunks, count, compression_level);
    } catch (const std::runtime_error& e) {  // zlib's, not HDF5's: no HDF5 error stack (nor its lock) to read
      throw RolloutFileError(path + ": cannot compress the step datasets" + at_steps + ": " + e.what());
    }
    const Hdf5Lock lock = lock_hdf5();
    for (std::size_t i = 0; i < slots.size(); ++i) {
      StepSlot& slot = slots[i];
      const auto failure = [&](const char* action) {
        fail(path, std::string("cannot ") + action + " step dataset '" + slot.name + "'" + at_steps);
      };
      slot.extent[0] = static_cast<hsize_t>(written) + steps;
      slot.start[0] = static_cast<hsize_t>(written);
      slot.count[0] = steps;
      if (H5Dset_extent(slot.dataset.get(), slot.extent.data()) < 0) failure("extend");
      if (frame_bytes[i] == 0) continue;  // a zero extent: the steps hold nothing
      if (first_chunk[i] >= 0) {
        std::vector<hsize_t> offset = slot.start;
        for (hsize_t c = 0; c < steps / slot.chunk_steps; ++c) {
          const rollout_chunks::Chunk& chunk = chunks[static_cast<std::size_t>(first_chunk[i]) + c];
          offset[0] = slot.start[0] + c * slot.chunk_steps;
          if (H5Dwrite_chunk(slot.dataset.get(), H5P_DEFAULT, 0, offset.data(), chunk.packed_bytes,
                             chunk.packed.data()) < 0)
            failure("write");
        }
        continue;
      }
      const Handle file_space(H5Dget_space(slot.dataset.get()), H5Sclose);
      const int rank = static_cast<int>(slot.count.size());
      const Handle memory_space(H5Screate_simple(rank, slot.count.data(), nullptr), H5Sclose);
      if (!file_space || !memory_space ||
          H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, slot.start.data(), nullptr, slot.count.data(),
                              nullptr) < 0 ||
          H5Dwrite(slot.dataset.get(), slot.memory_type, memory_space.get(), file_space.get(), H5P_DEFAULT,
                   block.frames[i].data()) < 0)
        failure("write");
    }
    written += block.steps;
  }

  // The whole chunks of the block that write_block filters itself, into
  // chunks[0, count): with compression, those of every dataset whose block
  // starts and ends on its chunks' bounds. Returns count.
  std::size_t plan_chunks(const Block& block) {
    const auto steps = static_cast<hsize_t>(block.steps);
    first_chunk.assign(slots.size(), -1);
    std::size_t count = 0;
    for (std::size_t i = 0; i < slots.size() && compression_level > 0; ++i) {
      const StepSlot& slot = slots[i];
      if (frame_bytes[i] == 0 || static_cast<hsize_t>(written) % slot.chunk_steps != 0 ||
          steps % slot.chunk_steps != 0)
        continue;
      first_chunk[i] = static_cast<int>(count);
      const std::size_t chunk_bytes = slot.chunk_steps * frame_bytes[i];
      for (hsize_t c = 0; c < steps / slot.chunk_steps; ++c, ++count) {
        if (chunks.size() <= count) chunks.emplace_back();
        chunks[count].in = block.frames[i].data() + c * chunk_bytes;
        chunks[count].bytes = chunk_bytes;
        chunks[count].element = element_size(definitions[i].type);
      }
    }
    return count;
  }

  // Everything written so far reaches the file: readers see it, and a killed
  // writer leaves it there. In SWMR mode HDF5 keeps chunks in memory until a
  // flush, and H5Fflush goes on to write the metadata (the new extents) when
  // writing the chunks failed; H5Dflush stops first. So each dataset is
  // flushed on its own, its chunks before its extent, and then the file.
  void flush() {
    const Hdf5Lock lock = lock_hdf5();
    const auto failure = [&](const std::string& what) {
      fail(path, "cannot flush steps [" + std::to_string(flushed) + ", " + std::to_string(written) + ") of " + what);
    };
    for (const StepSlot& slot : slots)
      if (H5Dflush(slot.dataset.get()) < 0) failure("step dataset '" + slot.name + "'");
    if (H5Fflush(file.get(), H5F_SCOPE_LOCAL) < 0) failure("the file");
    flushed.store(written);
    last_flush = Clock::now();
  }
};

RolloutWriter::RolloutWriter(const std::string& path, std::vector<StepDataset> steps,
                             std::vector<StaticDataset> statics, std::vector<Attribute> attributes,
                             RolloutFileOptions options)
    : impl_(std::make_unique<Impl>(path, std::move(steps), statics, attributes, options)) {}

RolloutWriter::~RolloutWriter() {
  if (!impl_->closed) impl_->stop_thread();
  // impl_'s handles close the datasets and the file; errors are ignored.
}

void* RolloutWriter::frame(int dataset) {
  Impl& w = *impl_;
  w.check_open("frame()");
  w.check_index(dataset);
  Impl::Block& block = w.blocks[w.filling];
  return block.frames[dataset].data() + block.steps * w.frame_bytes[dataset];
}

void RolloutWriter::check_frame_type(int dataset, ElementType type) const {
  impl_->check_index(dataset);
  const StepDataset& definition = impl_->definitions[dataset];
  if (definition.type != type)
    throw std::invalid_argument(impl_->path + ": step dataset '" + definition.name + "' holds " +
                                element_type_name(definition.type) + ", not " + element_type_name(type));
}

void RolloutWriter::commit() {
  Impl& w = *impl_;
  w.check_open("commit()");
  w.rethrow_thread_error();
  ++w.blocks[w.filling].steps;
  const std::int64_t committed = w.committed.load(std::memory_order_relaxed) + 1;
  w.committed.store(committed, std::memory_order_relaxed);
  if (committed % w.buffer_steps == 0)
    w.hand_over();
  else if (Clock::now() - w.last_hand_over >= w.flush_interval)
    w.hand_over_if_idle();
}

void RolloutWriter::close(std::vector<Attribute> final_attributes) {
  Impl& w = *impl_;
  w.check_open("close()");
  check_attributes(w.path, final_attributes);
  w.stop_thread();
  w.close_file();
  try {
    mark_complete(w.path, final_attributes);
  } catch (const RolloutFileError& e) {
    // The reopened file's header may still say it is open for writing,
    // which readers refuse until h5clear (HDF5's tools) clears it.
    throw RolloutFileError(std::string(e.what()) + "; its " + std::to_string(w.flushed.load()) +
                           " steps are written, but the file stays marked incomplete and may be marked as open for "
                           "writing: `h5clear -s " + w.path + "` lets readers open it");
  }
}

void RolloutWriter::close_incomplete() {
  Impl& w = *impl_;
  w.check_open("close_incomplete()");
  w.stop_thread();
  w.close_file();
}

std::int64_t RolloutWriter::steps_committed() const { return impl_->committed.load(); }
std::int64_t RolloutWriter::steps_flushed() const { return impl_->flushed.load(); }
double RolloutWriter::seconds_waiting() const { return impl_->seconds_waiting; }

}  // namespace lockstep
