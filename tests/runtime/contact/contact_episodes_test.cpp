// A tool's touch and leave events as contact episodes (ContactEpisodes,
// docs/tools.md "One tick", step 5) on tick sequences written by hand.

#include "palpate/runtime/contact/contact_episodes.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace palpate::detail {
namespace {

constexpr double kTick_s = 0.001;  // 1 kHz

/// The events of a state per tick, as letters: F free, T touching, G
/// grasping; "t"/"l" for a touch/leave at that tick, "." for none.
std::string events_of(const std::string& states, ContactEpisodes& episodes, int first_tick = 0) {
  std::string out;
  for (std::size_t i = 0; i < states.size(); ++i) {
    const ToolState state = states[i] == 'T'   ? ToolState::kTouching
                            : states[i] == 'G' ? ToolState::kGrasping
                                               : ToolState::kFree;
    const auto event = episodes.step(state, (first_tick + static_cast<int>(i)) * kTick_s);
    out += !event ? '.' : *event == ToolEventKind::kTouch ? 't' : 'l';
  }
  return out;
}

TEST(ContactEpisodes, AContactLostForATickOrTwoIsOneEpisode) {
  // A hook cutting through what it touches: contact on every other tick.
  ContactEpisodes episodes;
  EXPECT_EQ(events_of("FFTFTFTFFTFT", episodes), "..t.........");
  EXPECT_EQ(episodes.shown(), ToolState::kTouching);
}

TEST(ContactEpisodes, ALeaveIsSentOnceTheToolHasBeenFreeFor10Milliseconds) {
  ContactEpisodes episodes;
  // Free from tick 3: the leave at the 11th free tick (tick 13, 10 ms after
  // tick 3), not before; then nothing; a new touch is a new episode.
  EXPECT_EQ(events_of("TTT" + std::string(10, 'F') + "FFF" + "TT", episodes),
            "t" + std::string(12, '.') + "l" + ".." + "t.");
}

TEST(ContactEpisodes, AGapOf9MillisecondsIsNotALeave) {
  ContactEpisodes episodes;
  EXPECT_EQ(events_of("T" + std::string(9, 'F') + "T", episodes), "t" + std::string(10, '.'));
}

TEST(ContactEpisodes, AnEndingSessionSendsAPendingLeaveAtOnce) {
  ContactEpisodes episodes;
  EXPECT_EQ(events_of("TTFF", episodes), "t...");
  const auto event = episodes.step(ToolState::kFree, 4 * kTick_s, /*ending=*/true);
  ASSERT_TRUE(event.has_value());
  EXPECT_EQ(*event, ToolEventKind::kLeave);
  EXPECT_EQ(episodes.shown(), ToolState::kFree);
  // Nothing pending any more.
  EXPECT_FALSE(episodes.step(ToolState::kFree, 5 * kTick_s, /*ending=*/true).has_value());
}

TEST(ContactEpisodes, AGraspIsShownAtOnceAndLettingGoIntoFreeAirSendsNoLeave) {
  ContactEpisodes episodes;
  // touching → grasping (the grasp's own event) → free (its release):
  // no leave; grasping → touching → free: a leave, 10 ms later.
  EXPECT_EQ(events_of("TTGGGFFF", episodes), "t.......");
  EXPECT_EQ(episodes.shown(), ToolState::kFree);
  EXPECT_EQ(events_of("GGTT" + std::string(11, 'F'), episodes, 8), std::string(14, '.') + "l");
}

}  // namespace
}  // namespace palpate::detail
