// HDF5 plumbing shared by the rollout writer and reader: the process-wide
// lock, error messages from HDF5's error stack, handles that close
// themselves, element types and attributes. Internal to io/rollout_*.cpp
// (it includes hdf5.h, which the public header keeps out; not installed).
#pragma once

#include "io/rollout_file.hpp"

#include <hdf5.h>

#include <mutex>
#include <string>
#include <utility>

namespace lockstep::rollout_hdf5 {

// The file-level attributes every rollout file has.
inline constexpr char kFormatAttribute[] = "format";
inline constexpr char kFormatName[] = "lockstep rollout";
inline constexpr char kFormatVersionAttribute[] = "format_version";
inline constexpr std::int64_t kFormatVersion = 1;
inline constexpr char kCompleteAttribute[] = "complete";  // 0 while written, 1 after close()
inline constexpr char kDescriptionAttribute[] = "description";  // of a dataset

// Every HDF5 call of this layer holds this process-wide lock: HDF5 may be
// built without thread safety (Debian's 1.10 happens to be thread-safe, which
// this layer does not rely on), and a failing call's error stack is read
// before another call can clear it. It is recursive so that a Handle may close
// itself under it wherever it is destroyed, inside a locked section or not.
// A thread's first lock also turns HDF5's automatic error printing off for
// that thread: errors become exception messages instead.
using Hdf5Lock = std::unique_lock<std::recursive_mutex>;
Hdf5Lock lock_hdf5();

// An HDF5 identifier with the function that closes it (H5Fclose, H5Dclose,
// ...); closing takes the lock. Move-only.
class Handle {
 public:
  using Close = herr_t (*)(hid_t);
  Handle() = default;
  Handle(hid_t id, Close close) : id_(id), close_(close) {}
  Handle(Handle&& other) noexcept : id_(std::exchange(other.id_, H5I_INVALID_HID)), close_(other.close_) {}
  Handle& operator=(Handle&& other) noexcept {
    if (this != &other) {
      reset();
      id_ = std::exchange(other.id_, H5I_INVALID_HID);
      close_ = other.close_;
    }
    return *this;
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  ~Handle() { reset(); }

  hid_t get() const { return id_; }
  explicit operator bool() const { return id_ >= 0; }
  // Closes now; returns the close function's status (0 when there was nothing to close).
  herr_t reset();

 private:
  hid_t id_ = H5I_INVALID_HID;
  Close close_ = nullptr;
};

// Failures: RolloutFileError("<path>: <what>: <HDF5's error text>"). Call
// with the lock held, right after the failing call, so the error stack is
// that call's. check() passes a valid id or status through.
[[noreturn]] void fail(const std::string& path, const std::string& what);
hid_t check(hid_t id, const std::string& path, const std::string& what);
herr_t check(herr_t status, const std::string& path, const std::string& what);
// The same, returning a Handle closed by `close`.
Handle checked_handle(hid_t id, Handle::Close close, const std::string& path, const std::string& what);

// After a failed write: points HDF5's file descriptor of `file` at
// /dev/null. What HDF5 still holds in memory for the file (extents and chunk
// index entries of steps whose data never reached the disk) is then never
// written: the file stays as its last successful flush left it. And closing
// succeeds: a failed H5Fclose leaves a half-closed file that crashes HDF5 when
// the process exits. Only for the default (sec2) driver; a no-op otherwise.
void discard_further_writes(hid_t file) noexcept;

// The type in the file (little-endian) and in memory (native) of an element type.
hid_t file_type(ElementType type);
hid_t memory_type(ElementType type);
// The element type of a dataset's HDF5 type; throws RolloutFileError for another type.
ElementType element_type_of(hid_t type, const std::string& path, const std::string& dataset);

// Writes attribute `name` of `object`, replacing one of that name.
void write_attribute(hid_t object, const std::string& name, const AttributeValue& value, const std::string& path);
// Reads an attribute written by write_attribute (or h5py: variable or fixed
// length strings, integer or floating point scalars and 1-D arrays; integer
// arrays come back as doubles).
AttributeValue read_attribute(hid_t object, const std::string& name, const std::string& path);
bool has_attribute(hid_t object, const std::string& name, const std::string& path);

}  // namespace lockstep::rollout_hdf5
