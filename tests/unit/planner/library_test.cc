#include "services/planner/library/library.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "common/testing/process.h"

namespace kinemo::planner {
namespace {

const std::string kData = KINEMO_TEST_DATA_DIR "/motion/";

TEST(Library, LoadsABandaiClipWithToneAndScale) {
  auto lib = LoadLibrary("g", {.paths = {kData + "dataset-1_bye_normal_001.bvh"}});
  ASSERT_TRUE(lib.ok()) << lib.status();
  ASSERT_EQ((*lib)->clips.size(), 1u);
  const LibraryClip& c = (*lib)->clips[0];
  EXPECT_EQ(c.name, "dataset-1_bye_normal_001");
  EXPECT_EQ(c.style, "normal");
  EXPECT_EQ(c.tone, "neutral");
  EXPECT_NEAR((*lib)->frame_rate_hz, 30.0, 0.01);
  // Bandai skeletons are in centimetres.
  EXPECT_NEAR((*lib)->meters_per_unit, 0.01, 0.003);
  EXPECT_EQ((*lib)->regions.family, motion::SkeletonFamily::kBandai22);
}

TEST(Library, ManifestSetsNamesTonesKeywordsAndAnnotation) {
  kinemo::testing::TempDir dir;
  std::filesystem::copy_file(kData + "dataset-1_bye_normal_001.bvh", dir.path() + "/bye.bvh");
  std::ofstream(dir.path() + "/lib.json") << R"({"meters_per_unit": 0.01, "clips": [
      {"path": "bye.bvh", "name": "bye_a", "tone": "Energetic", "keywords": ["Bye", "goodbye"],
       "phrases": [{"stroke": [1.0, 1.4]}]},
      {"path": "bye.bvh"}]})";
  auto lib = LoadLibrary("g", {.paths = {dir.path() + "/lib.json"}});
  ASSERT_TRUE(lib.ok()) << lib.status();
  ASSERT_EQ((*lib)->clips.size(), 2u);
  EXPECT_EQ((*lib)->clips[0].name, "bye_a");
  EXPECT_EQ((*lib)->clips[0].tone, "energetic");
  EXPECT_EQ((*lib)->clips[0].keywords, (std::vector<std::string>{"bye", "goodbye"}));
  EXPECT_NE((*lib)->clips[0].annotation_json.find("stroke"), std::string::npos);
  EXPECT_EQ((*lib)->clips[1].name, "bye");
  EXPECT_DOUBLE_EQ((*lib)->meters_per_unit, 0.01);
  EXPECT_EQ((*lib)->keywords(), (std::vector<std::string>{"bye", "goodbye"}));
}

TEST(Library, ResamplesToTheFirstClipsRateAndRejectsOtherSkeletons) {
  // The same 60 fps clip twice: resampled to 30 fps, the second renamed.
  auto ok = LoadLibrary("l", {.paths = {kData + "cmu_002_03.bvh", kData + "cmu_002_03.bvh"},
                              .frame_rate_hz = 30});
  ASSERT_TRUE(ok.ok()) << ok.status();
  ASSERT_EQ((*ok)->clips.size(), 2u);
  for (const auto& c : (*ok)->clips) EXPECT_NEAR(c.clip.fps(), 30.0, 1e-6);
  EXPECT_EQ((*ok)->clips[1].name, "cmu_002_03#2");
  EXPECT_EQ((*ok)->warnings.size(), 3u);

  // Skeletons must match joint for joint (this CMU export has one joint more
  // than the other).
  auto bad = LoadLibrary("l", {.paths = {kData + "cmu_002_03.bvh", kData + "cmu_007_12_first40.bvh"}});
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("cmu_007_12_first40.bvh"), std::string::npos) << bad.status();
}

TEST(Library, BadSourcesNameTheProblem) {
  kinemo::testing::TempDir dir;
  std::ofstream(dir.path() + "/bad.json") << R"({"clips": [{"name": "x"}]})";
  auto missing_path = LoadLibrary("g", {.paths = {dir.path() + "/bad.json"}});
  ASSERT_FALSE(missing_path.ok());
  EXPECT_NE(missing_path.status().message().find("clips[0].path"), std::string::npos) << missing_path.status();

  auto none = LoadLibrary("g", {.paths = {dir.path() + "/nothing.bvh"}});
  EXPECT_EQ(none.status().code(), absl::StatusCode::kNotFound);
  auto bad_id = LoadLibrary("Bad Id", {.paths = {kData + "dataset-1_bye_normal_001.bvh"}});
  EXPECT_EQ(bad_id.status().code(), absl::StatusCode::kInvalidArgument);
  auto bad_bvh = LoadLibrary("g", {.inline_clips = {{"broken", "HIERARCHY\nROOT", "", {}}}});
  ASSERT_FALSE(bad_bvh.ok());
  EXPECT_NE(bad_bvh.status().message().find("broken:"), std::string::npos) << bad_bvh.status();
}

TEST(Library, StoreVersionsAndRefusesSilentOverwrite) {
  LibraryStore store;
  auto lib = LoadLibrary("g", {.paths = {kData + "dataset-1_bye_normal_001.bvh"}});
  ASSERT_TRUE(lib.ok());
  ASSERT_EQ(*store.Put("g", *lib, false), 1);
  EXPECT_EQ(store.Put("g", *lib, false).status().code(), absl::StatusCode::kAlreadyExists);
  auto again = LoadLibrary("g", {.paths = {kData + "dataset-1_bye_normal_001.bvh"}});
  EXPECT_EQ(*store.Put("g", *again, true), 2);
  EXPECT_EQ((*store.Get("g", "library_id"))->version, 2);
  EXPECT_EQ(store.Get("h", "library_id").status().code(), absl::StatusCode::kNotFound);
}

TEST(Library, BandaiNamesAndTones) {
  auto n = ParseBandaiName("dataset-2_wave-right-hand_not-confident_003");
  ASSERT_TRUE(n.has_value());
  EXPECT_EQ(n->content, "wave-right-hand");
  EXPECT_EQ(n->style, "not-confident");
  EXPECT_FALSE(ParseBandaiName("131_01").has_value());
  EXPECT_EQ(ToneForStyle("angry"), "energetic");
  EXPECT_EQ(ToneForStyle("tired"), "subdued");
  EXPECT_EQ(ToneForStyle("normal"), "neutral");
}

}  // namespace
}  // namespace kinemo::planner
