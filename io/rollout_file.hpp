// Rollout files: HDF5 files of datasets shaped [T, ...] that grow by one step
// at a time, static datasets written once, and attributes. This layer is
// generic: the caller names the datasets (q, qd, reward, ...); nothing here
// knows of physics. File format and usage: docs/rollout_files.md.
//
// The writer hands whole blocks of steps to a background thread, which writes
// them with HDF5's single-writer/multiple-reader mode (SWMR) and flushes at
// least every `flush_seconds`: a writer killed at any moment leaves a file
// that opens and holds every step up to its last flush, marked incomplete.
//
// Every HDF5 call in this layer holds one process-wide lock (HDF5 may be
// built without thread safety), so writers and readers may be used from
// different threads.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <variant>
#include <vector>

namespace lockstep {

// The element types a dataset may hold; stored little-endian.
enum class ElementType { Float32, Float64, UInt8, Int32 };
std::size_t element_size(ElementType type);  // bytes: 4, 8, 1, 4
const char* element_type_name(ElementType type);  // "float32", "float64", "uint8", "int32"

// The ElementType of a C++ type: ElementTypeOf<float>::value == Float32.
template <class T> struct ElementTypeOf;
template <> struct ElementTypeOf<float> { static constexpr ElementType value = ElementType::Float32; };
template <> struct ElementTypeOf<double> { static constexpr ElementType value = ElementType::Float64; };
template <> struct ElementTypeOf<std::uint8_t> { static constexpr ElementType value = ElementType::UInt8; };
template <> struct ElementTypeOf<std::int32_t> { static constexpr ElementType value = ElementType::Int32; };

// A dataset that grows by one frame per step: stored shape [T, shape...]. An
// empty `shape` makes a frame of one element (stored shape [T]).
struct StepDataset {
  std::string name;
  ElementType type = ElementType::Float32;
  std::vector<std::size_t> shape;
  std::string description;  // the dataset's "description" attribute, when not empty
};

// A dataset written once at creation: shape `shape` (empty: a scalar), from
// `data`, product(shape) elements of `type` in C order, native byte order.
struct StaticDataset {
  std::string name;
  ElementType type = ElementType::Float64;
  std::vector<std::size_t> shape;
  std::vector<unsigned char> data;
  std::string description;
};

// An attribute's value: a string, an integer, a double, a list of strings or
// a list of doubles. Strings are stored as variable-length UTF-8 (h5py reads
// them as str).
using AttributeValue =
    std::variant<std::string, std::int64_t, double, std::vector<std::string>, std::vector<double>>;
struct Attribute {
  std::string name;
  AttributeValue value;
};

struct RolloutFileOptions {
  int chunk_steps = 0;         // steps per chunk along T; 0: a chunk of the largest dataset is about 1 MiB
  int compression = 0;         // gzip (deflate) level 0..9, with the shuffle filter; 0: none
  double flush_seconds = 1.0;  // the writer thread flushes at least this often (and at close)
  // steps per in-memory block handed to the writer thread; 0: the largest
  // dataset's chunk. Its two blocks may hold 1 GiB at most.
  int buffer_steps = 0;
};

// Thrown for every failure of the file: the message names the file's path and
// what failed, followed by HDF5's own error text when there is one.
class RolloutFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Writes one rollout file. The caller fills frame(i) of every step dataset,
// then commit()s the step; close() marks the file complete. Use from one
// thread (the writer runs its own background thread).
class RolloutWriter {
 public:
  // Creates the file `path` (replacing one there) with the static datasets,
  // the attributes, "format" = "lockstep rollout", "format_version" = 1 and
  // "complete" = 0, in SWMR mode, and starts the background thread. The file
  // is set up as "<path>.creating" and renamed to `path` once it is valid: a
  // process killed meanwhile leaves the previous `path`, if any.
  // Throws std::invalid_argument for bad arguments (empty or duplicate names,
  // a reserved attribute name, options out of range, static
  // data of the wrong size) and RolloutFileError when the file cannot be
  // created.
  RolloutWriter(const std::string& path, std::vector<StepDataset> steps, std::vector<StaticDataset> statics,
                std::vector<Attribute> attributes, RolloutFileOptions options = {});
  // Without close(): writes and flushes the steps committed so far and leaves
  // "complete" = 0. Never throws.
  ~RolloutWriter();
  RolloutWriter(const RolloutWriter&) = delete;
  RolloutWriter& operator=(const RolloutWriter&) = delete;

