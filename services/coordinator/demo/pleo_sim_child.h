// pleo_sim as a child process on an ephemeral loopback port, for the
// benchmark and the demo; SIGTERM (then waits) on destruction.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "common/status/status.h"

namespace kinemo::coordinator {

// pleo_sim as a child; SIGTERM on destruction.
class PleoSimChild {
 public:
  ~PleoSimChild() {
    if (pid_ > 0) {
      ::kill(pid_, SIGTERM);
      ::waitpid(pid_, nullptr, 0);
    }
    std::error_code ec;
    if (!dir_.empty()) std::filesystem::remove_all(dir_, ec);
  }
  StatusOr<int> Start(const std::string& binary) {
    char tmpl[] = "/tmp/kinemo-e2e-XXXXXX";
    if (::mkdtemp(tmpl) == nullptr) return absl::InternalError("mkdtemp failed");
    dir_ = tmpl;
    const std::string pf = dir_ + "/port", log = dir_ + "/sim.log";
    pid_ = ::fork();
    if (pid_ == 0) {
      const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (fd >= 0) {
        ::dup2(fd, 1);
        ::dup2(fd, 2);
      }
      ::execl(binary.c_str(), binary.c_str(), "--tcp", "127.0.0.1:0", "--port-file", pf.c_str(),
              "--switch-ms", "100", static_cast<char*>(nullptr));
      ::_exit(127);
    }
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (std::chrono::steady_clock::now() < until) {
      std::ifstream in(pf);
      int port = 0;
      if (in >> port && port > 0) return port;
      if (::waitpid(pid_, nullptr, WNOHANG) == pid_) {
        pid_ = -1;
        return absl::UnavailableError(absl::StrCat("pleo_sim: exited (", binary, ")"));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return absl::DeadlineExceededError("pleo_sim: no port file within 10 s");
  }

 private:
  pid_t pid_ = -1;
  std::string dir_;
};


}  // namespace kinemo::coordinator
