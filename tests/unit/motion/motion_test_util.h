// Shared helpers for the kinemo_motion tests: the real files in
// tests/data/motion and small comparison utilities.
#pragma once

#include <string>
#include <vector>

#include "common/motion/skeleton.h"

namespace kinemo::motion::testing {

struct TestFile {
  std::string name;  // file name in tests/data/motion
  int num_joints;
  int num_channels;
  int num_frames;
  double frame_time_s;
};

// The real BVH files used by the tests, with their known shapes.
const std::vector<TestFile>& TestFiles();

// Absolute path of a file in tests/data/motion.
std::string MotionDataPath(const std::string& name);

// Whole file contents (fails the test and returns "" on error).
std::string ReadFileOrDie(const std::string& path);

// Loads a test clip (fails the test on error).
Clip LoadClip(const std::string& name);

// A fresh path under the test's temporary directory.
std::string TempPath(const std::string& name);

}  // namespace kinemo::motion::testing
