#include "common/testing/process.h"

#include <unistd.h>

#include <filesystem>
#include <system_error>

namespace kinemo::testing {

std::string FindBuiltBinary(const std::string& binary_dir, const std::string& name) {
  std::error_code ec;
  for (auto it = std::filesystem::recursive_directory_iterator(binary_dir, ec);
       it != std::filesystem::recursive_directory_iterator(); it.increment(ec)) {
    if (ec) break;
    if (it->is_regular_file(ec) && it->path().filename() == name &&
        access(it->path().c_str(), X_OK) == 0) {
      return it->path().string();
    }
  }
  return "";
}

}  // namespace kinemo::testing
