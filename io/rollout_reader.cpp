// RolloutReader: opens a rollout file read-only in SWMR mode (so a file whose
// writer was killed opens too) and reads what it held when opened.
#include "io/rollout_file.hpp"
#include "io/rollout_hdf5.hpp"

#include <algorithm>
#include <limits>
#include <map>

namespace lockstep {

using namespace rollout_hdf5;

namespace {

struct DatasetInfo {
  Handle dataset;
  ElementType type = ElementType::Float64;
  std::vector<hsize_t> extent;  // as stored: a step dataset's T is its own extent, which may exceed steps()
  bool step = false;            // grows along T (unlimited first dimension)
  std::string description;
};

// The names of the root group's links, in creation order where the file
// tracks it (files this layer writes do), else by name.
std::vector<std::string> link_names(hid_t file, const std::string& path) {
  const std::string what = "cannot list the datasets";
  const Handle root = checked_handle(H5Gopen2(file, "/", H5P_DEFAULT), H5Gclose, path, what);
  const Handle creation = checked_handle(H5Gget_create_plist(root.get()), H5Pclose, path, what);
  unsigned order_flags = 0;
  check(H5Pget_link_creation_order(creation.get(), &order_flags), path, what);
  const H5_index_t index = (order_flags & H5P_CRT_ORDER_INDEXED) ? H5_INDEX_CRT_ORDER : H5_INDEX_NAME;
  std::vector<std::string> names;
  const H5L_iterate_t collect = [](hid_t, const char* name, const H5L_info_t*, void* data) -> herr_t {
    static_cast<std::vector<std::string>*>(data)->emplace_back(name);
    return 0;
  };
  check(H5Literate(root.get(), index, H5_ITER_INC, nullptr, collect, &names), path, what);
  return names;
}

DatasetInfo open_dataset(hid_t file, const std::string& name, const std::string& path) {
  const std::string what = "cannot open dataset '" + name + "'";
  DatasetInfo info;
  info.dataset = checked_handle(H5Dopen2(file, name.c_str(), H5P_DEFAULT), H5Dclose, path, what);
  const Handle type = checked_handle(H5Dget_type(info.dataset.get()), H5Tclose, path, what);
  info.type = element_type_of(type.get(), path, name);
  const Handle space = checked_handle(H5Dget_space(info.dataset.get()), H5Sclose, path, what);
  const int rank = check(H5Sget_simple_extent_ndims(space.get()), path, what);
  info.extent.resize(rank);
  std::vector<hsize_t> max_extent(rank);
  check(H5Sget_simple_extent_dims(space.get(), info.extent.data(), max_extent.data()), path, what);
  info.step = rank > 0 && max_extent[0] == H5S_UNLIMITED;
  if (has_attribute(info.dataset.get(), kDescriptionAttribute, path)) {
    const AttributeValue description = read_attribute(info.dataset.get(), kDescriptionAttribute, path);
    if (const auto* text = std::get_if<std::string>(&description)) info.description = *text;
  }
  return info;
}

bool is_dataset(hid_t file, const std::string& name) {
  const Handle object(H5Oopen(file, name.c_str(), H5P_DEFAULT), H5Oclose);
  if (!object) H5Eclear2(H5E_DEFAULT);  // not an object (a dangling link): no error of the next failure's
  return object && H5Iget_type(object.get()) == H5I_DATASET;
}

// Refuses files that are not rollout files of a version this code reads.
void check_format(hid_t file, const std::string& path) {
  const auto text = [&](const char* name) -> std::string {
    if (!has_attribute(file, name, path)) return "";
    const AttributeValue value = read_attribute(file, name, path);
    if (const auto* s = std::get_if<std::string>(&value)) return *s;
    if (const auto* i = std::get_if<std::int64_t>(&value)) return std::to_string(*i);
    return "?";
  };
  if (text(kFormatAttribute) != kFormatName)
    throw RolloutFileError(path + ": not a lockstep rollout file (its \"format\" attribute is not \"" +
                           std::string(kFormatName) + "\")");
  const std::string version = text(kFormatVersionAttribute);
  if (version != std::to_string(kFormatVersion))
    throw RolloutFileError(path + ": rollout format version " + version + ", this build reads version " +
                           std::to_string(kFormatVersion));
}

}  // namespace

struct RolloutReader::Impl {
  std::string path;
  Handle file;
  std::vector<std::string> names;  // datasets, in creation order
  std::map<std::string, DatasetInfo> datasets;
  std::int64_t steps = 0;
  bool complete = false;

