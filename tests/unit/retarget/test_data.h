// Paths into tests/data for the retargeting tests (shared by their units,
// which also compile together as one unity unit).
#pragma once

#include <string>

namespace kinemo::retarget::test {

inline std::string Data(const std::string& rel) { return std::string(KINEMO_TEST_DATA_DIR) + "/" + rel; }

}  // namespace kinemo::retarget::test
