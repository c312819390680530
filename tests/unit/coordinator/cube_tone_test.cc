// The cube's action -> tone map and the style it makes (core/cube_tone.h).
#include "services/coordinator/core/cube_tone.h"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

namespace kinemo::coordinator {
namespace {

using google::protobuf::Map;
using common::v1::ACTION_IDLE;
using common::v1::ACTION_KISSES;
using common::v1::ACTION_SHOUTING;

TEST(CubeTone, DefaultsThenOptionsThenRequest) {
  Map<std::string, std::string> none, options, request;
  auto m = MakeCubeToneMap(none, "o", none, "r");
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->at(ACTION_IDLE), "neutral");
  EXPECT_EQ(m->at(ACTION_KISSES), "happy");
  EXPECT_EQ(m->at(ACTION_SHOUTING), "angry");
  options["idle"] = "subdued";
  options["kisses"] = "energetic";
  request["kisses"] = "happy";
  m = MakeCubeToneMap(options, "o", request, "r");
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->at(ACTION_IDLE), "subdued");
  EXPECT_EQ(m->at(ACTION_KISSES), "happy");
  EXPECT_EQ(m->at(ACTION_SHOUTING), "angry");
}

TEST(CubeTone, BadMapsNameTheField) {
  Map<std::string, std::string> none, bad;
  bad["waving"] = "happy";
  auto st = MakeCubeToneMap(none, "animate.cube_tones", bad, "config.cube_tones").status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("config.cube_tones"), std::string::npos) << st;
  bad.clear();
  bad["idle"] = "Very Happy";
  st = MakeCubeToneMap(bad, "animate.cube_tones", none, "config.cube_tones").status();
  EXPECT_NE(st.message().find("animate.cube_tones[idle]"), std::string::npos) << st;
}

TEST(CubeTone, IntensityBlendsNeutralAndTheTone) {
  Map<std::string, std::string> none;
  const CubeToneMap m = *MakeCubeToneMap(none, "o", none, "r");
  CubeStyle s = StyleForAction(m, ACTION_KISSES, 0.0);
  EXPECT_EQ(s.tone, "happy");
  EXPECT_DOUBLE_EQ(s.weight, 0.5);
  EXPECT_DOUBLE_EQ(s.style.tone_weights().at("happy"), 0.5);
  EXPECT_DOUBLE_EQ(s.style.tone_weights().at("neutral"), 0.5);
  s = StyleForAction(m, ACTION_SHOUTING, 1.0);
  EXPECT_EQ(s.tone, "angry");
  EXPECT_EQ(s.style.tone_weights().size(), 1u);
  EXPECT_DOUBLE_EQ(s.style.tone_weights().at("angry"), 1.0);
  s = StyleForAction(m, ACTION_SHOUTING, -1.0);
  EXPECT_DOUBLE_EQ(s.style.tone_weights().at("angry"), 0.0);
  EXPECT_DOUBLE_EQ(s.style.tone_weights().at("neutral"), 1.0);
  // Out of range or not finite: clamped, or none.
  EXPECT_DOUBLE_EQ(StyleForAction(m, ACTION_KISSES, 7.0).weight, 1.0);
  EXPECT_DOUBLE_EQ(StyleForAction(m, ACTION_KISSES, std::nan("")).weight, 0.5);
  // Idle (neutral) and an unmapped action: neutral only.
  for (auto a : {ACTION_IDLE, common::v1::ACTION_UNSPECIFIED}) {
    s = StyleForAction(m, a, 0.7);
    EXPECT_EQ(s.tone, "neutral");
    EXPECT_EQ(s.style.tone_weights().size(), 1u);
    EXPECT_DOUBLE_EQ(s.style.tone_weights().at("neutral"), 1.0);
    EXPECT_EQ(s.emphasis, 0.0);
    EXPECT_EQ(s.style.gesture_emphasis(), 0.0);
  }
}

TEST(CubeTone, IntensitySetsTheGestureEmphasis) {
  Map<std::string, std::string> none;
  const CubeToneMap m = *MakeCubeToneMap(none, "o", none, "r");
  // The default gain: e = 0.5 * intensity, in the style sent to the planner.
  for (double i : {-1.0, -0.4, 0.0, 0.3, 1.0}) {
    const CubeStyle s = StyleForAction(m, ACTION_SHOUTING, i);
    EXPECT_DOUBLE_EQ(s.emphasis, kDefaultCubeEmphasisGain * i) << i;
    EXPECT_DOUBLE_EQ(s.style.gesture_emphasis(), kDefaultCubeEmphasisGain * i) << i;
  }
  EXPECT_DOUBLE_EQ(kDefaultCubeEmphasisGain, 0.5);
  EXPECT_DOUBLE_EQ(StyleForAction(m, ACTION_KISSES, 0.6, 1.0).style.gesture_emphasis(), 0.6);
  EXPECT_DOUBLE_EQ(StyleForAction(m, ACTION_KISSES, -0.6, 0.25).emphasis, -0.15);
  EXPECT_EQ(StyleForAction(m, ACTION_KISSES, 0.9, 0.0).emphasis, 0.0);
  // Intensity clamped to [-1, 1] (the planner's bounds of the emphasis), NaN none.
  EXPECT_DOUBLE_EQ(StyleForAction(m, ACTION_KISSES, 7.0, 1.0).emphasis, 1.0);
  EXPECT_DOUBLE_EQ(StyleForAction(m, ACTION_KISSES, -7.0, 1.0).emphasis, -1.0);
  EXPECT_EQ(StyleForAction(m, ACTION_KISSES, std::nan(""), 1.0).emphasis, 0.0);
  // The gain's bounds name the option.
  EXPECT_TRUE(ValidateCubeEmphasisGain(0.0, "animate.cube_emphasis_gain").ok());
  EXPECT_TRUE(ValidateCubeEmphasisGain(1.0, "animate.cube_emphasis_gain").ok());
  for (double bad : {-0.1, 1.5, std::nan(""), std::numeric_limits<double>::infinity()}) {
    const Status st = ValidateCubeEmphasisGain(bad, "animate.cube_emphasis_gain");
    EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument) << bad;
    EXPECT_NE(st.message().find("animate.cube_emphasis_gain"), std::string::npos) << st;
  }
}

}  // namespace
}  // namespace kinemo::coordinator
