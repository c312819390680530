// pleo_sim as a child process on an ephemeral loopback port, for the
// benchmark (`kinemo bench e2e`) and the demo (`kinemo demo vleo`); started
// and stopped through kinemo_process (common/process/process.h): SIGTERM on
// destruction, SIGKILL if it has not exited 10 s later.
#pragma once

#include <signal.h>

#include <chrono>
#include <memory>
#include <string>

#include "absl/strings/str_cat.h"
#include "common/process/process.h"
#include "common/status/status.h"

namespace kinemo::coordinator {

// pleo_sim as a child; SIGTERM on destruction.
class PleoSimChild {
 public:
  ~PleoSimChild() {
    if (child_ != nullptr) (void)child_->Stop(SIGTERM, std::chrono::seconds(10));
  }
  // Starts `binary` on 127.0.0.1:0; its Modbus TCP port once it listens.
  StatusOr<int> Start(const std::string& binary) {
    const std::string port_file = dir_.File("port");
    KINEMO_ASSIGN_OR_RETURN(child_, process::ChildProcess::Spawn({binary, "--tcp", "127.0.0.1:0", "--port-file",
                                                                  port_file, "--switch-ms", "100"},
                                                                 dir_.File("sim.log")));
    const int port = process::WaitForPortFile(port_file, child_.get(), std::chrono::seconds(10));
    if (port > 0) return port;
    if (!child_->Running()) return absl::UnavailableError(absl::StrCat("pleo_sim: exited (", binary, ")"));
    return absl::DeadlineExceededError("pleo_sim: no port file within 10 s");
  }

 private:
  process::TempDir dir_{"kinemo-e2e"};  // removed after the child has stopped
  std::unique_ptr<process::ChildProcess> child_;
};

}  // namespace kinemo::coordinator
