// Rollout files (io/rollout_file.hpp): round trips, attributes, layout, the
// writer thread, crash safety (kill -9, a full disk) and argument checks.
//
// The crash tests fork() a child that writes: each forks before starting any
// thread of its own, the child does nothing but write (its writer starts its
// own thread), reports through a pipe and ends with _exit().
#include "io/rollout_chunks.hpp"
#include "io/rollout_file.hpp"
#include "io/rollout_hdf5.hpp"
#include "tests/test_support.hpp"

#include <gtest/gtest.h>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <thread>

namespace lockstep {
namespace {

namespace fs = std::filesystem;
using rollout_hdf5::Handle;
using Clock = std::chrono::steady_clock;

// A fresh directory under the test temp directory, removed with its files.
class TempDir {
 public:
  TempDir() {
    std::string pattern = ::testing::TempDir() + "lockstep_rollout_XXXXXX";
    if (!mkdtemp(pattern.data())) throw std::runtime_error("mkdtemp failed for " + pattern);
    path_ = pattern;
  }
  ~TempDir() {
    std::error_code ignored;
    fs::remove_all(path_, ignored);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string file(const std::string& name) const { return (path_ / name).string(); }

 private:
  fs::path path_;
};

// The sample rollout ------------------------------------------------------------
// Three environments, two joints; every element type. Each value is a
// function of (step, element index), so any step can be checked.

constexpr std::size_t kEnvs = 3, kJoints = 2;

float q_value(std::int64_t t, std::size_t i) { return static_cast<float>(std::sin(0.01 * t + 0.7 * i)); }
double qd_value(std::int64_t t, std::size_t i) { return std::cos(0.013 * t) * (1.0 + i) / 3.0; }
float reward_value(std::int64_t t, std::size_t i) { return static_cast<float>(t % 17) - 0.1f * i; }
std::uint8_t done_value(std::int64_t t, std::size_t i) { return static_cast<std::uint8_t>((t * 7 + i) & 0xff); }
std::int32_t tick_value(std::int64_t t, std::size_t) { return static_cast<std::int32_t>(1000 * t - 3); }

std::vector<StepDataset> sample_steps() {
  return {{"q", ElementType::Float32, {kEnvs, kJoints}, "joint positions"},
          {"qd", ElementType::Float64, {kEnvs, kJoints}, ""},
          {"reward", ElementType::Float32, {kEnvs}, "reward per environment"},
          {"done", ElementType::UInt8, {kEnvs}, ""},
          {"tick", ElementType::Int32, {}, "a scalar per step"}};
}

template <class T> std::vector<unsigned char> bytes_of(const std::vector<T>& values) {
  std::vector<unsigned char> bytes(values.size() * sizeof(T));
  std::memcpy(bytes.data(), values.data(), bytes.size());
  return bytes;
}

std::vector<StaticDataset> sample_statics() {
  return {{"masses", ElementType::Float32, {2, 3}, bytes_of(std::vector<float>{1, 2.5f, 3, 4, 5, 1e-30f}), "kg"},
          {"seed", ElementType::Float64, {}, bytes_of(std::vector<double>{1.0 / 3.0}), ""},
          {"mask", ElementType::UInt8, {4}, bytes_of(std::vector<std::uint8_t>{0, 1, 254, 255}), ""},
          {"ids", ElementType::Int32, {2}, bytes_of(std::vector<std::int32_t>{-2147483647 - 1, 2147483647}), ""}};
}

std::vector<Attribute> sample_attributes() {
  return {{"dt", 0.005},
          {"control_steps", std::int64_t{2}},
          {"q_names", std::vector<std::string>{"hip", "knee"}},
          {"dof_names", std::vector<std::string>{"hip", "knee"}}};
}

template <class T> void fill(RolloutWriter& writer, int dataset, std::size_t count, std::int64_t t,
                             T (*value)(std::int64_t, std::size_t)) {
  T* frame = writer.frame_as<T>(dataset);
  for (std::size_t i = 0; i < count; ++i) frame[i] = value(t, i);
}

void write_sample_step(RolloutWriter& writer, std::int64_t t) {
  fill(writer, 0, kEnvs * kJoints, t, q_value);
  fill(writer, 1, kEnvs * kJoints, t, qd_value);
  fill(writer, 2, kEnvs, t, reward_value);
  fill(writer, 3, kEnvs, t, done_value);
  fill(writer, 4, 1, t, tick_value);
}

// Steps [0, steps) written and committed.
void commit_sample_steps(RolloutWriter& writer, std::int64_t steps) {
  for (std::int64_t t = 0; t < steps; ++t) {
    write_sample_step(writer, t);
    writer.commit();
  }
}

void write_sample(const std::string& path, std::int64_t steps, const RolloutFileOptions& options = {},
                  std::vector<Attribute> final_attributes = {}) {
  RolloutWriter writer(path, sample_steps(), sample_statics(), sample_attributes(), options);
  commit_sample_steps(writer, steps);
  writer.close(std::move(final_attributes));
}

// Expects steps [t0, t1) of a step dataset to hold value(t, i), bit for bit.
template <class T> void expect_values(const RolloutReader& reader, const std::string& name, std::int64_t t0,
                                      std::int64_t t1, T (*value)(std::int64_t, std::size_t)) {
  const std::vector<T> data = reader.read_as<T>(name, t0, t1);
  if (t1 == t0) return;
  const std::size_t per_step = data.size() / static_cast<std::size_t>(t1 - t0);
  for (std::int64_t t = t0; t < t1; ++t)
    for (std::size_t i = 0; i < per_step; ++i) {
      const T expected = value(t, i);
      const T& got = data[static_cast<std::size_t>(t - t0) * per_step + i];
      if (std::memcmp(&got, &expected, sizeof(T)) != 0 || !std::isfinite(static_cast<double>(got))) {
        ADD_FAILURE() << name << " at step " << t << ", element " << i << ": " << +got << ", expected " << +expected;
        return;
      }
    }
}

void expect_sample_values(const RolloutReader& reader, std::int64_t t0, std::int64_t t1) {
  expect_values(reader, "q", t0, t1, q_value);
  expect_values(reader, "qd", t0, t1, qd_value);
  expect_values(reader, "reward", t0, t1, reward_value);
  expect_values(reader, "done", t0, t1, done_value);
  expect_values(reader, "tick", t0, t1, tick_value);
}

// A reader moved from is refused by name (its calls dereferenced null).
TEST(RolloutFile, AMovedFromReaderIsRefused) {
  const TempDir dir;
  const std::string path = dir.file("moved.h5");
  write_sample(path, 3, RolloutFileOptions());
  RolloutReader reader(path);
  const RolloutReader taken(std::move(reader));
  EXPECT_EQ(taken.steps(), 3);
  try {
    (void)reader.steps();
    ADD_FAILURE() << "a moved-from reader was used";
  } catch (const std::logic_error& e) {
    EXPECT_NE(std::string(e.what()).find("RolloutReader: used after it was moved from"), std::string::npos)
        << e.what();
  }
}

// Round trips ----------------------------------------------------------------------

TEST(RolloutFile, RoundTripsEveryElementTypeBitForBit) {
  const TempDir dir;
  const std::string path = dir.file("round_trip.h5");
  RolloutFileOptions options;
  options.buffer_steps = 8;  // 37 steps: four full blocks and a partial one
  write_sample(path, 37, options);

  const RolloutReader reader(path);
  EXPECT_TRUE(reader.complete());
  EXPECT_EQ(reader.steps(), 37);
  EXPECT_EQ(reader.datasets(),
            (std::vector<std::string>{"masses", "seed", "mask", "ids", "q", "qd", "reward", "done", "tick"}));
  EXPECT_EQ(reader.shape("q"), (std::vector<std::size_t>{37, kEnvs, kJoints}));
  EXPECT_EQ(reader.shape("tick"), (std::vector<std::size_t>{37}));
  EXPECT_EQ(reader.shape("masses"), (std::vector<std::size_t>{2, 3}));
  EXPECT_EQ(reader.shape("seed"), (std::vector<std::size_t>{}));
  EXPECT_EQ(reader.type("qd"), ElementType::Float64);
  EXPECT_EQ(reader.type("done"), ElementType::UInt8);
  EXPECT_EQ(reader.type("ids"), ElementType::Int32);
  EXPECT_TRUE(reader.is_step_dataset("q"));
  EXPECT_FALSE(reader.is_step_dataset("masses"));
  EXPECT_EQ(reader.description("q"), "joint positions");
  EXPECT_EQ(reader.description("masses"), "kg");
  EXPECT_EQ(reader.description("qd"), "");

  expect_sample_values(reader, 0, 37);
  expect_sample_values(reader, 5, 20);  // a range
  EXPECT_EQ(reader.read_as<float>("q").size(), 37 * kEnvs * kJoints);
  EXPECT_EQ(reader.read_as<float>("q", 36, 36).size(), 0u);

  // Static datasets, bit for bit, and every type converted to double.
  for (const StaticDataset& expected : sample_statics()) {
    std::vector<unsigned char> got;
    switch (expected.type) {
      case ElementType::Float32: got = bytes_of(reader.read_as<float>(expected.name)); break;
      case ElementType::Float64: got = bytes_of(reader.read_as<double>(expected.name)); break;
      case ElementType::UInt8: got = bytes_of(reader.read_as<std::uint8_t>(expected.name)); break;
      case ElementType::Int32: got = bytes_of(reader.read_as<std::int32_t>(expected.name)); break;
    }
    EXPECT_EQ(got, expected.data) << expected.name;
  }
  EXPECT_EQ(reader.read("ids"), (std::vector<double>{-2147483648.0, 2147483647.0}));
  EXPECT_EQ(reader.read("mask"), (std::vector<double>{0, 1, 254, 255}));
  EXPECT_EQ(reader.read("tick", 2, 4), (std::vector<double>{1997, 2997}));
  EXPECT_EQ(reader.read("q")[7], static_cast<double>(q_value(1, 1)));
}

TEST(RolloutFile, WritesAttributesOfEveryKind) {
  const TempDir dir;
  const std::string path = dir.file("attributes.h5");
  const std::vector<Attribute> attributes = {
      {"name", std::string("quadruped \xc3\xa9t\xc3\xa9")},  // UTF-8
      {"count", std::int64_t{-9007199254740993}},
      {"dt", 0.1},
      {"names", std::vector<std::string>{"a", "", "long name"}},
      {"gains", std::vector<double>{1.5, -2, 1e300}},
      {"no_names", std::vector<std::string>{}},
      {"no_gains", std::vector<double>{}},
      {"replaced", std::string("at creation")}};
  {
    RolloutWriter writer(path, {{"x", ElementType::Float32, {1}, ""}}, {}, attributes);
    *writer.frame_as<float>(0) = 1;
    writer.commit();
    writer.close({{"replaced", 3.5}, {"summary", std::string("1 step")}});
  }
  const RolloutReader reader(path);
  for (const Attribute& attribute : attributes)
    if (attribute.name != "replaced") {
      EXPECT_EQ(reader.attribute(attribute.name), attribute.value) << attribute.name;
    }
  EXPECT_EQ(reader.attribute("replaced"), AttributeValue(3.5));
  EXPECT_EQ(reader.attribute("summary"), AttributeValue(std::string("1 step")));
  EXPECT_EQ(reader.attribute("format"), AttributeValue(std::string("lockstep rollout")));
  EXPECT_EQ(reader.attribute("format_version"), AttributeValue(std::int64_t{1}));
  EXPECT_EQ(reader.attribute("complete"), AttributeValue(std::int64_t{1}));
  EXPECT_TRUE(reader.has_attribute("gains"));
  EXPECT_FALSE(reader.has_attribute("missing"));
  EXPECT_THROW_WITH(reader.attribute("missing"), std::invalid_argument, "no attribute 'missing'");
}

// Layout -----------------------------------------------------------------------------

struct Layout {
  std::vector<hsize_t> chunk;
  bool shuffle = false;
  int deflate = 0;  // gzip level, 0: none
};

// A dataset's chunk shape and filters, read with the HDF5 C API.
Layout layout_of(const std::string& path, const std::string& dataset) {
  const rollout_hdf5::Hdf5Lock lock = rollout_hdf5::lock_hdf5();
  const Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  const Handle handle(H5Dopen2(file.get(), dataset.c_str(), H5P_DEFAULT), H5Dclose);
  const Handle creation(H5Dget_create_plist(handle.get()), H5Pclose);
  Layout layout;
  layout.chunk.resize(8);
  layout.chunk.resize(std::max(0, H5Pget_chunk(creation.get(), 8, layout.chunk.data())));
  for (int k = 0; k < H5Pget_nfilters(creation.get()); ++k) {
    unsigned flags = 0, values[4] = {}, config = 0;
    std::size_t count = 4;
    const H5Z_filter_t filter = H5Pget_filter2(creation.get(), k, &flags, &count, values, 0, nullptr, &config);
    if (filter == H5Z_FILTER_SHUFFLE) layout.shuffle = true;
    if (filter == H5Z_FILTER_DEFLATE) layout.deflate = static_cast<int>(values[0]);
  }
  return layout;
}

TEST(RolloutFile, ChunksAlongStepsWithinFourMebibytes) {
  const TempDir dir;
  const std::string path = dir.file("chunks.h5");
  const std::vector<StepDataset> steps = {{"small", ElementType::Float32, {10}, ""},       // 40 B a step
                                          {"large", ElementType::Float64, {512, 128}, ""},  // 512 KiB a step
                                          {"scalar", ElementType::UInt8, {}, ""}};
  RolloutWriter(path, steps, {}, {}).close();  // chunk_steps 0: ~1 MiB chunks of the largest dataset
  EXPECT_EQ(layout_of(path, "large").chunk, (std::vector<hsize_t>{2, 512, 128}));
  EXPECT_EQ(layout_of(path, "small").chunk, (std::vector<hsize_t>{2, 10}));
  EXPECT_EQ(layout_of(path, "scalar").chunk, (std::vector<hsize_t>{2}));

  RolloutFileOptions options;
  options.chunk_steps = 100;  // "large" shrinks to 8 steps (4 MiB)
  RolloutWriter(path, steps, {}, {}, options).close();
  EXPECT_EQ(layout_of(path, "large").chunk, (std::vector<hsize_t>{8, 512, 128}));
  EXPECT_EQ(layout_of(path, "small").chunk, (std::vector<hsize_t>{100, 10}));
  EXPECT_FALSE(layout_of(path, "small").shuffle);
  EXPECT_EQ(layout_of(path, "small").deflate, 0);
}

// HDF5's shuffle: byte b of every element together; the bytes after the
// last whole element stay where they are.
TEST(RolloutFile, ShuffleGathersEachByteOfTheElements) {
  const std::vector<unsigned char> in = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14};  // 3 elements of 4, 2 more
  std::vector<unsigned char> out(in.size());
  rollout_chunks::shuffle(in.data(), in.size(), 4, out.data());
  EXPECT_EQ(out, (std::vector<unsigned char>{1, 5, 9, 2, 6, 10, 3, 7, 11, 4, 8, 12, 13, 14}));
  rollout_chunks::shuffle(in.data(), in.size(), 1, out.data());  // bytes: unchanged
  EXPECT_EQ(out, in);
  rollout_chunks::shuffle(in.data(), 4, 4, out.data());  // one element: unchanged
  EXPECT_TRUE(std::equal(in.begin(), in.begin() + 4, out.begin()));
}

// 500 steps in chunks of 16: 31 blocks of whole chunks, deflated on the TBB
// threads and written as they are, then 4 steps through HDF5's own filters.
TEST(RolloutFile, CompressedFileReadsBackTheSame) {
  const TempDir dir;
  RolloutFileOptions options;
  options.chunk_steps = 16;
  options.compression = 6;
  write_sample(dir.file("gzip.h5"), 500, options);
  options.compression = 0;
  write_sample(dir.file("plain.h5"), 500, options);

  const Layout layout = layout_of(dir.file("gzip.h5"), "qd");
  EXPECT_EQ(layout.chunk, (std::vector<hsize_t>{16, kEnvs, kJoints}));
  EXPECT_TRUE(layout.shuffle);
  EXPECT_EQ(layout.deflate, 6);
  EXPECT_LT(fs::file_size(dir.file("gzip.h5")), fs::file_size(dir.file("plain.h5")));
  const RolloutReader reader(dir.file("gzip.h5"));
  EXPECT_EQ(reader.steps(), 500);
  expect_sample_values(reader, 0, 500);
}

TEST(RolloutFile, StepsIsTheSmallestExtentOfTheStepDatasets) {
  const TempDir dir;
  const std::string path = dir.file("ragged.h5");
  write_sample(path, 20);
  {  // as a writer killed between extending two datasets would leave it
    const rollout_hdf5::Hdf5Lock lock = rollout_hdf5::lock_hdf5();
    const Handle file(H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT), H5Fclose);
    const Handle qd(H5Dopen2(file.get(), "qd", H5P_DEFAULT), H5Dclose);
    const hsize_t shorter[3] = {17, kEnvs, kJoints};
    ASSERT_GE(H5Dset_extent(qd.get(), shorter), 0);
  }
  const RolloutReader reader(path);
  EXPECT_EQ(reader.steps(), 17);
  EXPECT_EQ(reader.shape("q")[0], 17u);
  EXPECT_EQ(reader.read_as<float>("q").size(), 17 * kEnvs * kJoints);
  EXPECT_THROW_WITH(reader.read("q", 10, 18), std::invalid_argument, "not within [0, 17)");
  expect_sample_values(reader, 0, 17);
}

// The complete flag and the writer thread ------------------------------------------

TEST(RolloutFile, CompleteOnlyAfterClose) {
  const TempDir dir;
  const std::string path = dir.file("abandoned.h5");
  {
    RolloutWriter writer(path, sample_steps(), {}, {});
    commit_sample_steps(writer, 10);
    EXPECT_FALSE(RolloutReader(path).complete());  // while it is written
  }  // destroyed without close(): steps written, not complete
  {
    const RolloutReader reader(path);
    EXPECT_FALSE(reader.complete());
    EXPECT_EQ(reader.attribute("complete"), AttributeValue(std::int64_t{0}));
    EXPECT_EQ(reader.steps(), 10);
    expect_sample_values(reader, 0, 10);
  }
  write_sample(path, 10);
  EXPECT_TRUE(RolloutReader(path).complete());
}

// A reader holding the live file open (HDF5's shared file lock, as h5py
// with swmr=True takes it) does not keep close() from marking it complete.
TEST(RolloutFile, CompletesWhileAReaderHoldsTheFileOpen) {
  const TempDir dir;
  const std::string path = dir.file("watched.h5");
  RolloutWriter writer(path, sample_steps(), {}, {});
  commit_sample_steps(writer, 10);
  const int reader = ::open(path.c_str(), O_RDONLY);
  ASSERT_GE(reader, 0);
  ASSERT_EQ(::flock(reader, LOCK_SH | LOCK_NB), 0) << "the writer holds no exclusive lock while it writes";
  EXPECT_NO_THROW(writer.close({{"episodes", std::int64_t{3}}}));
  ::close(reader);
  const RolloutReader done(path);
  EXPECT_TRUE(done.complete());
  EXPECT_EQ(done.attribute("episodes"), AttributeValue(std::int64_t{3}));
  EXPECT_EQ(done.steps(), 10);
  expect_sample_values(done, 0, 10);
}

TEST(RolloutFile, ReplacesAFileOnlyOnceTheNewOneIsSetUp) {
  const TempDir dir;
  const std::string path = dir.file("replaced.h5");
  write_sample(path, 5);
  RolloutWriter writer(path, {{"other", ElementType::Float64, {1}, ""}}, {}, {});
  EXPECT_FALSE(fs::exists(path + ".creating"));
  EXPECT_EQ(RolloutReader(path).datasets(), std::vector<std::string>{"other"});
  writer.close();
}

// A "<path>.creating" left behind as a link (a killed run's leftover, or
// planted) is replaced, not followed: the file it points to stays as it was.
TEST(RolloutFile, ALeftoverCreatingLinkIsNotFollowed) {
  const TempDir dir;
  const std::string path = dir.file("linked.h5"), target = dir.file("precious.txt");
  std::ofstream(target) << "keep me";
  fs::create_symlink(target, path + ".creating");
  write_sample(path, 2);
  std::ifstream in(target);
  const std::string kept((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_TRUE(kept == "keep me") << "the link's target now holds " << kept.size() << " bytes";
  EXPECT_EQ(RolloutReader(path).steps(), 2);
  EXPECT_FALSE(fs::is_symlink(path));
}

TEST(RolloutFile, ZeroStepsCloseToAnEmptyCompleteFile) {
  const TempDir dir;
  const std::string path = dir.file("empty.h5");
  write_sample(path, 0);
  const RolloutReader reader(path);
  EXPECT_TRUE(reader.complete());
  EXPECT_EQ(reader.steps(), 0);
  EXPECT_TRUE(reader.read("q").empty());
}

// A zero extent (the actions of a model without actuated DOFs, the q of a
// fixed base without joints) is an empty dataset of that shape, beside
// datasets that hold data, compressed or not; the writer once refused it,
// and a rollout of such a model stopped with an internal error.
TEST(RolloutFile, ZeroExtentsAreEmptyDatasetsOfTheirShape) {
  const TempDir dir;
  for (int compression : {0, 4}) {
    const std::string path = dir.file("zero_" + std::to_string(compression) + ".h5");
    RolloutFileOptions options;
    options.compression = compression;
    options.buffer_steps = 4;  // 10 steps: whole blocks and a partial one
    {
      RolloutWriter writer(path,
                           {{"actions", ElementType::Float64, {3, 0}, ""}, {"tick", ElementType::Int32, {}, ""}},
                           {{"names", ElementType::Float32, {0}, {}, ""}, {"grid", ElementType::UInt8, {2, 0}, {}, ""}},
                           {}, options);
      for (std::int32_t t = 0; t < 10; ++t) {
        *writer.frame_as<std::int32_t>(1) = t;
        writer.commit();
      }
      writer.close();
    }
    const RolloutReader reader(path);
    EXPECT_TRUE(reader.complete());
    EXPECT_EQ(reader.steps(), 10);
    EXPECT_EQ(reader.shape("actions"), (std::vector<std::size_t>{10, 3, 0}));
    EXPECT_TRUE(reader.is_step_dataset("actions"));
    EXPECT_TRUE(reader.read("actions").empty());
    EXPECT_EQ(reader.shape("names"), (std::vector<std::size_t>{0}));
    EXPECT_EQ(reader.shape("grid"), (std::vector<std::size_t>{2, 0}));
    EXPECT_TRUE(reader.read("grid").empty());
    EXPECT_EQ(reader.read("tick"), (std::vector<double>{0, 1, 2, 3, 4, 5, 6, 7, 8, 9}));
  }
}

TEST(RolloutFile, SlowProducerStepsReachTheFileWithinTheFlushInterval) {
  const TempDir dir;
  RolloutFileOptions options;
  options.buffer_steps = 1000;  // never full here
  options.flush_seconds = 0.01;
  RolloutWriter writer(dir.file("slow.h5"), sample_steps(), {}, {}, options);
  for (std::int64_t t = 0; t < 3; ++t) {
    write_sample_step(writer, t);
    writer.commit();
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  // The later commits found the interval passed and handed their partial blocks over.
  const Clock::time_point deadline = Clock::now() + std::chrono::seconds(1);
  while (writer.steps_flushed() < 2 && Clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  EXPECT_GE(writer.steps_flushed(), 2);
  EXPECT_EQ(writer.steps_committed(), 3);
  writer.close();
}

TEST(RolloutFile, WritersAndReadersShareHdf5AcrossThreads) {
  const TempDir dir;
  write_sample(dir.file("done.h5"), 50);
  RolloutFileOptions options;
  options.buffer_steps = 4;
  options.flush_seconds = 0;  // flush after every block: many HDF5 calls on the writer thread
  RolloutWriter writer(dir.file("busy.h5"), sample_steps(), {}, {}, options);
  std::thread reading([&] {
    for (int k = 0; k < 30; ++k) expect_sample_values(RolloutReader(dir.file("done.h5")), 0, 50);
  });
  for (std::int64_t t = 0; t < 2000; ++t) {
    write_sample_step(writer, t);
    writer.commit();
  }
  reading.join();
  writer.close();
  EXPECT_GE(writer.seconds_waiting(), 0.0);
  expect_sample_values(RolloutReader(dir.file("busy.h5")), 0, 2000);
}

// Crash safety: kill -9 ---------------------------------------------------------------

// The child: writes sample steps without end, flushing every 20 ms, and
// writes steps_flushed() to `report` whenever it grows.
[[noreturn]] void write_until_killed(const std::string& path, int report) {
  try {
    RolloutFileOptions options;
    options.chunk_steps = 8;
    options.flush_seconds = 0.02;
    RolloutWriter writer(path, sample_steps(), sample_statics(), sample_attributes(), options);
    std::int64_t reported = 0;
    for (std::int64_t t = 0;; ++t) {
      write_sample_step(writer, t);
      writer.commit();
      if (writer.steps_flushed() > reported) {
        reported = writer.steps_flushed();
        if (write(report, &reported, sizeof reported) != sizeof reported) _exit(3);
      }
      usleep(10);
    }
  } catch (...) {
    _exit(2);
  }
}

// Forks a child writing `path`, SIGKILLs it at an arbitrary moment after it
// reported `flushes` flushes, and returns the last flushed step count it
// reported (-1 on failure).
std::int64_t kill_writer_after_flushes(const std::string& path, int flushes) {
  int pipe_fds[2];
  if (pipe(pipe_fds) != 0) return -1;
  const pid_t child = fork();
  if (child < 0) return -1;
  if (child == 0) {
    close(pipe_fds[0]);
    write_until_killed(path, pipe_fds[1]);
  }
  close(pipe_fds[1]);
  std::int64_t flushed = -1;
  for (int seen = 0; seen < flushes; ++seen) {
    pollfd ready{pipe_fds[0], POLLIN, 0};
    if (poll(&ready, 1, 5000) != 1 || read(pipe_fds[0], &flushed, sizeof flushed) != sizeof flushed) {
      ADD_FAILURE() << "the writing child reported no flush within 5 s";
      flushed = -1;
      break;
    }
  }
  const auto delay = std::chrono::microseconds(Clock::now().time_since_epoch().count() / 1000 % 20000);
  std::this_thread::sleep_for(delay);  // somewhere within the next flush interval
  kill(child, SIGKILL);
  int status = 0;
  waitpid(child, &status, 0);
  close(pipe_fds[0]);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << "the child ended by itself: " << status;
  return flushed;
}

TEST(RolloutCrash, KilledWriterLeavesEveryFlushedStepReadable) {
  const TempDir dir;
  const std::string path = dir.file("killed.h5");
  const std::int64_t flushed = kill_writer_after_flushes(path, 3);
  ASSERT_GT(flushed, 0);

  const RolloutReader reader(path);
  EXPECT_FALSE(reader.complete());
  EXPECT_GE(reader.steps(), flushed);
  expect_sample_values(reader, 0, reader.steps());  // every whole step, not only the reported ones
  EXPECT_EQ(reader.read_as<float>("masses"), (std::vector<float>{1, 2.5f, 3, 4, 5, 1e-30f}));
  EXPECT_EQ(reader.attribute("dt"), AttributeValue(0.005));
}

#ifdef LOCKSTEP_PYTHON_WITH_H5PY
// Runs `command` through the shell; returns its exit status and output.
std::pair<int, std::string> run(const std::string& command) {
  std::string output;
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return {-1, "popen failed"};
  char buffer[4096];
  while (std::size_t n = std::fread(buffer, 1, sizeof buffer, pipe)) output.append(buffer, n);
  const int status = pclose(pipe);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, output};
}

// h5py on a killed file: plain read-only opening is refused (the superblock
// still says a SWMR writer has it open); swmr=True reads every whole step.
constexpr char kH5pyCheck[] = R"(
import sys, h5py, numpy as np
path, flushed = sys.argv[1], int(sys.argv[2])
try:
    h5py.File(path, "r").close()
    sys.exit("plain h5py.File(path, 'r') opened a killed file: update docs/rollout_files.md")
except OSError as e:
    print("plain open refused:", e)
with h5py.File(path, "r", swmr=True) as f:
    assert f.attrs["complete"] == 0
    steps = min(d.shape[0] for d in f.values() if d.maxshape and d.maxshape[0] is None)
    assert steps >= flushed, (steps, flushed)
    t = np.arange(steps)[:, None, None]
    i = np.arange(6).reshape(1, 3, 2)
    q = f["q"][:steps]
    assert np.array_equal(q, np.sin(0.01 * t + 0.7 * i).astype(np.float32)), "q differs"
    assert np.isfinite(f["qd"][:steps]).all()
    assert list(f.attrs["q_names"]) == ["hip", "knee"]
print("ok", steps)
)";
#endif

TEST(RolloutPython, H5pyReadsAKilledFileWithSwmr) {
#ifndef LOCKSTEP_PYTHON_WITH_H5PY
  GTEST_SKIP() << "no python3 with h5py and matplotlib was found when configuring";
#else
  const TempDir dir;
  const std::string path = dir.file("killed.h5");
  const std::int64_t flushed = kill_writer_after_flushes(path, 2);
  ASSERT_GT(flushed, 0);
  std::ofstream(dir.file("check.py")) << kH5pyCheck;
  const auto [status, output] = run(std::string(LOCKSTEP_PYTHON_WITH_H5PY) + " " + dir.file("check.py") + " " +
                                    path + " " + std::to_string(flushed));
  EXPECT_EQ(status, 0) << output;
  EXPECT_NE(output.find("ok"), std::string::npos) << output;
#endif
}

TEST(RolloutPython, PlotScriptDrawsAKilledFile) {
#ifndef LOCKSTEP_PYTHON_WITH_H5PY
  GTEST_SKIP() << "no python3 with h5py and matplotlib was found when configuring";
#else
  const TempDir dir;
  const std::string path = dir.file("killed.h5");
  ASSERT_GT(kill_writer_after_flushes(path, 2), 0);
  const std::string picture = dir.file("killed.png");
  const auto [status, output] = run(std::string(LOCKSTEP_PYTHON_WITH_H5PY) + " " + LOCKSTEP_PLOT_ROLLOUT_SCRIPT +
                                    " " + path + " " + picture + " --envs 2 --dofs knee");
  ASSERT_EQ(status, 0) << output;
  std::ifstream png(picture, std::ios::binary);
  char magic[4] = {};
  png.read(magic, 4);
  EXPECT_EQ(std::string(magic, 4), "\x89PNG");
#endif
}

// Crash safety: a full disk -------------------------------------------------------------

constexpr rlim_t kFileSizeLimit = 128 * 1024;

// The child: with files limited to kFileSizeLimit bytes (writes beyond fail
// with EFBIG instead of raising SIGXFSZ), writes until the writer fails;
// reports the steps flushed before, then the error message. Then exits as a
// program does (HDF5 is not shut down at exit: io/rollout_hdf5.cpp).
[[noreturn]] void write_until_disk_full(const std::string& path, int report) {
  const rlimit limit{kFileSizeLimit, kFileSizeLimit};
  setrlimit(RLIMIT_FSIZE, &limit);
  signal(SIGXFSZ, SIG_IGN);
  std::int64_t flushed = -1;
  std::string message = "no error";
  try {
    RolloutFileOptions options;
    options.chunk_steps = 4;
    options.flush_seconds = 0;
    RolloutWriter writer(path, sample_steps(), sample_statics(), sample_attributes(), options);
    for (std::int64_t t = 0; t < 1000000; ++t) {
      write_sample_step(writer, t);
      writer.commit();
      flushed = writer.steps_flushed();
    }
    writer.close();
  } catch (const RolloutFileError& e) {
    message = e.what();
  } catch (const std::exception& e) {
    message = std::string("unexpected exception: ") + e.what();
  }
  const bool reported = write(report, &flushed, sizeof flushed) == sizeof flushed &&
                        write(report, message.data(), message.size()) == static_cast<ssize_t>(message.size());
  std::exit(reported ? 0 : 3);
}

// Runs child(path, fd) in a forked process that writes its report to fd and
// exits; returns its wait status and its report.
std::pair<int, std::string> run_child(void (*child)(const std::string&, int), const std::string& path) {
  int pipe_fds[2];
  if (pipe(pipe_fds) != 0) return {-1, "no pipe"};
  const pid_t pid = fork();
  if (pid < 0) return {-1, "no fork"};
  if (pid == 0) {
    close(pipe_fds[0]);
    child(path, pipe_fds[1]);
  }
  close(pipe_fds[1]);
  std::string report;
  char buffer[4096];
  for (ssize_t n; (n = read(pipe_fds[0], buffer, sizeof buffer)) > 0;) report.append(buffer, static_cast<std::size_t>(n));
  close(pipe_fds[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  return {status, report};
}

TEST(RolloutDiskFull, CommitFailsAndFlushedStepsStayReadable) {
  const TempDir dir;
  const std::string path = dir.file("full.h5");
  const auto [status, report] = run_child(write_until_disk_full, path);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "child status " << status;
  ASSERT_GE(report.size(), sizeof(std::int64_t));
  std::int64_t flushed = 0;
  std::memcpy(&flushed, report.data(), sizeof flushed);
  const std::string message = report.substr(sizeof flushed);

  EXPECT_NE(message.find(path), std::string::npos) << message;
  EXPECT_NE(message.find("File too large"), std::string::npos) << message;
  EXPECT_GT(flushed, 0) << message;
  EXPECT_LE(fs::file_size(path), kFileSizeLimit);
  const RolloutReader reader(path);
  EXPECT_FALSE(reader.complete());
  EXPECT_GE(reader.steps(), flushed);
  expect_sample_values(reader, 0, reader.steps());  // no step the file claims lost its data
}

// The child: writes 3 steps, limits files to 1 MiB beyond the file's size
// (room for the steps) and closes with a summary larger than that;
// reports the error and exits as a program does (which HDF5's shutdown at
// exit, trying to close the file again, once crashed).
[[noreturn]] void close_past_the_limit(const std::string& path, int report) {
  signal(SIGXFSZ, SIG_IGN);
  std::string message = "no error";
  try {
    RolloutFileOptions options;
    options.chunk_steps = 4;  // small chunks: the steps' fit in the room left
    RolloutWriter writer(path, sample_steps(), sample_statics(), sample_attributes(), options);
    for (std::int64_t t = 0; t < 3; ++t) {
      write_sample_step(writer, t);
      writer.commit();
    }
    const rlim_t size = static_cast<rlim_t>(fs::file_size(path)) + (1 << 20);
    const rlimit limit{size, size};
    setrlimit(RLIMIT_FSIZE, &limit);
    writer.close({{"summary", std::string(2 * size, 'x')}});
  } catch (const RolloutFileError& e) {
    message = e.what();
  }
  const bool reported = write(report, message.data(), message.size()) == static_cast<ssize_t>(message.size());
  std::exit(reported ? 0 : 3);
}

// A failure to mark the file complete says that its steps are written and
// how to open a file HDF5 left marked as open for writing.
TEST(RolloutDiskFull, AFailureToMarkTheFileCompleteSaysHowToOpenIt) {
  const TempDir dir;
  const std::string path = dir.file("summary.h5");
  const auto [status, message] = run_child(close_past_the_limit, path);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "child status " << status << ", said: " << message;
  EXPECT_NE(message.find(path + ": cannot"), std::string::npos) << message;
  EXPECT_NE(message.find("its 3 steps are written, but the file stays marked incomplete"), std::string::npos)
      << message;
  EXPECT_NE(message.find("`h5clear -s " + path + "` lets readers open it"), std::string::npos) << message;
}

// Errors --------------------------------------------------------------------------------

TEST(RolloutErrors, UnwritablePathFailsNamingIt) {
  const TempDir dir;
  const std::string missing = dir.file("no_such_directory/x.h5");
  EXPECT_THROW_WITH(RolloutWriter(missing, sample_steps(), {}, {}), RolloutFileError, missing);
  std::ofstream(dir.file("plain_file")) << "not a directory";
  const std::string under_file = dir.file("plain_file/x.h5");
  EXPECT_THROW_WITH(RolloutWriter(under_file, sample_steps(), {}, {}), RolloutFileError, under_file);
  const std::string directory = dir.file("a_directory");
  fs::create_directory(directory);
  EXPECT_THROW_WITH(RolloutWriter(directory, sample_steps(), {}, {}), RolloutFileError, directory);
  EXPECT_FALSE(fs::exists(directory + ".creating")) << "the file set up under another name is removed";
  if (geteuid() != 0) {  // root writes anywhere
    fs::create_directory(dir.file("read_only"));
    fs::permissions(dir.file("read_only"), fs::perms::owner_read | fs::perms::owner_exec);
    const std::string denied = dir.file("read_only/x.h5");
    EXPECT_THROW_WITH(RolloutWriter(denied, sample_steps(), {}, {}), RolloutFileError, denied);
  }
}

TEST(RolloutErrors, WriterRejectsBadArguments) {
  const TempDir dir;
  const std::string path = dir.file("bad.h5");
  const auto make = [&](std::vector<StepDataset> steps, std::vector<StaticDataset> statics = {},
                        std::vector<Attribute> attributes = {}, RolloutFileOptions options = {}) {
    RolloutWriter(path, std::move(steps), std::move(statics), std::move(attributes), options);
  };
  const StepDataset x{"x", ElementType::Float32, {2}, ""};
  EXPECT_THROW_WITH(make({}), std::invalid_argument, "at least one step dataset");
  EXPECT_THROW_WITH(make({{"", ElementType::Float32, {2}, ""}}), std::invalid_argument, "empty name");
  EXPECT_THROW_WITH(make({{"a/b", ElementType::Float32, {2}, ""}}), std::invalid_argument, "'a/b'");
  EXPECT_THROW_WITH(make({x, x}), std::invalid_argument, "duplicate dataset name 'x'");
  EXPECT_THROW_WITH(make({x}, {{"x", ElementType::Float32, {}, bytes_of(std::vector<float>{1}), ""}}),
                    std::invalid_argument, "duplicate dataset name 'x'");
  EXPECT_THROW_WITH(make({x}, {{"s", ElementType::Float64, {2}, bytes_of(std::vector<double>{1}), ""}}),
                    std::invalid_argument, "'s' has 8 bytes of data, its shape and type need 16");
  EXPECT_THROW_WITH(make({x}, {}, {{"complete", std::int64_t{1}}}), std::invalid_argument, "'complete' is reserved");
  EXPECT_THROW_WITH(make({x}, {}, {{"a", 1.0}, {"a", 2.0}}), std::invalid_argument, "duplicate attribute name 'a'");
  EXPECT_THROW_WITH(make({x}, {}, {{"", 1.0}}), std::invalid_argument, "empty name");
  for (int level : {-1, 10}) {
    RolloutFileOptions options;
    options.compression = level;
    EXPECT_THROW_WITH(make({x}, {}, {}, options), std::invalid_argument, "compression must be a gzip level in 0..9");
  }
  RolloutFileOptions options;
  options.chunk_steps = -1;
  EXPECT_THROW_WITH(make({x}, {}, {}, options), std::invalid_argument, "chunk_steps");
  options = {};
  options.buffer_steps = -1;
  EXPECT_THROW_WITH(make({x}, {}, {}, options), std::invalid_argument, "buffer_steps");
  // the two in-memory blocks within 1 GiB: x's 8-byte frames, 2^27 steps each
  options.buffer_steps = 1 << 27;
  EXPECT_THROW_WITH(make({x}, {}, {}, options), std::invalid_argument,
                    "buffer_steps 134217728 of 8 bytes each, in two blocks, would hold 2147483648 bytes in memory; at "
                    "most 1073741824");
  for (double seconds : {-1.0, std::nan(""), 1e300}) {
    options = {};
    options.flush_seconds = seconds;
    EXPECT_THROW_WITH(make({x}, {}, {}, options), std::invalid_argument, "flush_seconds");
  }
  EXPECT_FALSE(fs::exists(path)) << "argument errors come before the file is created";
  options = {};
  options.chunk_steps = 1 << 30;  // a huge chunk is clamped to 4 MiB, and so is the block it sets by default
  EXPECT_NO_THROW(make({x}, {}, {}, options));
}

TEST(RolloutErrors, WriterRejectsMisuse) {
  const TempDir dir;
  const std::string path = dir.file("misuse.h5");
  RolloutWriter writer(path, sample_steps(), {}, {});
  EXPECT_THROW_WITH(writer.frame(-1), std::invalid_argument, "index -1 is out of range [0, 5)");
  EXPECT_THROW_WITH(writer.frame(5), std::invalid_argument, "index 5 is out of range");
  EXPECT_THROW_WITH(writer.frame_as<double>(0), std::invalid_argument, "'q' holds float32, not float64");
  EXPECT_THROW_WITH(writer.close({{"format", std::string("mine")}}), std::invalid_argument, "'format' is reserved");
  write_sample_step(writer, 0);  // still open after a rejected close()
  writer.commit();
  writer.close();
  EXPECT_THROW_WITH(writer.commit(), RolloutFileError, "commit() after close()");
  EXPECT_THROW_WITH(writer.frame(0), RolloutFileError, "frame() after close()");
  EXPECT_THROW_WITH(writer.close(), RolloutFileError, "close() after close()");
  EXPECT_EQ(RolloutReader(path).steps(), 1);
}

TEST(RolloutErrors, ReaderRejectsBadFilesAndArguments) {
  const TempDir dir;
  const std::string missing = dir.file("missing.h5");
  EXPECT_THROW_WITH(RolloutReader{missing}, RolloutFileError, missing);
  const std::string text = dir.file("text.h5");
  std::ofstream(text) << "not HDF5";
  EXPECT_THROW_WITH(RolloutReader{text}, RolloutFileError, text);
  const std::string foreign = dir.file("foreign.h5");
  {
    const rollout_hdf5::Hdf5Lock lock = rollout_hdf5::lock_hdf5();
    const Handle access(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
    H5Pset_libver_bounds(access.get(), H5F_LIBVER_LATEST, H5F_LIBVER_LATEST);
    const Handle file(H5Fcreate(foreign.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, access.get()), H5Fclose);
  }
  EXPECT_THROW_WITH(RolloutReader{foreign}, RolloutFileError, "not a lockstep rollout file");

  const std::string path = dir.file("good.h5");
  write_sample(path, 4);
  const RolloutReader reader(path);
  EXPECT_THROW_WITH(reader.read("nope"), std::invalid_argument, "no dataset 'nope'");
  EXPECT_THROW_WITH(reader.shape("nope"), std::invalid_argument, "no dataset 'nope'");
  EXPECT_THROW_WITH(reader.read_as<double>("q"), std::invalid_argument, "'q' holds float32, not float64");
  EXPECT_THROW_WITH(reader.read("q", 3, 2), std::invalid_argument, "steps [3, 2)");
  EXPECT_THROW_WITH(reader.read("q", -1, 2), std::invalid_argument, "not within [0, 4)");
  EXPECT_THROW_WITH(reader.read("masses", 0, 1), std::invalid_argument, "'masses' is static");
}

}  // namespace
}  // namespace lockstep
