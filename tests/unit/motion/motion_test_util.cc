#include "tests/unit/motion/motion_test_util.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/motion/bvh.h"

namespace kinemo::motion::testing {

const std::vector<TestFile>& TestFiles() {
  static const std::vector<TestFile>* const files = new std::vector<TestFile>{
      {"dataset-1_bye_normal_001.bvh", 22, 132, 111, 0.0333333},
      {"cmu_002_03.bvh", 101, 306, 86, 0.016667},
      {"cmu_007_12_first40.bvh", 100, 303, 40, 0.016667},
      {"131_01.bvh", 31, 96, 994, 0.0083333},
      // BEAT2's SMPL-X tree (55 joints, ZXY channels, fingers, jaw, eyes).
      {"../paired/beat2/2_scott_0_2_2.bvh", 55, 168, 1804, 0.03333333},
  };
  return *files;
}

std::string MotionDataPath(const std::string& name) {
  return std::string(KINEMO_TEST_DATA_DIR) + "/motion/" + name;
}

std::string ReadFileOrDie(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  EXPECT_TRUE(f.good()) << "cannot open " << path;
  std::ostringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

Clip LoadClip(const std::string& name) {
  StatusOr<Clip> clip = ReadBvhFile(MotionDataPath(name));
  EXPECT_TRUE(clip.ok()) << clip.status();
  return clip.ok() ? *std::move(clip) : Clip{};
}

namespace {

std::filesystem::path TempDir() {
  return std::filesystem::temp_directory_path() /
         ("kinemo_motion_test_" + std::to_string(::getpid()));
}

// Removes this process's temporary directory after the last test.
class TempDirCleanup : public ::testing::Environment {
 public:
  void TearDown() override {
    std::error_code ignored;
    std::filesystem::remove_all(TempDir(), ignored);
  }
};
[[maybe_unused]] ::testing::Environment* const kCleanup =
    ::testing::AddGlobalTestEnvironment(new TempDirCleanup);

}  // namespace

std::string TempPath(const std::string& name) {
  const ::testing::TestInfo* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::filesystem::path dir = TempDir();
  std::filesystem::create_directories(dir);
  std::string file = std::string(info->test_suite_name()) + "_" + info->name() + "_" + name;
  for (char& c : file) {
    if (c == '/') c = '_';  // parameterised test names contain '/'
  }
  return (dir / file).string();
}

}  // namespace kinemo::motion::testing
