// Segmentation of real Bandai clips: the same segments and parameters as the
// inference corpus computes, end points, transition costs.
#include "services/planner/controller/segments.h"

#include <gtest/gtest.h>

#include "services/inference/corpus/corpus.h"
#include "tests/unit/planner_controller/test_util.h"

namespace kinemo::planner::controller {
namespace {

TEST(Segments, SameAsInferenceCorpus) {
  auto lib = testing::TestLibrary();
  auto s = BuildSegmentLibrary(lib, {});
  ASSERT_TRUE(s.ok()) << s.status();
  size_t k = 0;
  for (size_t c = 0; c < lib->clips.size(); ++c) {
    auto ref = ::kinemo::gesture::ComputeKinematicSegments(lib->clips[c].clip);
    ASSERT_TRUE(ref.ok());
    for (const auto& r : *ref) {
      ASSERT_LT(k, (*s)->segments.size());
      const auto& g = (*s)->segments[k++];
      EXPECT_EQ(g.clip, static_cast<int>(c));
      EXPECT_EQ((g.params - r.params).norm(), 0.0);
      EXPECT_NEAR(g.first_frame * lib->clips[c].clip.frame_time_s, r.start_s, 1e-9);
    }
  }
  EXPECT_EQ(k, (*s)->segments.size());
  EXPECT_GT(k, 3 * lib->clips.size());  // gestures have several phases
  auto n = CountSegments(lib->clips[0].clip, {});
  ASSERT_TRUE(n.ok());
  EXPECT_GT(*n, 1);
}

TEST(Segments, EndPointsAndTransitions) {
  auto lib = testing::TestLibrary();
  auto s = BuildSegmentLibrary(lib, {});
  ASSERT_TRUE(s.ok());
  const SegmentLibrary& L = **s;
  int strokes = 0;
  for (int a = 0; a < L.num_segments(); ++a) {
    const auto& g = L.segments[static_cast<size_t>(a)];
    ASSERT_FALSE(g.ends.empty());
    EXPECT_LE(g.ends.size(), 4u);  // 3 interruption frames + the last
    EXPECT_EQ(g.ends.back(), g.num_frames - 1);
    for (size_t k = 1; k < g.ends.size(); ++k) EXPECT_LT(g.ends[k - 1], g.ends[k]);
    if (g.num_frames >= 8) {
      EXPECT_EQ(g.ends.size(), 4u);
    }
    const int last = g.first_end + static_cast<int>(g.ends.size()) - 1;
    EXPECT_TRUE(L.end_points[static_cast<size_t>(last)].last);
    if (g.next >= 0) {
      // The true successor costs nothing: D_seg(a+, a+) + D_seg(a, a).
      EXPECT_FLOAT_EQ(L.S(last, g.next), 0.f);
      // ... while substitutes cost something.
      int positive = 0;
      for (int b = 0; b < L.num_segments(); ++b) positive += L.S(last, b) > 0.f;
      EXPECT_GT(positive, L.num_segments() / 2);
    }
    // Interruptions pay the penalty.
    if (g.ends.size() > 1) {
      EXPECT_GE(L.S(g.first_end, a), L.options.interruption_penalty);
    }
    strokes += g.stroke;
  }
  EXPECT_EQ(strokes, 4);  // one per keyword-tagged clip in the manifest
  EXPECT_EQ(L.keywords, (std::vector<std::string>{"bow", "bye", "this"}));
  EXPECT_GT(L.angular_speed_p99_dps, 10);
  EXPECT_GE(L.angular_speed_max_dps, L.angular_speed_p99_dps);
}

TEST(Segments, RejectsBadOptions) {
  SegmentOptions o;
  o.speed_threshold_heights_per_s = 0;
  auto st = BuildSegmentLibrary(testing::TestLibrary(), o).status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("speed_threshold_heights_per_s"), std::string::npos);
  o = {};
  o.interruption_frames = -1;
  EXPECT_EQ(BuildSegmentLibrary(testing::TestLibrary(), o).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace kinemo::planner::controller
