// A whole file as bytes, for the studio's tests (shared by their units, which
// also compile together as one unity unit).
#pragma once

#include <fstream>
#include <sstream>
#include <string>

namespace kinemo::studio::test {

inline std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace kinemo::studio::test
