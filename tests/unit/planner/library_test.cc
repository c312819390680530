#include "services/planner/library/library.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "common/motion/bvh.h"
#include "common/motion/kinematics.h"
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

TEST(Library, ResamplesToTheFirstClipsRate) {
  // The same 60 fps clip twice: resampled to 30 fps, the second renamed.
  auto ok = LoadLibrary("l", {.paths = {kData + "cmu_002_03.bvh", kData + "cmu_002_03.bvh"},
                              .frame_rate_hz = 30});
  ASSERT_TRUE(ok.ok()) << ok.status();
  ASSERT_EQ((*ok)->clips.size(), 2u);
  for (const auto& c : (*ok)->clips) EXPECT_NEAR(c.clip.fps(), 30.0, 1e-6);
  EXPECT_EQ((*ok)->clips[1].name, "cmu_002_03#2");
  EXPECT_EQ((*ok)->warnings.size(), 3u);

}

TEST(Library, MapsOtherExportsByJointName) {
  // cmu_002_03 has the extra root RL_BoneRoot (Z-up, the hips' position in
  // its channels); cmu_007_12 starts at CC_Base_Hip with relative positions.
  auto lib = LoadLibrary("l", {.paths = {kData + "cmu_002_03.bvh", kData + "cmu_007_12_first40.bvh"}});
  ASSERT_TRUE(lib.ok()) << lib.status();
  const auto& l = **lib;
  EXPECT_EQ(l.skeleton.num_joints(), 100);
  EXPECT_EQ(l.skeleton.joint(0).name, "CC_Base_Hip");
  EXPECT_EQ(l.skeleton.joint(0).num_channels(), 6);
  bool dropped = false, mapped = false;
  for (const auto& w : l.warnings) {
    dropped = dropped || w.find("dropped: RL_BoneRoot") != std::string::npos;
    mapped = mapped || w.find("mapped by joint name") != std::string::npos;
  }
  EXPECT_TRUE(dropped && mapped);
  // World positions of every joint are those of the source files.
  for (int c = 0; c < 2; ++c) {
    auto src = motion::ReadBvhFile(kData + (c == 0 ? "cmu_002_03.bvh" : "cmu_007_12_first40.bvh"));
    ASSERT_TRUE(src.ok());
    ASSERT_EQ(l.clips[static_cast<size_t>(c)].clip.num_frames(), src->num_frames());
    for (int f : {0, 17, 39}) {
      auto a = motion::ComputeWorldPose(*src, f);
      auto b = motion::ComputeWorldPose(l.clips[static_cast<size_t>(c)].clip, f);
      ASSERT_TRUE(a.ok() && b.ok());
      for (int j = 0; j < l.skeleton.num_joints(); ++j) {
        const int sj = src->skeleton.FindJoint(l.skeleton.joint(j).name);
        EXPECT_LT((a->positions[static_cast<size_t>(sj)] - b->positions[static_cast<size_t>(j)]).norm(), 1e-3)
            << l.skeleton.joint(j).name << " frame " << f;
      }
    }
  }
  // A skeleton that shares too few names is refused, naming the file.
  auto bad = LoadLibrary("l", {.paths = {kData + "cmu_002_03.bvh", kData + "dataset-1_bye_normal_001.bvh"}});
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("dataset-1_bye_normal_001.bvh"), std::string::npos) << bad.status();
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
