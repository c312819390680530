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

TEST(Library, StoreServesTheVersionItIsGiven) {
  LibraryStore store;
  auto lib = LoadLibrary("g", {.paths = {kData + "dataset-1_bye_normal_001.bvh"}});
  ASSERT_TRUE(lib.ok());
  EXPECT_EQ(store.Version("g"), 0);
  store.Set("g", *lib, 3);
  EXPECT_EQ(store.Version("g"), 3);
  EXPECT_EQ((*store.Get("g", "library_id"))->version, 3);
  auto older = LoadLibrary("g", {.paths = {kData + "dataset-1_bye_normal_001.bvh"}});
  store.Set("g", *older, 2);  // e.g. version 3 was deleted: 2 is served again
  EXPECT_EQ((*store.Get("g", "library_id"))->version, 2);
  store.Remove("g");
  EXPECT_EQ(store.Get("g", "library_id").status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store.Get("h", "library_id").status().code(), absl::StatusCode::kNotFound);
}

// A library written as stored files (manifest.json + clips/) loads back the
// same: sources from paths, a manifest with annotations, and inline clips
// (one with a name that is not file-safe, two with the same name).
TEST(Library, WrittenFilesReloadTheSameLibrary) {
  kinemo::testing::TempDir dir;
  std::ifstream in(kData + "dataset-1_bye_normal_001.bvh");
  const std::string bye((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::filesystem::copy_file(kData + "dataset-1_bye_normal_001.bvh", dir.path() + "/bye.bvh");
  std::ofstream(dir.path() + "/lib.json") << R"({"clips": [
      {"path": "bye.bvh", "name": "bye_a", "tone": "Energetic", "keywords": ["Bye"],
       "phrases": [{"stroke": [1.0, 1.4]}]}]})";
  LibrarySources src;
  src.paths = {dir.path() + "/lib.json", KINEMO_TEST_DATA_DIR "/planner_controller/dataset-1_bow_normal_001.bvh"};
  src.inline_clips = {{"my clip/1", bye, "subdued", {"Wave"}}, {"my clip/1", bye, "", {}}};
  auto lib = LoadLibrary("g", src);
  ASSERT_TRUE(lib.ok()) << lib.status();
  ASSERT_EQ((*lib)->clips.size(), 4u);
  EXPECT_EQ((*lib)->clips[2].inline_index, 0);
  EXPECT_EQ((*lib)->clips[3].inline_index, 1);

  const std::string stored = dir.path() + "/stored";
  ASSERT_TRUE(WriteLibraryFiles(**lib, src, stored).ok());
  // The originals are not needed any more.
  std::filesystem::remove(dir.path() + "/bye.bvh");
  auto again = LoadLibrary("g", {.paths = {stored + "/manifest.json"}});
  ASSERT_TRUE(again.ok()) << again.status();
  const Library& a = **lib;
  const Library& b = **again;
  ASSERT_EQ(b.clips.size(), a.clips.size());
  EXPECT_DOUBLE_EQ(b.meters_per_unit, a.meters_per_unit);
  EXPECT_DOUBLE_EQ(b.frame_rate_hz, a.frame_rate_hz);
  EXPECT_EQ(b.skeleton.num_joints(), a.skeleton.num_joints());
  for (size_t i = 0; i < a.clips.size(); ++i) {
    EXPECT_EQ(b.clips[i].name, a.clips[i].name);
    EXPECT_EQ(b.clips[i].tone, a.clips[i].tone);
    EXPECT_EQ(b.clips[i].keywords, a.clips[i].keywords);
    EXPECT_EQ(b.clips[i].annotation_json, a.clips[i].annotation_json);
    ASSERT_EQ(b.clips[i].clip.num_frames(), a.clips[i].clip.num_frames()) << a.clips[i].name;
    EXPECT_EQ(b.clips[i].clip.frames, a.clips[i].clip.frames) << a.clips[i].name;
    EXPECT_EQ(b.clips[i].source.rfind(stored + "/clips/", 0), 0u) << b.clips[i].source;
  }
  EXPECT_EQ(a.clips[1].name, "dataset-1_bow_normal_001");
  EXPECT_EQ(b.clips[2].name, "my clip/1");
  EXPECT_EQ(b.clips[3].name, "my clip/1#2");
  EXPECT_EQ(b.clips[2].tone, "subdued");
  EXPECT_TRUE(std::filesystem::exists(stored + "/clips/my_clip_1.bvh"));
  EXPECT_TRUE(std::filesystem::exists(stored + "/clips/my_clip_1_2.bvh"));
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
