// Helpers for robot_bridge integration tests: start real binaries (pleo_sim,
// socat, mbpoll, the pymodbus server), wait on readiness by condition with a
// deadline, and stop only the processes started here (by pid).
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <optional>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace kinemo::robot::testing {

class Child {
 public:
  Child() = default;
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;
  Child(Child&& o) noexcept : pid_(o.pid_) { o.pid_ = -1; }
  Child& operator=(Child&& o) noexcept {
    Stop();
    pid_ = o.pid_;
    o.pid_ = -1;
    return *this;
  }
  ~Child() { Stop(); }

  // Starts argv[0] with stdout/stderr to `log_path` (appended).
  static Child Start(const std::vector<std::string>& argv, const std::string& log_path) {
    Child c;
    pid_t pid = fork();
    if (pid == 0) {
      int fd = open(log_path.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
      if (fd >= 0) {
        dup2(fd, 1);
        dup2(fd, 2);
        close(fd);
      }
      std::vector<char*> args;
      for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
      args.push_back(nullptr);
      execv(args[0], args.data());
      _exit(127);
    }
    c.pid_ = pid;
    return c;
  }

  pid_t pid() const { return pid_; }
  bool running() {
    if (pid_ <= 0) return false;
    int status;
    pid_t r = waitpid(pid_, &status, WNOHANG);
    if (r == pid_) {
      pid_ = -1;
      return false;
    }
    return true;
  }
  // Sends `sig` to the child and reaps it.
  void Stop(int sig = SIGTERM) {
    if (pid_ <= 0) return;
    kill(pid_, sig);
    int status;
    for (int i = 0; i < 200; ++i) {
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    kill(pid_, SIGKILL);
    waitpid(pid_, &status, 0);
    pid_ = -1;
  }

 private:
  pid_t pid_ = -1;
};

inline std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

template <typename Pred>
bool WaitUntil(Pred pred, std::chrono::milliseconds timeout = std::chrono::seconds(10)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    if (pred()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return pred();
}

// Waits for a port file ("PORT\n") and returns the port, or 0.
inline int WaitForPortFile(const std::string& path,
                           std::chrono::milliseconds timeout = std::chrono::seconds(10)) {
  int port = 0;
  WaitUntil(
      [&] {
        std::string s = ReadFile(path);
        if (s.empty() || s.back() != '\n') return false;
        port = std::atoi(s.c_str());
        return port > 0;
      },
      timeout);
  return port;
}

// A temporary directory removed at the end.
class TempDir {
 public:
  TempDir() {
    char tmpl[] = "/tmp/kinemo_robot_XXXXXX";
    path_ = mkdtemp(tmpl);
  }
  ~TempDir() {
    std::string cmd = "rm -rf '" + path_ + "'";
    int rc = std::system(cmd.c_str());
    (void)rc;
  }
  std::string File(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

// socat -d -d pty,raw,echo=0 pty,raw,echo=0: two connected pseudo-terminals.
struct PtyPair {
  Child socat;
  std::string a, b;

  static std::optional<PtyPair> Start(const TempDir& dir) {
    PtyPair p;
    std::string log = dir.File("socat.log");
    p.socat = Child::Start({"/usr/bin/socat", "-d", "-d", "pty,raw,echo=0", "pty,raw,echo=0"}, log);
    std::vector<std::string> ptys;
    bool ok = WaitUntil([&] {
      ptys.clear();
      std::string s = ReadFile(log);
      std::regex re("PTY is (\\S+)");
      for (auto it = std::sregex_iterator(s.begin(), s.end(), re); it != std::sregex_iterator();
           ++it) {
        ptys.push_back((*it)[1]);
      }
      return ptys.size() >= 2 && s.find("starting data transfer loop") != std::string::npos;
    });
    if (!ok) return std::nullopt;
    p.a = ptys[0];
    p.b = ptys[1];
    return p;
  }
};

// Runs a command, returns its stdout (and exit code through `rc`).
inline std::string Run(const std::string& cmd, int* rc = nullptr) {
  std::string out;
  FILE* f = popen((cmd + " 2>&1").c_str(), "r");
  if (f == nullptr) return out;
  char buf[512];
  while (fgets(buf, sizeof(buf), f) != nullptr) out += buf;
  int status = pclose(f);
  if (rc != nullptr) *rc = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return out;
}

// Parses mbpoll's "[addr]: \tvalue" lines.
inline std::vector<std::pair<int, int>> ParseMbpoll(const std::string& out) {
  std::vector<std::pair<int, int>> v;
  std::regex re("\\[(\\d+)\\]:\\s+(-?\\d+)");
  for (auto it = std::sregex_iterator(out.begin(), out.end(), re); it != std::sregex_iterator();
       ++it) {
    v.emplace_back(std::stoi((*it)[1]), std::stoi((*it)[2]));
  }
  return v;
}

}  // namespace kinemo::robot::testing
