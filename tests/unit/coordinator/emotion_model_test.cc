// The emotion model on a fake timeline: exact crossing times, hysteresis,
// defaults against the thesis' 5-40 s.
#include "services/coordinator/core/emotion_model.h"

#include <cmath>

#include "absl/strings/match.h"
#include "gtest/gtest.h"

namespace kinemo::coordinator {
namespace {

using common::v1::ACTION_IDLE;
using common::v1::ACTION_KISSES;
using common::v1::ACTION_SHOUTING;
using common::v1::EMOTION_ANGRY;
using common::v1::EMOTION_HAPPY;
using common::v1::EMOTION_NEUTRAL;

EmotionParams Defaults() { return *ResolveEmotionParams(v1::EmotionModelOptions()); }

// Time for sustained kisses at `intensity` to take an angry robot to happy,
// found by advancing in `step_s` increments.
double TimeToHappy(double intensity, double step_s) {
  EmotionModel m(Defaults(), EMOTION_ANGRY, 0.0);
  std::vector<EmotionChange> changes;
  m.SetAction(0.0, ACTION_KISSES, intensity, &changes);
  for (double t = step_s; t < 1000; t += step_s) {
    m.AdvanceTo(t, &changes);
    for (const auto& c : changes) {
      if (c.to == EMOTION_HAPPY) return c.time_s;
    }
  }
  return -1;
}

TEST(EmotionModel, KissesTakeAngryThroughNeutralToHappyInsideTheThesisRange) {
  EmotionModel m(Defaults(), EMOTION_ANGRY, 0.0);
  std::vector<EmotionChange> changes;
  m.SetAction(0.0, ACTION_KISSES, 1.0, &changes);
  m.AdvanceTo(100.0, &changes);
  ASSERT_EQ(changes.size(), 2u);
  EXPECT_EQ(changes[0].from, EMOTION_ANGRY);
  EXPECT_EQ(changes[0].to, EMOTION_NEUTRAL);
  EXPECT_NEAR(changes[0].time_s, 7.0, 1e-9);  // -1 -> -0.3 at 0.1 /s
  EXPECT_EQ(changes[1].to, EMOTION_HAPPY);
  EXPECT_NEAR(changes[1].time_s, 15.0, 1e-9);  // -1 -> +0.5
  EXPECT_EQ(changes[1].action, ACTION_KISSES);
  EXPECT_DOUBLE_EQ(m.valence(), 1.0);  // clamped
  // Middle intensity: 24 s; both inside the children's 5-40 s.
  EXPECT_NEAR(TimeToHappy(0.0, 0.05), 24.0, 1e-6);
  EXPECT_GE(TimeToHappy(1.0, 0.05), 5.0);
  EXPECT_LE(TimeToHappy(0.0, 0.05), 40.0);
}

TEST(EmotionModel, CrossingTimesDoNotDependOnTheAdvanceStep) {
  EXPECT_NEAR(TimeToHappy(0.5, 0.001), TimeToHappy(0.5, 3.7), 1e-9);
  EXPECT_NEAR(TimeToHappy(-1.0, 0.05), 60.0, 1e-6);
}

TEST(EmotionModel, ShoutingTakesHappyThroughNeutralToAngry) {
  EmotionModel m(Defaults(), EMOTION_HAPPY, 0.0);
  std::vector<EmotionChange> changes;
  m.SetAction(0.0, ACTION_SHOUTING, 1.0, &changes);
  m.AdvanceTo(30.0, &changes);
  ASSERT_EQ(changes.size(), 2u);
  EXPECT_EQ(changes[0].to, EMOTION_NEUTRAL);
  EXPECT_NEAR(changes[0].time_s, 7.0, 1e-9);
  EXPECT_EQ(changes[1].to, EMOTION_ANGRY);
  EXPECT_NEAR(changes[1].time_s, 15.0, 1e-9);
  EXPECT_EQ(m.emotion(), EMOTION_ANGRY);
}

TEST(EmotionModel, IdleKeepsTheEmotionAndValence) {
  EmotionModel m(Defaults(), EMOTION_NEUTRAL, 0.0);
  std::vector<EmotionChange> changes;
  m.SetAction(0.0, ACTION_KISSES, 1.0, &changes);
  m.SetAction(3.0, ACTION_IDLE, 0.0, &changes);  // v = 0.3
  m.AdvanceTo(1000.0, &changes);
  EXPECT_TRUE(changes.empty());
  EXPECT_NEAR(m.valence(), 0.3, 1e-12);
  EXPECT_EQ(m.emotion(), EMOTION_NEUTRAL);
  EXPECT_TRUE(std::isinf(m.NextChangeTime()));
}

TEST(EmotionModel, HysteresisHoldsHappyBetweenExitAndEnter) {
  EmotionModel m(Defaults(), EMOTION_NEUTRAL, 0.0);
  std::vector<EmotionChange> changes;
  m.SetAction(0.0, ACTION_KISSES, 1.0, &changes);
  m.AdvanceTo(6.0, &changes);  // v = 0.6 -> happy at 5 s
  ASSERT_EQ(changes.size(), 1u);
  EXPECT_NEAR(changes[0].time_s, 5.0, 1e-9);
  changes.clear();
  m.SetAction(6.0, ACTION_SHOUTING, 1.0, &changes);
  m.AdvanceTo(8.0, &changes);  // v = 0.4: below enter, above exit: still happy
  EXPECT_TRUE(changes.empty());
  EXPECT_EQ(m.emotion(), EMOTION_HAPPY);
  EXPECT_NEAR(m.NextChangeTime(), 9.0, 1e-9);  // v reaches exit 0.3
  m.AdvanceTo(9.5, &changes);
  ASSERT_EQ(changes.size(), 1u);
  EXPECT_EQ(changes[0].to, EMOTION_NEUTRAL);
  EXPECT_NEAR(changes[0].time_s, 9.0, 1e-9);
  // Back up: neutral again needs +enter, not +exit.
  changes.clear();
  m.SetAction(9.5, ACTION_KISSES, 1.0, &changes);  // v = 0.25
  m.AdvanceTo(10.5, &changes);                      // v = 0.35
  EXPECT_TRUE(changes.empty());
  EXPECT_EQ(m.emotion(), EMOTION_NEUTRAL);
}

TEST(EmotionModel, IdleDecayReturnsToNeutralWhenConfigured) {
  v1::EmotionModelOptions o;
  o.set_idle_decay_per_s(0.05);
  EmotionModel m(*ResolveEmotionParams(o), EMOTION_HAPPY, 0.0);
  std::vector<EmotionChange> changes;
  m.AdvanceTo(100.0, &changes);
  ASSERT_EQ(changes.size(), 1u);
  EXPECT_NEAR(changes[0].time_s, 14.0, 1e-9);  // 1 -> 0.3 at 0.05 /s
  EXPECT_DOUBLE_EQ(m.valence(), 0.0);
}

TEST(EmotionModel, OptionsAreValidatedWithTheFieldName) {
  v1::EmotionModelOptions o;
  o.set_exit_threshold(0.6);
  auto p = ResolveEmotionParams(o);
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(absl::StartsWith(p.status().message(), "emotion.exit_threshold"));
  o.Clear();
  o.set_rate_per_s(-1);
  EXPECT_TRUE(absl::StartsWith(ResolveEmotionParams(o).status().message(), "emotion.rate_per_s"));
}

TEST(EmotionModel, IntensityScalesTheRate) {
  const EmotionParams p = Defaults();
  EXPECT_DOUBLE_EQ(IntensityFactor(p, -1), 0.25);
  EXPECT_DOUBLE_EQ(IntensityFactor(p, 0), 0.625);
  EXPECT_DOUBLE_EQ(IntensityFactor(p, 1), 1.0);
}

}  // namespace
}  // namespace kinemo::coordinator
