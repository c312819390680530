// Fuzzes the services' options files (common/config): the input is the text
// of a --config file, loaded by LoadServiceOptions (the function every
// service's main calls) into each service's options message in turn, over
// the defaults a fresh message holds.
#include <sys/mman.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <string>

#include "common/config/options.h"
#include "kinemo/coordinator/v1/allinone.pb.h"
#include "kinemo/coordinator/v1/options.pb.h"
#include "kinemo/cube_tracker/v1/options.pb.h"
#include "kinemo/inference/v1/options.pb.h"
#include "kinemo/planner/v1/options.pb.h"
#include "kinemo/prosody/v1/options.pb.h"
#include "kinemo/robot_bridge/v1/options.pb.h"
#include "tests/fuzz/fuzz_check.h"

namespace {

// The config file: an in-memory file named by its /proc/self/fd path.
const std::string& ConfigPath(int* fd_out) {
  static int fd = memfd_create("options.textproto", 0);
  static const std::string path = "/proc/self/fd/" + std::to_string(fd);
  *fd_out = fd;
  return path;
}

template <typename Options>
void Load(const std::string& path) {
  Options options;
  kinemo::config::ServerCommandLine command_line;
  command_line.config_paths = {path};
  const auto s = kinemo::config::LoadServiceOptions(command_line, &options);
  if (s.ok()) {
    const auto* server = kinemo::config::MutableServerOptions(&options);
    KINEMO_FUZZ_CHECK(server != nullptr && server->port() <= 65535 && !server->host().empty(),
                      "accepted options with an invalid server");
  } else {
    KINEMO_FUZZ_CHECK_REFUSED(s, absl::StatusCode::kInvalidArgument);
    KINEMO_FUZZ_CHECK(s.message().find(path) == 0 || s.message().find("server.") == 0,
                      "the message names neither the file nor the field: " + s.ToString());
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  int fd = -1;
  const std::string& path = ConfigPath(&fd);
  if (fd < 0 || ftruncate(fd, 0) != 0 || pwrite(fd, data, size, 0) != static_cast<ssize_t>(size)) {
    std::abort();  // the harness itself failed
  }
  Load<kinemo::prosody::v1::ProsodyOptions>(path);
  Load<kinemo::inference::v1::InferenceOptions>(path);
  Load<kinemo::planner::v1::PlannerOptions>(path);
  Load<kinemo::cube_tracker::v1::CubeTrackerOptions>(path);
  Load<kinemo::robot_bridge::v1::RobotBridgeOptions>(path);
  Load<kinemo::coordinator::v1::CoordinatorOptions>(path);
  Load<kinemo::coordinator::v1::AllInOneOptions>(path);
  return 0;
}
