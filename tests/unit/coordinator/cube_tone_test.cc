// The cube's action -> tone map and the style it makes (core/cube_tone.h).
#include "services/coordinator/core/cube_tone.h"

#include <cmath>

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
  }
}

}  // namespace
}  // namespace kinemo::coordinator