  const DatasetInfo& find(const std::string& name) const {
    const auto it = datasets.find(name);
    if (it == datasets.end()) throw std::invalid_argument(path + ": no dataset '" + name + "'");
    return it->second;
  }
};

RolloutReader::RolloutReader(const std::string& path) : impl_(std::make_unique<Impl>()) {
  const Hdf5Lock lock = lock_hdf5();
  Impl& r = *impl_;
  r.path = path;
  r.file = checked_handle(H5Fopen(path.c_str(), H5F_ACC_RDONLY | H5F_ACC_SWMR_READ, H5P_DEFAULT), H5Fclose, path,
                          "cannot open the rollout file");
  check_format(r.file.get(), path);
  if (rollout_hdf5::has_attribute(r.file.get(), kCompleteAttribute, path)) {
    const AttributeValue value = read_attribute(r.file.get(), kCompleteAttribute, path);
    r.complete = std::holds_alternative<std::int64_t>(value) && std::get<std::int64_t>(value) == 1;
  }
  std::int64_t steps = std::numeric_limits<std::int64_t>::max();
  for (const std::string& name : link_names(r.file.get(), path)) {
    if (!is_dataset(r.file.get(), name)) continue;
    DatasetInfo info = open_dataset(r.file.get(), name, path);
    if (info.step) steps = std::min(steps, static_cast<std::int64_t>(info.extent[0]));
    r.names.push_back(name);
    r.datasets.emplace(name, std::move(info));
  }
  r.steps = steps == std::numeric_limits<std::int64_t>::max() ? 0 : steps;
}

RolloutReader::~RolloutReader() = default;
RolloutReader::RolloutReader(RolloutReader&&) noexcept = default;
RolloutReader& RolloutReader::operator=(RolloutReader&&) noexcept = default;

RolloutReader::Impl& RolloutReader::impl() const {
  if (!impl_) throw std::logic_error("RolloutReader: used after it was moved from (assign another to it first)");
  return *impl_;
}

bool RolloutReader::complete() const { return impl().complete; }
std::int64_t RolloutReader::steps() const { return impl().steps; }
std::vector<std::string> RolloutReader::datasets() const { return impl().names; }
bool RolloutReader::is_step_dataset(const std::string& name) const { return impl().find(name).step; }
ElementType RolloutReader::type(const std::string& name) const { return impl().find(name).type; }
std::string RolloutReader::description(const std::string& name) const { return impl().find(name).description; }

std::vector<std::size_t> RolloutReader::shape(const std::string& name) const {
  const DatasetInfo& info = impl().find(name);
  std::vector<std::size_t> shape(info.extent.begin(), info.extent.end());
  if (info.step) shape[0] = static_cast<std::size_t>(impl().steps);
  return shape;
}

bool RolloutReader::has_attribute(const std::string& name) const {
  const Hdf5Lock lock = lock_hdf5();
  return rollout_hdf5::has_attribute(impl().file.get(), name, impl().path);
}

AttributeValue RolloutReader::attribute(const std::string& name) const {
  const Hdf5Lock lock = lock_hdf5();
  if (!rollout_hdf5::has_attribute(impl().file.get(), name, impl().path))
    throw std::invalid_argument(impl().path + ": no attribute '" + name + "'");
  return read_attribute(impl().file.get(), name, impl().path);
}

std::vector<double> RolloutReader::read(const std::string& name) const {
  std::vector<double> out(element_count(name, {}));
  read_into(name, ElementType::Float64, {}, out.data());
  return out;
}

std::vector<double> RolloutReader::read(const std::string& name, std::int64_t t0, std::int64_t t1) const {
  const StepRange range{t0, t1};
  std::vector<double> out(element_count(name, range));
  read_into(name, ElementType::Float64, range, out.data());
  return out;
}

void RolloutReader::check_stored_type(const std::string& name, ElementType type) const {
  const ElementType stored = impl().find(name).type;
  if (stored != type)
    throw std::invalid_argument(impl().path + ": dataset '" + name + "' holds " + element_type_name(stored) +
                                ", not " + element_type_name(type));
}

std::size_t RolloutReader::element_count(const std::string& name, std::optional<StepRange> range) const {
  const DatasetInfo& info = impl().find(name);
  std::size_t count = 1;
  for (std::size_t d = info.step ? 1 : 0; d < info.extent.size(); ++d) count *= info.extent[d];
  if (!info.step) {
    if (range)
      throw std::invalid_argument(impl().path + ": dataset '" + name + "' is static: it has no steps to select");
    return count;
  }
  const StepRange steps = range.value_or(StepRange{0, impl().steps});
  if (steps.begin < 0 || steps.begin > steps.end || steps.end > impl().steps)
    throw std::invalid_argument(impl().path + ": steps [" + std::to_string(steps.begin) + ", " +
                                std::to_string(steps.end) + ") of dataset '" + name + "' are not within [0, " +
                                std::to_string(impl().steps) + ")");
  return count * static_cast<std::size_t>(steps.end - steps.begin);
}

void RolloutReader::read_into(const std::string& name, ElementType memory, std::optional<StepRange> range,
                              void* out) const {
  if (element_count(name, range) == 0) return;  // also checks the range
  const Hdf5Lock lock = lock_hdf5();
  const std::string what = "cannot read dataset '" + name + "'";
  const std::string& path = impl().path;
  const DatasetInfo& info = impl().find(name);
  const Handle file_space = checked_handle(H5Dget_space(info.dataset.get()), H5Sclose, path, what);
  Handle memory_space = checked_handle(H5Scopy(file_space.get()), H5Sclose, path, what);
  if (info.step) {
    const StepRange steps = range.value_or(StepRange{0, impl().steps});
    std::vector<hsize_t> start(info.extent.size(), 0), count = info.extent;
    start[0] = static_cast<hsize_t>(steps.begin);
    count[0] = static_cast<hsize_t>(steps.end - steps.begin);
    check(H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start.data(), nullptr, count.data(), nullptr), path,
          what);
    memory_space = checked_handle(H5Screate_simple(static_cast<int>(count.size()), count.data(), nullptr), H5Sclose,
                                  path, what);
  }
  check(H5Dread(info.dataset.get(), memory_type(memory), memory_space.get(), file_space.get(), H5P_DEFAULT, out),
        path, what);
}

}  // namespace lockstep
