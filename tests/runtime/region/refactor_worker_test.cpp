// The implicit step's worker thread (lib/runtime/src/region/refactor_worker):
// the cuts made while a work runs reach it until it closes its queue, those
// made after are kept for the owner, the result and what the work threw are
// handed over, and the work runs as an ordinary thread. Every wait is on a
// promise the test sets: nothing depends on timing.

#include "palpate/runtime/region/refactor_worker.hpp"

#include <gtest/gtest.h>
#include <sched.h>
#include <sys/resource.h>
#include <unistd.h>

#include <future>
#include <memory>
#include <stdexcept>
#include <vector>

namespace palpate::detail {
namespace {

TEST(CutQueue, HandsOverBatchesUntilItFindsNoneAndCloses) {
  CutQueue queue;
  const std::vector<int> first{4, 7}, second{9};
  EXPECT_TRUE(queue.offer(first));
  EXPECT_TRUE(queue.offer(second));
  std::vector<int> batch{1};  // emptied first
  ASSERT_TRUE(queue.take(batch));
  EXPECT_EQ(batch, (std::vector<int>{4, 7, 9}));
  EXPECT_FALSE(queue.take(batch)) << "nothing left: the queue closes";
  EXPECT_TRUE(batch.empty());
  EXPECT_FALSE(queue.offer(first)) << "closed: the cutting thread keeps them";
  EXPECT_FALSE(queue.take(batch));
}

// The work takes what was cut before it starts, closes its queue, and
// returns only once the test has cut again: that cut is the owner's.
TEST(RefactorWorker, CutsAfterTheQueueClosesAreTheOwners) {
  std::promise<void> go, closed, finish;
  auto go_f = go.get_future();
  auto closed_f = closed.get_future();
  auto finish_f = finish.get_future();
  RefactorWorker<std::unique_ptr<std::vector<int>>> worker;
  EXPECT_FALSE(worker.running());
  worker.start([&](CutQueue& cuts) {
    go_f.wait();
    auto taken = std::make_unique<std::vector<int>>();
    std::vector<int> batch;
    while (cuts.take(batch)) taken->insert(taken->end(), batch.begin(), batch.end());
    closed.set_value();
    finish_f.wait();
    return taken;
  });
  EXPECT_TRUE(worker.running());  // not ASSERT: returning now would leave the work waiting
  const std::vector<int> before{1, 2}, after{3};
  worker.note_cut(before);
  go.set_value();
  closed_f.wait();
  EXPECT_TRUE(worker.running()) << "finished, but not taken";
  worker.note_cut(after);
  finish.set_value();
  const auto result = worker.take();
  EXPECT_FALSE(worker.running());
  EXPECT_FALSE(worker.finished());
  EXPECT_EQ(*result, before);
  EXPECT_EQ(worker.cut_after(), after);
}

TEST(RefactorWorker, TakeRethrowsWhatTheWorkThrew) {
  RefactorWorker<std::unique_ptr<int>> worker;
  worker.start([](CutQueue&) -> std::unique_ptr<int> { throw std::runtime_error("not SPD"); });
  EXPECT_THROW(worker.take(), std::runtime_error);
  EXPECT_FALSE(worker.running());
}

// The work runs under SCHED_OTHER at nice 10 at least (an unprivileged
// process already above 10 cannot come back down), whatever its owner's.
TEST(RefactorWorker, TheWorkRunsAsAnOrdinaryThread) {
  struct Scheduling {
    int policy = -1, nice = -100;
  };
  RefactorWorker<std::unique_ptr<Scheduling>> worker;
  worker.start([](CutQueue&) {
    auto s = std::make_unique<Scheduling>();
    s->policy = sched_getscheduler(0);
    s->nice = getpriority(PRIO_PROCESS, static_cast<id_t>(gettid()));
    return s;
  });
  const auto s = worker.take();
  EXPECT_EQ(s->policy, SCHED_OTHER);
  EXPECT_GE(s->nice, 10);
}

TEST(RefactorWorker, TheDestructorWaitsForTheWork) {
  std::promise<void> go;
  auto go_f = go.get_future();
  bool done = false;
  {
    RefactorWorker<std::unique_ptr<int>> worker;
    worker.start([&](CutQueue&) {
      go_f.wait();
      done = true;
      return std::make_unique<int>(1);
    });
    go.set_value();
  }
  EXPECT_TRUE(done);
}

}  // namespace
}  // namespace palpate::detail
