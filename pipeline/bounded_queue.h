#pragma once
// A blocking queue of bounded capacity joining two threads (docs/design.md §8): Push blocks while
// the queue is full (backpressure: the producer waits instead of the memory growing), Pop
// blocks while it is empty. Close() wakes both sides: Push then refuses, Pop drains what is
// left and then returns nothing.

#include <cassert>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <mutex>
#include <optional>

namespace omni {

template <typename T>
class BoundedQueue {
 public:
  explicit BoundedQueue(size_t capacity) : capacity_(capacity) { assert(capacity > 0); }

  // Waits for room; false (and the item dropped) when the queue was closed.
  bool Push(T item) {
    std::unique_lock<std::mutex> lock(mutex_);
    if (items_.size() >= capacity_) {
      const auto start = std::chrono::steady_clock::now();
      not_full_.wait(lock, [&] { return closed_ || items_.size() < capacity_; });
      blocked_seconds_ +=
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      ++blocked_pushes_;
    }
    if (closed_) return false;
    items_.push_back(std::move(item));
    max_size_ = std::max(max_size_, items_.size());
    not_empty_.notify_one();
    return true;
  }

  // Waits for an item; nothing once the queue is closed and empty.
  std::optional<T> Pop() {
    return PopLatest([](const T&) { return false; }, [](const T&) {});
  }

  // Pop, except that when a queued item after the first satisfies `supersedes` (it makes every
  // item before it useless), the items before the last such item are dropped unseen, each
  // handed to `dropped` first, and that item is returned. Both run under the queue's lock.
  template <typename Supersedes, typename Dropped>
  std::optional<T> PopLatest(Supersedes supersedes, Dropped dropped) {
    std::unique_lock<std::mutex> lock(mutex_);
    not_empty_.wait(lock, [&] { return closed_ || !items_.empty(); });
    if (items_.empty()) return std::nullopt;
    size_t first = 0;
    for (size_t i = items_.size(); i-- > 1;) {
      if (supersedes(static_cast<const T&>(items_[i]))) {
        first = i;
        break;
      }
    }
    for (size_t i = 0; i < first; ++i) dropped(static_cast<const T&>(items_[i]));
    items_.erase(items_.begin(), items_.begin() + static_cast<std::ptrdiff_t>(first));
    T item = std::move(items_.front());
    items_.pop_front();
    not_full_.notify_all();
    return item;
  }

  void Close() {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
    not_full_.notify_all();
    not_empty_.notify_all();
  }

  size_t capacity() const { return capacity_; }
  size_t Size() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return items_.size();
  }
  // The most items held at once so far (never above the capacity).
  size_t MaxSize() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return max_size_;
  }
  // Pushes that had to wait for room, and the time they waited in total.
  size_t BlockedPushes() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return blocked_pushes_;
  }
  double BlockedSeconds() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return blocked_seconds_;
  }

 private:
  const size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable not_full_, not_empty_;
  std::deque<T> items_;
  bool closed_ = false;
  size_t max_size_ = 0;
  size_t blocked_pushes_ = 0;
  double blocked_seconds_ = 0.0;
};

}  // namespace omni
