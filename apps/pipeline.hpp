#pragma once
/// An ordered parallel map with bounded look-ahead: items 0..count-1 are produced by a pool of
/// worker threads, at most `depth` of them ahead of the consumer, and taken in index order. The
/// producer must be pure for the item (same index, same result, whichever worker runs it), so the
/// consumer sees exactly what a sequential loop would; the bound keeps memory at `depth` items.
#include <condition_variable>
#include <cstddef>
#include <exception>
#include <functional>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>
#include <vector>

namespace planeslam::app {

/// Threads to use: `requested` when positive, else the machine's cores (at least 1).
std::size_t ResolveThreads(int requested);

template <typename T>
class OrderedPipeline {
 public:
  /// `produce(index, worker)` makes item `index` on worker `worker` (0..workers-1, for per-worker
  /// state such as a detector); an exception it throws is rethrown by Take for that item.
  OrderedPipeline(std::size_t count, std::size_t workers, std::size_t depth,
                  std::function<T(std::size_t, std::size_t)> produce)
      : produce_(std::move(produce)), count_(count), depth_(depth < 1 ? 1 : depth),
        slots_(depth_) {
    for (std::size_t w = 0; w < (workers < 1 ? 1 : workers); ++w) {
      workers_.emplace_back([this, w] { Work(w); });
    }
  }
  ~OrderedPipeline() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    changed_.notify_all();
    for (std::thread& t : workers_) t.join();
  }
  OrderedPipeline(const OrderedPipeline&) = delete;
  OrderedPipeline& operator=(const OrderedPipeline&) = delete;

  /// The next item in index order (blocks until it is made); call at most `count` times.
  T Take() {
    std::unique_lock<std::mutex> lock(mutex_);
    Slot& slot = slots_[taken_ % depth_];
    changed_.wait(lock, [&] { return slot.ready; });
    slot.ready = false;
    ++taken_;
    std::exception_ptr error = std::exchange(slot.error, nullptr);
    std::optional<T> value = std::exchange(slot.value, std::nullopt);
    lock.unlock();
    changed_.notify_all();
    if (error) std::rethrow_exception(error);
    return std::move(*value);
  }

 private:
  struct Slot {
    bool ready = false;
    std::optional<T> value;
    std::exception_ptr error;
  };

  void Work(std::size_t worker) {
    for (;;) {
      std::size_t index = 0;
      {
        std::unique_lock<std::mutex> lock(mutex_);
        // Item i reuses the slot of item i - depth, free once that one was taken.
        changed_.wait(lock, [&] { return stop_ || claimed_ >= count_ || claimed_ < taken_ + depth_; });
        if (stop_ || claimed_ >= count_) return;
        index = claimed_++;
      }
      std::optional<T> value;
      std::exception_ptr error;
      try {
        value.emplace(produce_(index, worker));
      } catch (...) {
        error = std::current_exception();
      }
      {
        std::lock_guard<std::mutex> lock(mutex_);
        Slot& slot = slots_[index % depth_];
        slot.value = std::move(value);
        slot.error = error;
        slot.ready = true;
      }
      changed_.notify_all();
    }
  }

  std::function<T(std::size_t, std::size_t)> produce_;
  std::size_t count_, depth_;
  std::vector<Slot> slots_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::size_t claimed_ = 0, taken_ = 0;
  bool stop_ = false;
  std::vector<std::thread> workers_;
};

/// Runs `task(i)` for i in 0..count-1 on `threads` threads (inline when 1); tasks must touch
/// disjoint state. Every task runs; then the exception of the lowest failing index, if any, is
/// rethrown (the one a sequential loop would have met first).
void ParallelFor(std::size_t count, std::size_t threads,
                 const std::function<void(std::size_t)>& task);

}  // namespace planeslam::app
