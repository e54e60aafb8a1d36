#include "io/rollout_hdf5.hpp"

#include <algorithm>
#include <type_traits>
#include <vector>

#include <fcntl.h>
#include <unistd.h>

namespace lockstep {

std::size_t element_size(ElementType type) {
  switch (type) {
    case ElementType::Float32: return 4;
    case ElementType::Float64: return 8;
    case ElementType::UInt8: return 1;
    case ElementType::Int32: return 4;
  }
  return 0;
}

const char* element_type_name(ElementType type) {
  switch (type) {
    case ElementType::Float32: return "float32";
    case ElementType::Float64: return "float64";
    case ElementType::UInt8: return "uint8";
    case ElementType::Int32: return "int32";
  }
  return "unknown";
}

namespace rollout_hdf5 {

Hdf5Lock lock_hdf5() {
  static std::recursive_mutex mutex;
  // HDF5 (1.10.8) cannot close a file whose flush once failed (a full disk
  // as a rollout file is marked complete): its cache then refuses every
  // flush, the file stays open, and the library's own shutdown at exit,
  // which tries again, crashes. Every file lockstep opens is closed by its
  // owner, and one that failed is left as a killed run leaves it, so the
  // process ends without that shutdown (before HDF5 starts: a no-op when
  // the program started HDF5 itself).
  static const bool no_shutdown_at_exit = (H5dont_atexit(), true);
  static_cast<void>(no_shutdown_at_exit);
  Hdf5Lock lock(mutex);
  // A thread-safe HDF5 (Debian's is) keeps the printing switch per thread.
  thread_local bool quiet = false;
  if (!quiet) {
    H5open();
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    quiet = true;
  }
  return lock;
}

herr_t Handle::reset() {
  if (id_ < 0) return 0;
  const Hdf5Lock lock = lock_hdf5();
  return close_(std::exchange(id_, H5I_INVALID_HID));
}

namespace {

// HDF5's error stack in one line: the outermost failure and its reason, the
// system's error message when a call below failed with one (errno), else the
// innermost failure. Clears the stack.
std::string hdf5_error_text() {
  std::vector<std::string> entries;  // outermost first
  H5Ewalk2(
      H5E_DEFAULT, H5E_WALK_DOWNWARD,
      [](unsigned, const H5E_error2_t* error, void* data) -> herr_t {
        if (error->desc && *error->desc) static_cast<std::vector<std::string>*>(data)->emplace_back(error->desc);
        return 0;
      },
      &entries);
  H5Eclear2(H5E_DEFAULT);
  if (entries.empty()) return "";
  std::string reason = entries.size() > 1 ? entries.back() : "";
  const std::string errno_tag = "error message = '";
  for (auto entry = entries.rbegin(); entry != entries.rend(); ++entry) {
    const std::size_t begin = entry->find(errno_tag);
    if (begin == std::string::npos) continue;
    const std::size_t text = begin + errno_tag.size();
    reason = entry->substr(text, entry->find('\'', text) - text);
    break;
  }
  std::string line = reason.empty() ? entries.front() : entries.front() + ": " + reason;
  std::replace(line.begin(), line.end(), '\n', ' ');
  return line;
}

}  // namespace

void fail(const std::string& path, const std::string& what) {
  std::string message = path + ": " + what;
  const std::string detail = hdf5_error_text();
  if (!detail.empty()) message += " (HDF5: " + detail + ")";
  throw RolloutFileError(message);
}

hid_t check(hid_t id, const std::string& path, const std::string& what) {
  if (id < 0) fail(path, what);
  return id;
}

herr_t check(herr_t status, const std::string& path, const std::string& what) {
  if (status < 0) fail(path, what);
  return status;
}

Handle checked_handle(hid_t id, Handle::Close close, const std::string& path, const std::string& what) {
  return Handle(check(id, path, what), close);
}

void discard_further_writes(hid_t file) noexcept {
  const Hdf5Lock lock = lock_hdf5();
  const hid_t access = H5Fget_access_plist(file);
  if (access < 0) return;
  const bool sec2 = H5Pget_driver(access) == H5FD_SEC2;
  H5Pclose(access);
  void* handle = nullptr;
  if (!sec2 || H5Fget_vfd_handle(file, H5P_DEFAULT, &handle) < 0 || !handle) return;
  const int null_device = ::open("/dev/null", O_RDWR | O_CLOEXEC);
  if (null_device < 0) return;
  ::dup2(null_device, *static_cast<int*>(handle));  // the sec2 driver's handle is its descriptor
  ::close(null_device);
}

hid_t file_type(ElementType type) {
  switch (type) {
    case ElementType::Float32: return H5T_IEEE_F32LE;
    case ElementType::Float64: return H5T_IEEE_F64LE;
    case ElementType::UInt8: return H5T_STD_U8LE;
    case ElementType::Int32: return H5T_STD_I32LE;
  }
  return H5I_INVALID_HID;
}

hid_t memory_type(ElementType type) {
  switch (type) {
    case ElementType::Float32: return H5T_NATIVE_FLOAT;
    case ElementType::Float64: return H5T_NATIVE_DOUBLE;
    case ElementType::UInt8: return H5T_NATIVE_UINT8;
    case ElementType::Int32: return H5T_NATIVE_INT32;
  }
  return H5I_INVALID_HID;
}

ElementType element_type_of(hid_t type, const std::string& path, const std::string& dataset) {
  const H5T_class_t type_class = H5Tget_class(type);
  const std::size_t size = H5Tget_size(type);
  if (type_class == H5T_FLOAT && size == 4) return ElementType::Float32;
  if (type_class == H5T_FLOAT && size == 8) return ElementType::Float64;
  if (type_class == H5T_INTEGER) {
    const bool is_signed = H5Tget_sign(type) == H5T_SGN_2;
    if (!is_signed && size == 1) return ElementType::UInt8;
    if (is_signed && size == 4) return ElementType::Int32;
  }
  throw RolloutFileError(path + ": dataset '" + dataset +
                         "' has an element type other than float32, float64, uint8 and int32");
}

namespace {

// A variable-length UTF-8 string type.
Handle string_type(const std::string& path) {
  Handle type = checked_handle(H5Tcopy(H5T_C_S1), H5Tclose, path, "cannot create a string type");
  check(H5Tset_size(type.get(), H5T_VARIABLE), path, "cannot create a string type");
  check(H5Tset_cset(type.get(), H5T_CSET_UTF8), path, "cannot create a string type");
  return type;
}

// A scalar dataspace, or a 1-D one of `count` elements.
Handle attribute_space(bool scalar, std::size_t count, const std::string& path) {
  const hsize_t dims[1] = {count};
  const hid_t id = scalar ? H5Screate(H5S_SCALAR) : H5Screate_simple(1, dims, nullptr);
  return checked_handle(id, H5Sclose, path, "cannot create an attribute dataspace");
}

void write_attribute_data(hid_t object, const std::string& name, hid_t stored_type, hid_t in_memory,
                          const Handle& space, const void* data, const std::string& path) {
  const std::string what = "cannot write attribute '" + name + "'";
  if (check(H5Aexists(object, name.c_str()), path, what) > 0)
    check(H5Adelete(object, name.c_str()), path, what);
  const Handle attribute = checked_handle(
      H5Acreate2(object, name.c_str(), stored_type, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose, path, what);
  const char nothing = 0;  // HDF5 refuses a null buffer, even for an empty list
  check(H5Awrite(attribute.get(), in_memory, data ? data : &nothing), path, what);
}

}  // namespace

void write_attribute(hid_t object, const std::string& name, const AttributeValue& value, const std::string& path) {
  std::visit(
      [&](const auto& v) {
        using V = std::decay_t<decltype(v)>;
        if constexpr (std::is_same_v<V, std::string>) {
          const Handle type = string_type(path);
          const char* text = v.c_str();
          write_attribute_data(object, name, type.get(), type.get(), attribute_space(true, 1, path), &text, path);
        } else if constexpr (std::is_same_v<V, std::int64_t>) {
          write_attribute_data(object, name, H5T_STD_I64LE, H5T_NATIVE_INT64, attribute_space(true, 1, path), &v,
                               path);
        } else if constexpr (std::is_same_v<V, double>) {
          write_attribute_data(object, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, attribute_space(true, 1, path), &v,
                               path);
        } else if constexpr (std::is_same_v<V, std::vector<std::string>>) {
          const Handle type = string_type(path);
          std::vector<const char*> texts;
          for (const std::string& s : v) texts.push_back(s.c_str());
          write_attribute_data(object, name, type.get(), type.get(), attribute_space(false, v.size(), path),
                               texts.data(), path);
        } else {
          static_assert(std::is_same_v<V, std::vector<double>>);
          write_attribute_data(object, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE,
                               attribute_space(false, v.size(), path), v.data(), path);
        }
      },
      value);
}

bool has_attribute(hid_t object, const std::string& name, const std::string& path) {
  return check(H5Aexists(object, name.c_str()), path, "cannot look for attribute '" + name + "'") > 0;
}

namespace {

// The strings of a string attribute: variable-length or fixed-length
// (padded with NULs or spaces, as h5py and other tools write them).
std::vector<std::string> read_strings(hid_t attribute, hid_t stored_type, std::size_t count, const std::string& path,
                                      const std::string& what) {
  std::vector<std::string> strings;
  if (count == 0) return strings;
  if (check(H5Tis_variable_str(stored_type), path, what) > 0) {
    const Handle type = string_type(path);
    std::vector<char*> texts(count, nullptr);
    check(H5Aread(attribute, type.get(), texts.data()), path, what);
    for (char* text : texts) strings.emplace_back(text ? text : "");
    const Handle space = checked_handle(H5Aget_space(attribute), H5Sclose, path, what);
    H5Dvlen_reclaim(type.get(), space.get(), H5P_DEFAULT, texts.data());
    return strings;
  }
  const std::size_t size = H5Tget_size(stored_type);
  std::vector<char> buffer(size * count);
  check(H5Aread(attribute, stored_type, buffer.data()), path, what);
  for (std::size_t i = 0; i < count; ++i) {
    std::string text(buffer.data() + i * size, size);
    text.erase(std::min(text.find('\0'), text.size()));
    if (H5Tget_strpad(stored_type) == H5T_STR_SPACEPAD) text.erase(text.find_last_not_of(' ') + 1);
    strings.push_back(std::move(text));
  }
  return strings;
}

}  // namespace

AttributeValue read_attribute(hid_t object, const std::string& name, const std::string& path) {
  const std::string what = "cannot read attribute '" + name + "'";
  const Handle attribute = checked_handle(H5Aopen(object, name.c_str(), H5P_DEFAULT), H5Aclose, path, what);
  const Handle type = checked_handle(H5Aget_type(attribute.get()), H5Tclose, path, what);
  const Handle space = checked_handle(H5Aget_space(attribute.get()), H5Sclose, path, what);
  const bool scalar = H5Sget_simple_extent_type(space.get()) == H5S_SCALAR;
  const hssize_t points = H5Sget_simple_extent_npoints(space.get());
  if (points < 0) fail(path, what);
  const auto count = static_cast<std::size_t>(points);

  switch (H5Tget_class(type.get())) {
    case H5T_STRING: {
      std::vector<std::string> strings = read_strings(attribute.get(), type.get(), count, path, what);
      if (scalar) return strings.at(0);
      return strings;
    }
    case H5T_INTEGER:
      if (scalar) {
        std::int64_t value = 0;
        check(H5Aread(attribute.get(), H5T_NATIVE_INT64, &value), path, what);
        return value;
      }
      [[fallthrough]];  // an integer array comes back as doubles
    case H5T_FLOAT: {
      std::vector<double> values(count);
      if (count > 0) check(H5Aread(attribute.get(), H5T_NATIVE_DOUBLE, values.data()), path, what);
      if (scalar) return values.at(0);
      return values;
    }
    default:
      throw RolloutFileError(path + ": attribute '" + name +
                             "' is not a string, a number or a list of strings or numbers");
  }
}

}  // namespace rollout_hdf5
}  // namespace lockstep
