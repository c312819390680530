// The embedded stack: a kinemo_allinone child (embedded_stack.h).
#include "services/cli/embedded_stack.h"

#include "services/cli/channel.h"

#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <vector>

namespace kinemo::cli {
namespace {

namespace fs = std::filesystem;

// The bundled gesture data (BEAT2's conversational takes and the Bandai
// gesture clips): $KINEMO_GESTURE_LIBRARY, <prefix>/share/kinemo/gestures
// beside an installed binary, or the source tree's tests/data. Returns the
// library root and the folders in it, or "".
std::string FindGestureLibrary(std::vector<std::string>* folders) {
  const std::vector<std::string> kFolders = {"paired/beat2", "planner_gesture", "planner_controller"};
  std::error_code ec;
  std::vector<fs::path> roots;
  if (const char* env = std::getenv("KINEMO_GESTURE_LIBRARY"); env != nullptr && *env) roots.emplace_back(env);
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) roots.push_back(self.parent_path().parent_path() / "share" / "kinemo" / "gestures");
#ifdef KINEMO_CLI_TEST_DATA_DIR
  roots.emplace_back(KINEMO_CLI_TEST_DATA_DIR);
#endif
  for (const fs::path& root : roots) {
    folders->clear();
    for (const auto& f : kFolders) {
      if (fs::is_directory(root / f, ec)) folders->push_back(f);
    }
    if (!folders->empty()) return fs::absolute(root, ec).string();
  }
  return "";
}

}  // namespace

// The bundled libraries and their gesture graphs — "bundled" (conversational,
// BEAT2) and "bandai" (emblems) — so that Animate works out of the box even
// without the seed store; the Gesture Controller (--method gc, --stream)
// defaults to the model and controller "bundled" of the all-in-one's seed
// store (which also holds both libraries and graphs: the preloads below are
// then skipped).
std::string DefaultAllInOneConfig(const std::string& command, std::uint32_t max_streams) {
  std::vector<std::string> folders;
  const std::string root = FindGestureLibrary(&folders);
  std::string config = "# written by kinemo " + command + "\n";
  if (root.empty()) return config;
  config +=
      "coordinator { animate { default_method: METHOD_BODYSPEECH models { gesture_graph_id: \"bundled\" "
      "inference_model_id: \"bundled\" controller_id: \"bundled\" }" +
      (max_streams > 0 ? " max_concurrent_streams: " + std::to_string(max_streams) : std::string()) + " } }\n";
  // The prosody service's own stream limit (default 64) follows.
  if (max_streams > 0) config += "prosody { max_concurrent_streams: " + std::to_string(max_streams) + " }\n";
  config += "planner {\n  library_root: \"" + root + "\"\n";
  const auto has = [&](const std::string& f) { return std::find(folders.begin(), folders.end(), f) != folders.end(); };
  const auto library = [&](const std::string& id, const std::vector<std::string>& paths) {
    std::string lib = "  preload { library_id: \"" + id + "\"";
    int n = 0;
    for (const auto& p : paths) {
      if (!has(p)) continue;
      lib += " paths: \"" + p + "\"";
      ++n;
    }
    if (n == 0) return;
    config += lib + " }\n  preload_gesture_graphs { graph_id: \"" + id + "\" library_id: \"" + id +
              "\" params { stroke_phrases: true } }\n";
  };
  library("bundled", {"paired/beat2"});
  library("bandai", {"planner_gesture", "planner_controller"});
  config += "}\n";
  return config;
}

std::string BundledDataFile(const std::string& relative) {
  std::vector<std::string> folders;
  const std::string root = FindGestureLibrary(&folders);
  std::error_code ec;
  if (root.empty() || !fs::is_regular_file(fs::path(root) / relative, ec)) return "";
  return (fs::path(root) / relative).string();
}

std::string FindKinemoBinary(const std::string& name, const std::string& build_dir) {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    for (const fs::path& p : {self.parent_path() / name, self.parent_path().parent_path() / build_dir / name}) {
      if (fs::exists(p, ec)) return p.string();
    }
  }
  if (const char* path = std::getenv("PATH")) {
    std::stringstream ss(path);
    std::string dir;
    while (std::getline(ss, dir, ':')) {
      const fs::path p = fs::path(dir) / name;
      if (fs::exists(p, ec)) return p.string();
    }
  }
  return "";
}

bool Reachable(const std::string& address, double timeout_s) {
  auto channel = ServerChannel(address);
  return channel->WaitForConnected(std::chrono::system_clock::now() +
                                   std::chrono::milliseconds(static_cast<int64_t>(timeout_s * 1000)));
}

std::string EmbeddedStack::Start(const std::string& command, const std::string& config, double timeout_s,
                                 std::uint32_t max_streams) {
  // $KINEMO_ALLINONE, beside this binary, in the build tree, or on PATH.
  const char* env = std::getenv("KINEMO_ALLINONE");
  const std::string binary = env != nullptr && *env ? env : FindKinemoBinary("kinemo_allinone", "allinone");
  if (binary.empty()) {
    std::cerr << "kinemo " << command
              << ": kinemo_allinone not found (set KINEMO_ALLINONE, or start a stack and pass --coordinator)\n";
    return "";
  }
  std::string config_file = config;
  if (config_file.empty()) {
    config_file = dir_.File("allinone.textproto");
    std::ofstream(config_file) << DefaultAllInOneConfig(command, max_streams);
  }
  auto started = process::ServiceProcess::Start(
      {.binary = binary,
       .args = {"--config", config_file},
       .ready_timeout = std::chrono::milliseconds(static_cast<int64_t>(timeout_s * 1000))});
  if (!started.ok()) {
    std::cerr << "kinemo " << command << ": " << started.status().message() << "\n";
    return "";
  }
  stack_ = *std::move(started);
  return stack_->address();
}

}  // namespace kinemo::cli
