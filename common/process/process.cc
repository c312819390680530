#include "common/process/process.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include <grpcpp/client_context.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/numbers.h"
#include "absl/strings/strip.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace kinemo::process {
namespace {

// Poll interval while waiting for a readiness condition (not a guess at how
// long start-up takes: every wait is bounded by an explicit deadline).
constexpr std::chrono::milliseconds kPoll{5};

std::string Tail(const std::string& text, std::size_t n = 2000) {
  return text.size() <= n ? text : text.substr(text.size() - n);
}

}  // namespace

StatusOr<std::unique_ptr<ChildProcess>> ChildProcess::Spawn(const std::vector<std::string>& argv,
                                                            const std::string& log_path) {
  if (argv.empty()) return absl::InvalidArgumentError("argv: empty");
  if (access(argv[0].c_str(), X_OK) != 0) {
    return absl::NotFoundError(kinemo::StrCat(argv[0], ": not an executable file"));
  }
  const int log_fd = open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (log_fd < 0) return absl::InternalError(kinemo::StrCat(log_path, ": ", std::strerror(errno)));
  std::vector<char*> cargv;
  for (const auto& a : argv) cargv.push_back(const_cast<char*>(a.c_str()));
  cargv.push_back(nullptr);

  const pid_t pid = fork();
  if (pid < 0) {
    close(log_fd);
    return absl::ResourceExhaustedError(kinemo::StrCat("fork: ", std::strerror(errno)));
  }
  if (pid == 0) {
    // Child: unblock signals the parent (or gtest) may have blocked, redirect
    // output, exec. Only async-signal-safe calls here.
    sigset_t none;
    sigemptyset(&none);
    sigprocmask(SIG_SETMASK, &none, nullptr);
    dup2(log_fd, STDOUT_FILENO);
    dup2(log_fd, STDERR_FILENO);
    const int devnull = open("/dev/null", O_RDONLY);
    if (devnull >= 0) dup2(devnull, STDIN_FILENO);
    execv(cargv[0], cargv.data());
    _exit(127);
  }
  close(log_fd);
  auto child = std::unique_ptr<ChildProcess>(new ChildProcess());
  child->pid_ = pid;
  child->log_path_ = log_path;
  return child;
}

ChildProcess::~ChildProcess() {
  if (pid_ > 0 && !exited_) (void)Stop(SIGKILL, std::chrono::milliseconds(5000));
}

void ChildProcess::Reap(int wait_status) {
  exited_ = true;
  if (WIFEXITED(wait_status)) {
    exit_code_ = WEXITSTATUS(wait_status);
  } else if (WIFSIGNALED(wait_status)) {
    exit_code_ = 128 + WTERMSIG(wait_status);
  }
}

bool ChildProcess::Running() {
  if (exited_ || pid_ <= 0) return false;
  int st = 0;
  const pid_t r = waitpid(pid_, &st, WNOHANG);
  if (r == pid_) {
    Reap(st);
    return false;
  }
  return r == 0;
}

StatusOr<int> ChildProcess::WaitExit(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (Running()) {
    if (std::chrono::steady_clock::now() >= deadline) {
      return absl::DeadlineExceededError(
          kinemo::StrCat("pid ", pid_, " still running after ", timeout.count(), " ms"));
    }
    std::this_thread::sleep_for(kPoll);
  }
  return exit_code_;
}

StatusOr<int> ChildProcess::Stop(int signal, std::chrono::milliseconds timeout) {
  if (!Running()) return exit_code_;
  kill(pid_, signal);  // our own child only
  auto code = WaitExit(timeout);
  if (code.ok()) return code;
  kill(pid_, SIGKILL);
  int st = 0;
  if (waitpid(pid_, &st, 0) == pid_) Reap(st);
  return absl::DeadlineExceededError(kinemo::StrCat("pid ", pid_, " ignored signal ", signal,
                                                  " for ", timeout.count(), " ms; killed"));
}

StatusOr<int> ChildProcess::Run(const std::vector<std::string>& argv, const std::string& log_path,
                                std::chrono::milliseconds timeout, std::string* output) {
  KINEMO_ASSIGN_OR_RETURN(std::unique_ptr<ChildProcess> child, Spawn(argv, log_path));
  auto code = child->WaitExit(timeout);
  if (!code.ok()) (void)child->Stop(SIGKILL, std::chrono::seconds(5));
  *output = child->ReadLog();
  return code;
}

