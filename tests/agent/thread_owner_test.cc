// Thread ownership (thread_owner.h): the first thread to call owns an object; a call from any other
// is caught, counted where the 1 kHz loop must not abort and fatal elsewhere; the loop's two sides
// and the uplink's backlog are guarded by it.
#include "idms/agent/thread_owner.h"

#include <gtest/gtest.h>

#include <memory>
#include <thread>

#include "alloc_counter.h"
#include "backlog.h"
#include "hex_loop.h"
#include "idms/agent/device.h"
#include "idms/agent/loop.h"
#include "idms/agent/setup.h"
#include "idms/sim/model_io.h"

namespace idms::test {
namespace {

using agent::ThreadOwner;

// Runs f on a thread of its own, to completion.
template <typename F>
void OnAnotherThread(F f) {
  std::thread(f).join();
}

TEST(ThreadOwner, TheFirstCallerOwnsAndOthersAreCounted) {
  ThreadOwner owner("the test object", ThreadOwner::OnViolation::kCount);
  EXPECT_FALSE(owner.owned_by_this_thread());
  EXPECT_TRUE(owner.Check("first"));
  EXPECT_TRUE(owner.owned_by_this_thread());
  EXPECT_TRUE(owner.Check("again"));
  bool other = true;
  OnAnotherThread([&] { other = owner.Check("from another thread"); });
  EXPECT_FALSE(other);
  EXPECT_EQ(owner.violations(), 1u);
  EXPECT_TRUE(owner.Check("still the owner's"));
  // Handed on: the next caller owns it, and the first is now the stranger.
  owner.Release();
  OnAnotherThread([&] { other = owner.Check("the new owner"); });
  EXPECT_TRUE(other);
  EXPECT_FALSE(owner.Check("the old owner"));
  EXPECT_EQ(owner.violations(), 2u);
}

TEST(ThreadOwner, TheCheckAllocatesNothing) {
  ThreadOwner owner("the test object", ThreadOwner::OnViolation::kCount);
  owner.Check("bind");
  const int64_t before = AllocationCount();
  for (int i = 0; i < 1000; ++i) owner.Check("tick");
  EXPECT_EQ(AllocationCount() - before, 0);
}

TEST(ThreadOwnerDeathTest, AbortsNamingTheCallAndTheObject) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_DEATH(
      {
        ThreadOwner owner("the test object", ThreadOwner::OnViolation::kAbort);
        owner.Check("bind");
        OnAnotherThread([&] { owner.Check("Stranger::Call"); });
      },
      "BUG: Stranger::Call called from a thread that does not own the test object");
}

// The uplink's backlog is the I/O thread's: a sample accepted from elsewhere aborts, in any build.
TEST(ThreadOwnerDeathTest, TheBacklogBelongsToTheIoThread) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_DEATH(
      {
        agent::Backlog backlog(16);
        agent::TickSample s;
        s.tick = 1;
        backlog.Accept(s);
        s.tick = 2;
        OnAnotherThread([&] { backlog.Accept(s); });
      },
      "BUG: Backlog::Accept called from a thread that does not own the uplink's backlog");
}

using test::HexLoop;

// A tick from a thread other than the loop's, and the I/O side's rings from a thread other than
// the I/O thread's, are caught: counted in a release build (the loop must not abort), fatal in a
// debug build.
TEST(ThreadOwnerDeathTest, TheLoopsTwoSidesBelongToTheirThreads) {
  Model model;
  std::unique_ptr<agent::Device> device;
  std::unique_ptr<agent::Loop> loop = HexLoop(&model, &device);
  ASSERT_TRUE(device);
  // The loop thread ticks; the I/O thread drains. Here one test thread is both: no violation.
  const int64_t now = agent::MonotonicNs();
  loop->Tick(now, now + 1000000000);
  loop->samples().consume_all([](const agent::TickSample&) {});
  EXPECT_EQ(loop->wrong_thread_calls(), 0u);
#ifdef NDEBUG
  OnAnotherThread([&] { loop->Tick(now + 1000000, now + 1000000000); });
  EXPECT_EQ(loop->wrong_thread_calls(), 1u);
  // The first tick published a surface: popped and handed back from the wrong thread, twice caught.
  int32_t index = -1;
  bool popped = false;
  OnAnotherThread([&] {
    popped = loop->PopMeshSlot(&index);
    if (popped) loop->ReleaseMeshSlot(index);
  });
  EXPECT_TRUE(popped);
  EXPECT_EQ(loop->wrong_thread_calls(), 3u);
  // The owners are unchanged: their own calls still pass.
  loop->Tick(now + 2000000, now + 1000000000);
  loop->samples().consume_all([](const agent::TickSample&) {});
  EXPECT_EQ(loop->wrong_thread_calls(), 3u);
#else
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_DEATH(OnAnotherThread([&] { loop->Tick(now + 1000000, now + 1000000000); }),
               "BUG: Loop::Tick called from a thread that does not own the loop's tick side");
  EXPECT_DEATH(OnAnotherThread([&] {
                 loop->PushCommand(agent::LoopCommand{agent::LoopCommand::kTweezersDevice, 0});
               }),
               "BUG: Loop::PushCommand called from a thread that does not own the loop's I/O side");
#endif
}

}  // namespace
}  // namespace idms::test
