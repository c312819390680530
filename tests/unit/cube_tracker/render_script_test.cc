// Render scripts (services/cube_tracker/render): the shipped scripts parse;
// numbers out of range are INVALID_ARGUMENT naming the field, never a cast.
#include <gtest/gtest.h>

#include <string>

#include "services/cube_tracker/render/renderer.h"

namespace kinemo::cube {
namespace {

const std::string kData = KINEMO_TEST_DATA_DIR;

TEST(RenderScript, ShippedScriptsParse) {
  for (const char* name : {"lift_rotate_place", "move_path", "rotate_two_turns", "vleo_scenario"}) {
    auto s = LoadRenderScript(kData + "/cube/" + name + ".json");
    ASSERT_TRUE(s.ok()) << name << ": " << s.status();
    EXPECT_GT(s->frame_count(), 1) << name;
  }
}

// Found by tests/fuzz/cube_script_fuzz (corpus: regression-motion-blur-7e60.json):
// `"motion_blur_samples": 7.5e60` was cast to int (undefined behaviour).
TEST(RenderScript, NumbersOutOfRangeNameTheField) {
  const std::string keys = R"("background": "bg.jpg", "keys": [{"t_s": 0}, {"t_s": 1}])";
  const struct {
    std::string json;
    std::string field;
  } cases[] = {
      {R"({"motion_blur_samples": 7555555555555555555555555555555555555555555555555555555555555, )" +
           keys + "}",
       "motion_blur_samples"},
      {R"({"width": 1e300, )" + keys + "}", "width"},
      {R"({"height": 640.5, )" + keys + "}", "height"},
      {R"({"seed": -1, )" + keys + "}", "seed"},
      {R"({"initial_top_face": 6, )" + keys + "}", "initial_top_face"},
      {R"({"fps": "30", )" + keys + "}", "fps"},
      {R"({"camera": {"distance_m": true}, )" + keys + "}", "camera.distance_m"},
      {R"({"camera": {"look_at_m": [0, "x", 0]}, )" + keys + "}", "camera.look_at_m[1]"},
      {R"({"background": "bg.jpg", "keys": [{"t_s": 0}, {"t_s": 1e300}]})", "keys[1].t_s"},
      {R"({"background": "bg.jpg", "keys": [{"t_s": -2}, {"t_s": -1}]})", "keys[0].t_s"},
      {R"({"background": "bg.jpg", "keys": [{"t_s": 0}, 5]})", "keys[1]"},
      {R"({"background": "bg.jpg", "keys": [{"t_s": 0, "yaw_deg": "90"}]})", "keys[0].yaw_deg"},
  };
  for (const auto& c : cases) {
    auto s = ParseRenderScript(c.json, "");
    ASSERT_FALSE(s.ok()) << c.json;
    EXPECT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_EQ(s.status().message().rfind(c.field + ": ", 0), 0u) << s.status();
  }
  auto ok = ParseRenderScript(
      R"({"background": "bg.jpg", "fps": 25, "keys": [{"t_s": 0}, {"t_s": 600}]})", "/d");
  ASSERT_TRUE(ok.ok()) << ok.status();
  EXPECT_EQ(ok->frame_count(), 600 * 25 + 1);
  EXPECT_EQ(ok->background, "/d/bg.jpg");
}

}  // namespace
}  // namespace kinemo::cube
