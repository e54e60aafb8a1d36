// Structure-of-arrays storage for N environment copies, padded to whole
// blocks of `width` lanes: element k of copy c lives at
// data[((c / width) * size + k) * width + c % width], so one block holds each
// field's lanes contiguously ([block][field][lane]) for aligned SIMD loads.
#pragma once

#include <Eigen/Core>

#include <cstddef>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>

namespace lockstep {

template <class T>
class BatchArray {
 public:
  static constexpr std::size_t kAlignment = 64;

  BatchArray() = default;
  BatchArray(int copies, int size, int width, T fill = T(0))
      : copies_(copies), size_(size), width_(width), blocks_((copies + width - 1) / width) {
    if (copies < 0 || size < 0 || width <= 0)
      throw std::invalid_argument("BatchArray: copies " + std::to_string(copies) + ", size " + std::to_string(size) +
                                  ", width " + std::to_string(width));
    count_ = static_cast<std::size_t>(blocks_) * size_ * width_;
    data_.reset(static_cast<T*>(::operator new[](std::max<std::size_t>(count_, 1) * sizeof(T), std::align_val_t(kAlignment))));
    std::fill(data_.get(), data_.get() + count_, fill);
  }
  BatchArray(const BatchArray& other) : BatchArray(other.copies_, other.size_, other.width_) {
    std::copy(other.data(), other.data() + count_, data_.get());
  }
  BatchArray& operator=(const BatchArray& other) {
    if (this != &other) *this = BatchArray(other);
    return *this;
  }
  BatchArray(BatchArray&&) noexcept = default;
  BatchArray& operator=(BatchArray&&) noexcept = default;

  int copies() const { return copies_; }
  int size() const { return size_; }    // values per copy
  int width() const { return width_; }  // lanes per block
  int blocks() const { return blocks_; }

  T* block(int b) { return data_.get() + static_cast<std::size_t>(b) * size_ * width_; }
  const T* block(int b) const { return data_.get() + static_cast<std::size_t>(b) * size_ * width_; }
  T* data() { return data_.get(); }
  const T* data() const { return data_.get(); }

  T& at(int copy, int k) { return data_[index(copy, k)]; }
  const T& at(int copy, int k) const { return data_[index(copy, k)]; }
  // One copy's values with stride width(): element k at lane(copy)[k * width()]
  // (for loops over many elements of a copy, without at()'s division).
  T* lane(int copy) { return data_.get() + index(copy, 0); }
  const T* lane(int copy) const { return data_.get() + index(copy, 0); }

  // One copy's values as a double vector, and back.
  Eigen::VectorXd get(int copy) const {
    check_copy(copy);
    Eigen::VectorXd out(size_);
    for (int k = 0; k < size_; ++k) out[k] = static_cast<double>(at(copy, k));
    return out;
  }
  // values: any double vector (fixed-size ones and segments bind without a copy)
  void set(int copy, const Eigen::Ref<const Eigen::VectorXd>& values) {
    check_copy(copy);
    if (values.size() != size_)
      throw std::invalid_argument("BatchArray::set: copy " + std::to_string(copy) + " expects " + std::to_string(size_) +
                                  " values, got " + std::to_string(values.size()));
    T* out = lane(copy);
    for (int k = 0; k < size_; ++k) out[k * width_] = static_cast<T>(values[k]);
  }
  // One copy's values all set to `value`; from the same copy of `source`
  // (an array of the same shape); whether any is nonzero. None allocates.
  void fill(int copy, T value) {
    check_copy(copy);
    T* out = lane(copy);
    for (int k = 0; k < size_; ++k) out[k * width_] = value;
  }
  void set_from(int copy, const BatchArray& source) {
    check_copy(copy);
    if (source.size_ != size_ || source.width_ != width_)
      throw std::invalid_argument("BatchArray::set_from: arrays of different shapes");
    const T* in = source.lane(copy);
    T* out = lane(copy);
    for (int k = 0; k < size_; ++k) out[k * width_] = in[k * width_];
  }
  bool any_nonzero(int copy) const {
    check_copy(copy);
    const T* in = lane(copy);
    for (int k = 0; k < size_; ++k)
      if (in[k * width_] != T(0)) return true;
    return false;
  }
  // The same values in every copy, padding lanes included.
  void set_all(const Eigen::VectorXd& values) {
    for (int c = 0; c < blocks_ * width_; ++c)
      for (int k = 0; k < size_; ++k) data_[index(c, k)] = static_cast<T>(values[k]);
  }

 private:
  struct AlignedDelete {
    void operator()(T* p) const { ::operator delete[](p, std::align_val_t(kAlignment)); }
  };
  std::size_t index(int copy, int k) const {
    return (static_cast<std::size_t>(copy / width_) * size_ + k) * width_ + copy % width_;
  }
  void check_copy(int copy) const {
    if (copy < 0 || copy >= copies_)
      throw std::out_of_range("copy index " + std::to_string(copy) + " outside [0, " + std::to_string(copies_) + ")");
  }

  int copies_ = 0, size_ = 0, width_ = 1, blocks_ = 0;
  std::size_t count_ = 0;
  std::unique_ptr<T[], AlignedDelete> data_;
};

}  // namespace lockstep
