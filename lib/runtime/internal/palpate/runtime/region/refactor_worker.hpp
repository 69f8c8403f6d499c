#pragma once
// Private to palpate_runtime: the implicit step's worker thread
// (region_implicit_step.hpp). While the ticks go on with the factorization
// they hold, the worker factors a snapshot of A on a thread of its own and
// then computes what the cuts made since the snapshot add to it; the step
// takes the result over at a later cut. What is computed is the step's
// business (the work it starts); the thread, its priority, the queue of the
// cuts it shares with the worker, and the handoff are this unit's.

#include <chrono>
#include <future>
#include <memory>
#include <mutex>
#include <span>
#include <utility>
#include <vector>

namespace palpate::detail {

/// The vertices cut since a worker's snapshot, shared by the thread that
/// cuts and the worker: the worker takes them batch by batch and, when it
/// finds none left, closes the queue; vertices cut after that are for the
/// cutting thread to handle itself.
///
/// Threads: any two, under one mutex. Allocates when it grows (the cutting
/// thread's offer(), never a tick).
class CutQueue {
 public:
  /// Adds @p vertices for the worker, unless it has closed the queue.
  /// @return whether they were added (false: the queue is closed).
  bool offer(std::span<const int> vertices);
  /// Moves the vertices offered since the last take into @p batch (emptied
  /// first). @return false, closing the queue, when there were none.
  bool take(std::vector<int>& batch);

 private:
  std::mutex mutex_;
  std::vector<int> vertices_;
  bool closed_ = false;
};

/// Lowers the calling thread to an ordinary one: SCHED_OTHER at nice 10, on
/// any CPU. A thread started from the haptic thread inherits its SCHED_FIFO
/// and its CPUs, where a factorization of hundreds of milliseconds would
/// starve the tick it serves (docs/realtime.md).
void become_background_thread();

/// One background job at a time for ImplicitRegionStep: start() runs a
/// work, `Result work(CutQueue&)`, on a new thread lowered by
/// become_background_thread(); note_cut() hands the vertices cut meanwhile
/// to the work's queue, or keeps them in cut_after() once the work has
/// closed it; take() hands the work's result over.
///
/// Ownership: holds the work and the queue (shared with the work's thread)
/// until take(); the work must own, or outlive, whatever it reads.
/// Threads: every member is called by the one thread that owns the step
/// (the one that cuts); the work runs on its own thread and meets the
/// owner only in the queue and in take(). Allocates in start() and
/// note_cut(), never in running(), finished() or take(); the destructor
/// waits for a work under way.
template <class Result>
class RefactorWorker {
 public:
  RefactorWorker() = default;
  ~RefactorWorker() {
    if (pending_.valid()) pending_.wait();
  }
  RefactorWorker(const RefactorWorker&) = delete;
  RefactorWorker& operator=(const RefactorWorker&) = delete;

  /// Starts @p work (callable as `Result(CutQueue&)`, moved to its thread)
  /// with an empty queue. Precondition: none under way (!running()).
  template <class Work>
  void start(Work work) {
    queue_ = std::make_shared<CutQueue>();
    after_.clear();
    pending_ = std::async(std::launch::async,
                          [work = std::move(work), queue = queue_]() mutable -> Result {
                            become_background_thread();
                            return work(*queue);
                          });
  }

  /// Whether a work was started and its result not yet taken.
  bool running() const { return pending_.valid(); }
  /// Whether the work under way has finished (its result ready), without waiting.
  bool finished() const {
    using namespace std::chrono_literals;
    return pending_.valid() && pending_.wait_for(0s) == std::future_status::ready;
  }

  /// The vertices of a cut made while the work runs: the work's, if its
  /// queue is still open, else kept in cut_after(). Precondition: running().
  void note_cut(std::span<const int> vertices) {
    if (!queue_->offer(vertices)) after_.insert(after_.end(), vertices.begin(), vertices.end());
  }
  /// The vertices cut after the work closed its queue, which its result
  /// does not cover (until the next start()).
  const std::vector<int>& cut_after() const { return after_; }

  /// Waits for the work and hands its result over; rethrows what the work
  /// threw. Precondition: running(); afterwards !running().
  Result take() {
    Result result = pending_.get();
    queue_.reset();
    return result;
  }

 private:
  std::future<Result> pending_;
  std::shared_ptr<CutQueue> queue_;
  std::vector<int> after_;
};

}  // namespace palpate::detail
