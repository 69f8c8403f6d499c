#include "serving_thread.hpp"

#include <pthread.h>
#include <sched.h>
#include <spdlog/spdlog.h>

#include <exception>
#include <future>

#include "palpate/core/error.hpp"

namespace palpate::daemon {

namespace {
/// The waitset's attachment of the wake-up guard; a reader's is its index.
constexpr dds_attach_t kWake = -1;
/// Readers served (requests, poses, commands), with room to spare.
constexpr std::size_t kMaxReaders = 8;
}  // namespace

ServingThread::ServingThread(dds_entity_t participant, ServeMode mode,
                             const RealtimeOptions& realtime)
    : mode_(mode), realtime_(realtime) {
  PALPATE_DEMAND(mode != ServeMode::kListener);
  readers_.reserve(kMaxReaders);
  if (mode_ == ServeMode::kWaitset) {
    waitset_ = dds::Entity(
        dds::check(dds_create_waitset(participant), "creating the serving thread's waitset"));
    wake_ = dds::Entity(dds::check(dds_create_guardcondition(participant),
                                   "creating the serving thread's guard condition"));
    dds::check(dds_waitset_attach(waitset_.get(), wake_.get(), kWake),
               "attaching the serving thread's guard condition");
  }
}

ServingThread::~ServingThread() { stop(); }

void ServingThread::add(dds_entity_t reader, dds_on_data_available_fn serve, void* arg) {
  PALPATE_DEMAND(!thread_.joinable() && readers_.size() < kMaxReaders);
  if (mode_ == ServeMode::kWaitset) {
    // Any sample there, read or not: the serve functions take them all.
    const dds_entity_t condition = dds::check(dds_create_readcondition(reader, DDS_ANY_STATE),
                                              "creating a serving thread's read condition");
    dds::check(
        dds_waitset_attach(waitset_.get(), condition, static_cast<dds_attach_t>(readers_.size())),
        "attaching a reader to the serving thread's waitset");
  }
  readers_.push_back({reader, serve, arg});
}

void ServingThread::start() {
  std::promise<void> started;
  std::future<void> applied = started.get_future();
  thread_ = std::thread([this, &started] {
    pthread_setname_np(pthread_self(), "palpate-serve");
    try {
      realtime::apply_to_this_thread(realtime_);
    } catch (...) {
      started.set_exception(std::current_exception());
      return;
    }
    started.set_value();
    if (mode_ == ServeMode::kWaitset)
      run_waitset();
    else
      run_busy();
  });
  try {
    applied.get();
  } catch (...) {
    thread_.join();
    throw;
  }
}

void ServingThread::stop() {
  if (!thread_.joinable()) return;
  stopping_.store(true, std::memory_order_release);
  if (wake_) dds_set_guardcondition(wake_.get(), true);
  thread_.join();
}

// Sleeps until a reader has data, then serves it: the wake-up a listener
// does not have, on a thread of palpated's choosing.
void ServingThread::run_waitset() {
  dds_attach_t triggered[kMaxReaders + 1];
  while (!stopping_.load(std::memory_order_acquire)) {
    const dds_return_t n =
        dds_waitset_wait(waitset_.get(), triggered, kMaxReaders + 1, DDS_INFINITY);
    if (n < 0) {
      spdlog::error("event=serving_failed error=\"waiting for poses and requests: {}\"",
                    dds_strretcode(n));
      return;
    }
    for (dds_return_t i = 0; i < n; ++i)
      if (triggered[i] != kWake) {
        const Reader& r = readers_[static_cast<std::size_t>(triggered[i])];
        r.serve(r.reader, r.arg);
      }
  }
}

// Polls every reader (a take that finds nothing is about a microsecond),
// yielding the CPU between rounds: to a thread of the same priority (Cyclone's
// receive thread, when it shares the CPU) under SCHED_FIFO, to any other under
// the normal scheduling. Never sleeps.
void ServingThread::run_busy() {
  while (!stopping_.load(std::memory_order_acquire)) {
    for (const Reader& r : readers_) r.serve(r.reader, r.arg);
    sched_yield();
  }
}

}  // namespace palpate::daemon