  // The next step's frame of step dataset `dataset` (its index in the
  // constructor's `steps`): product(shape) elements of its type, writable
  // until commit(). Throws std::invalid_argument for an index out of range,
  // RolloutFileError after close().
  void* frame(int dataset);
  // The same, checking that T is the dataset's element type (std::invalid_argument).
  template <class T> T* frame_as(int dataset) {
    check_frame_type(dataset, ElementTypeOf<T>::value);
    return static_cast<T*>(frame(dataset));
  }
  // Ends the step. A full block goes to the writer thread (double buffered:
  // this waits only while the thread is still writing the previous block);
  // so does a partial one when flush_seconds have passed since the last
  // hand-over and the thread is idle, so slow producers reach the disk too.
  // Rethrows, as RolloutFileError, an error the writer thread met (disk
  // full, ...); RolloutFileError after close().
  void commit();
  // Writes the remaining steps and closes the SWMR file, then reopens it to
  // set "complete" = 1 and `final_attributes` (e.g. a summary; they may
  // replace attributes given at creation, except the reserved ones). Throws
  // std::invalid_argument for a bad attribute (the writer stays open) and
  // RolloutFileError for a failure, including one the writer thread met
  // earlier; the writer is closed either way.
  void close(std::vector<Attribute> final_attributes = {});
  // The same for a run that stops early: writes the remaining steps and
  // closes the file, which stays "complete" = 0, as the destructor leaves
  // it, but throws RolloutFileError for a failure instead of keeping quiet
  // (steps_flushed() then says what the file keeps).
  void close_incomplete();

  std::int64_t steps_committed() const;
  std::int64_t steps_flushed() const;  // flushed to the file, visible to readers
  double seconds_waiting() const;      // time commit() spent waiting for the writer thread

 private:
  void check_frame_type(int dataset, ElementType type) const;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Reads a rollout file, complete or interrupted (opened read-only in SWMR
// mode, so a file whose writer was killed opens too). What it reports is
// fixed when it opens: steps() counts the whole steps then.
class RolloutReader {
 public:
  // Throws RolloutFileError if the file cannot be opened or is not a
  // lockstep rollout file of a format version this code reads.
  explicit RolloutReader(const std::string& path);
  ~RolloutReader();
  RolloutReader(RolloutReader&&) noexcept;
  RolloutReader& operator=(RolloutReader&&) noexcept;

  bool complete() const;       // the "complete" attribute is 1: the writer closed the file
  std::int64_t steps() const;  // whole steps: the smallest extent along T of the step datasets

  std::vector<std::string> datasets() const;  // in creation order
  bool is_step_dataset(const std::string& name) const;
  // Step datasets: [steps(), shape...]; static datasets: their shape.
  std::vector<std::size_t> shape(const std::string& name) const;
  ElementType type(const std::string& name) const;
  std::string description(const std::string& name) const;  // "" when it has none

  bool has_attribute(const std::string& name) const;  // of the file
  AttributeValue attribute(const std::string& name) const;

  // A whole dataset (the first steps() steps of a step dataset), C order,
  // converted to double (exact for every element type).
  std::vector<double> read(const std::string& name) const;
  // Steps [t0, t1) of a step dataset, converted to double.
  std::vector<double> read(const std::string& name, std::int64_t t0, std::int64_t t1) const;
  // The same without conversion, bit for bit: T must be the stored type
  // (std::invalid_argument otherwise).
  template <class T> std::vector<T> read_as(const std::string& name) const { return read_typed<T>(name, {}); }
  template <class T> std::vector<T> read_as(const std::string& name, std::int64_t t0, std::int64_t t1) const {
    return read_typed<T>(name, StepRange{t0, t1});
  }
  // Unknown names throw std::invalid_argument, and so do a step range out of
  // [0, steps()] or reversed and a step range of a static dataset.

 private:
  struct StepRange {
    std::int64_t begin, end;
  };
  // No range: the whole dataset (the first steps() steps of a step dataset).
  template <class T> std::vector<T> read_typed(const std::string& name, std::optional<StepRange> range) const {
    check_stored_type(name, ElementTypeOf<T>::value);
    std::vector<T> out(element_count(name, range));
    read_into(name, ElementTypeOf<T>::value, range, out.data());
    return out;
  }
  void check_stored_type(const std::string& name, ElementType type) const;
  std::size_t element_count(const std::string& name, std::optional<StepRange> range) const;
  void read_into(const std::string& name, ElementType memory_type, std::optional<StepRange> range, void* out) const;
  struct Impl;
  std::unique_ptr<Impl> impl_;  // null once moved from
  Impl& impl() const;  // throws std::logic_error once moved from
};

}  // namespace lockstep