std::string ChildProcess::ReadLog() const {
  std::ifstream in(log_path_);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TempDir::TempDir(const std::string& prefix) {
  const char* base = std::getenv("TMPDIR");
  std::string templ = kinemo::StrCat(base != nullptr && *base ? base : "/tmp", "/", prefix, "-XXXXXX");
  if (mkdtemp(templ.data()) == nullptr) std::abort();
  path_ = templ;
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

Status WaitForServing(const std::shared_ptr<grpc::Channel>& channel, const std::string& service,
                      std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::system_clock::now() + timeout;
  if (!channel->WaitForConnected(deadline)) {
    return absl::DeadlineExceededError("health: channel did not connect before the deadline");
  }
  auto stub = grpc::health::v1::Health::NewStub(channel);
  std::string last = "no answer";
  while (std::chrono::system_clock::now() < deadline) {
    grpc::ClientContext ctx;
    ctx.set_deadline(deadline);
    grpc::health::v1::HealthCheckRequest req;
    req.set_service(service);
    grpc::health::v1::HealthCheckResponse resp;
    const grpc::Status st = stub->Check(&ctx, req, &resp);
    if (st.ok() && resp.status() == grpc::health::v1::HealthCheckResponse::SERVING) {
      return absl::OkStatus();
    }
    last = st.ok() ? grpc::health::v1::HealthCheckResponse::ServingStatus_Name(resp.status())
                   : st.error_message();
    std::this_thread::sleep_for(kPoll);
  }
  return absl::DeadlineExceededError(kinemo::StrCat("health: not SERVING before the deadline (", last, ")"));
}

StatusOr<std::unique_ptr<ServiceProcess>> ServiceProcess::Start(
    const ServiceProcessOptions& options) {
  auto sp = std::unique_ptr<ServiceProcess>(new ServiceProcess());
  KINEMO_ASSIGN_OR_RETURN(sp->credentials_, MakeChannelCredentials(options.tls));
  const std::string port_file = sp->dir_.File("port");
  std::vector<std::string> argv = {options.binary};
  argv.insert(argv.end(), options.args.begin(), options.args.end());
  argv.insert(argv.end(), {"--host", "127.0.0.1", "--port", "0", "--port-file", port_file});
  const std::string metrics_port_file = sp->dir_.File("metrics_port");
  if (options.metrics) argv.insert(argv.end(), {"--metrics-port", "0", "--metrics-port-file", metrics_port_file});
  KINEMO_ASSIGN_OR_RETURN(sp->process_, ChildProcess::Spawn(argv, sp->dir_.File("log")));

  const auto deadline = std::chrono::steady_clock::now() + options.ready_timeout;
  for (;;) {
    std::ifstream in(port_file);
    std::string text;
    if (in && std::getline(in, text) && absl::SimpleAtoi(absl::StripAsciiWhitespace(text), &sp->port_) &&
        sp->port_ > 0) {
      break;
    }
    if (!sp->process_->Running()) {
      return absl::UnavailableError(kinemo::StrCat(options.binary, " exited with code ",
                                                 sp->process_->exit_code(), " before listening:\n",
                                                 Tail(sp->process_->ReadLog())));
    }
    if (std::chrono::steady_clock::now() >= deadline) {
      return absl::DeadlineExceededError(kinemo::StrCat(options.binary, " wrote no port file within ",
                                                      options.ready_timeout.count(), " ms:\n",
                                                      Tail(sp->process_->ReadLog())));
    }
    std::this_thread::sleep_for(kPoll);
  }
  sp->address_ = kinemo::StrCat("127.0.0.1:", sp->port_);
  if (options.metrics) {
    // Written before the port file (ServiceMain).
    std::ifstream in(metrics_port_file);
    std::string text;
    if (!in || !std::getline(in, text) ||
        !absl::SimpleAtoi(absl::StripAsciiWhitespace(text), &sp->metrics_port_) || sp->metrics_port_ <= 0) {
      return absl::InternalError(kinemo::StrCat(options.binary, " wrote no --metrics-port-file"));
    }
  }
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
      deadline - std::chrono::steady_clock::now());
  if (Status s = WaitForServing(sp->Channel(), options.health_service,
                                std::max(left, std::chrono::milliseconds(1000)));
      !s.ok()) {
    return Annotate(s, kinemo::StrCat(options.binary, " (log: ", Tail(sp->process_->ReadLog()), ")"));
  }
  return sp;
}

ServiceProcess::~ServiceProcess() {
  if (process_ != nullptr) (void)process_->Stop(SIGTERM, std::chrono::milliseconds(10000));
}

std::shared_ptr<grpc::Channel> ServiceProcess::Channel() const {
  return grpc::CreateChannel(address_, credentials_);
}

StatusOr<int> ServiceProcess::Stop(std::chrono::milliseconds timeout) {
  return process_->Stop(SIGTERM, timeout);
}

int WaitForPortFile(const std::string& path, ChildProcess* child, std::chrono::milliseconds timeout) {
  const auto until = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < until) {
    std::ifstream in(path);
    int port = 0;
    if (in >> port && port > 0) return port;
    if (!child->Running()) return -1;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return -1;
}

}  // namespace kinemo::process
