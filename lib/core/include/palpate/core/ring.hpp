#pragma once
/// @file
/// A fixed-capacity FIFO that drops its oldest element when full: what a
/// haptic loop keeps of answers and events it has not read yet, without
/// allocating after construction (the tool client's pending and late
/// answers, the C API's log of answers and events).

#include <array>
#include <cstddef>

namespace palpate {

template <typename T, std::size_t N>
class Ring {
 public:
  /// @returns false when the oldest element had to be dropped.
  bool push(const T& value) {
    const bool room = count_ < N;
    if (!room) pop();
    items_[(head_ + count_) % N] = value;
    ++count_;
    return room;
  }
  bool empty() const { return count_ == 0; }
  std::size_t size() const { return count_; }
  const T& front() const { return items_[head_]; }
  void pop() {
    head_ = (head_ + 1) % N;
    --count_;
  }

 private:
  std::array<T, N> items_{};
  std::size_t head_ = 0, count_ = 0;
};

}  // namespace palpate
