// Process launching (kinemo_process): start a child binary with its
// arguments, its output in a log file; wait until it is ready; stop exactly
// the processes that were started. Used by the CLI's embedded stack
// (`kinemo animate`), `kinemo studio`, the system benchmarks (kinemo-bench)
// and, through common/testing/process.h, the integration-test harness.
//
//   auto svc = ServiceProcess::Start({.binary = allinone, .args = {"--config", cfg}});
//   ASSERT_TRUE(svc.ok()) << svc.status();
//   auto stub = Prosody::NewStub((*svc)->Channel());
//
// ServiceProcess adds `--host 127.0.0.1 --port 0 --port-file F`, waits for F
// (while checking the child is alive), then for grpc.health.v1 to report
// SERVING — there are no fixed sleeps. On destruction it sends SIGTERM to its
// own child only, waits, and escalates to SIGKILL after a timeout.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/channel.h>

#include "common/grpc/tls_credentials.h"
#include "common/status/status.h"

namespace kinemo::process {

// A child process with stdout+stderr captured to a log file.
class ChildProcess {
 public:
  // Starts argv[0] with the given arguments. `log_path` receives its output.
  static StatusOr<std::unique_ptr<ChildProcess>> Spawn(const std::vector<std::string>& argv,
                                                       const std::string& log_path);
  ~ChildProcess();
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  pid_t pid() const { return pid_; }
  // True while the child has not exited (reaps it if it has).
  bool Running();
  // Sends `signal` and waits up to `timeout` for the exit, then SIGKILLs.
  // Returns the exit code, or 128+signal if it was killed by a signal.
  StatusOr<int> Stop(int signal, std::chrono::milliseconds timeout);
  // Waits for exit up to `timeout` without signalling.
  StatusOr<int> WaitExit(std::chrono::milliseconds timeout);
  // Exit code once exited (see Stop).
  int exit_code() const { return exit_code_; }
  const std::string& log_path() const { return log_path_; }
  // The captured output so far.
  std::string ReadLog() const;

  // Runs argv to its end (at most `timeout`, then it is killed and the
  // status says so): its exit code; its output (stdout and stderr, kept in
  // `log_path` too) in `output`.
  static StatusOr<int> Run(const std::vector<std::string>& argv, const std::string& log_path,
                           std::chrono::milliseconds timeout, std::string* output);

 private:
  ChildProcess() = default;
  void Reap(int wait_status);
  pid_t pid_ = -1;
  bool exited_ = false;
  int exit_code_ = -1;
  std::string log_path_;
};

// A scratch directory ($TMPDIR or /tmp, named PREFIX-XXXXXX) removed
// (recursively) on destruction.
class TempDir {
 public:
  explicit TempDir(const std::string& prefix = "kinemo");
  ~TempDir();
  const std::string& path() const { return path_; }
  std::string File(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

struct ServiceProcessOptions {
  std::string binary;                 // absolute path of the service binary
  std::vector<std::string> args;      // extra arguments (e.g. --config FILE)
  std::string health_service;         // service name to wait for; "" = whole server
  ClientTlsFiles tls;                 // how Channel() and the health wait connect (plaintext by default)
  std::chrono::milliseconds ready_timeout{30000};
  bool metrics = false;               // also serve GET /metrics on an ephemeral port (metrics_port())
};

// A service binary on an ephemeral loopback port, ready when Start returns.
class ServiceProcess {
 public:
  static StatusOr<std::unique_ptr<ServiceProcess>> Start(const ServiceProcessOptions& options);
  ~ServiceProcess();

  const std::string& address() const { return address_; }
  int port() const { return port_; }
  // The /metrics port when started with `metrics` (else 0).
  int metrics_port() const { return metrics_port_; }
  // A new channel to the service, with the options' TLS.
  std::shared_ptr<grpc::Channel> Channel() const;
  ChildProcess& process() { return *process_; }
  // SIGTERM, then the exit code (0 after a graceful shutdown).
  StatusOr<int> Stop(std::chrono::milliseconds timeout = std::chrono::milliseconds(10000));

 private:
  ServiceProcess() = default;
  TempDir dir_;
  std::unique_ptr<ChildProcess> process_;
  std::shared_ptr<grpc::ChannelCredentials> credentials_;
  std::string address_;
  int port_ = 0;
  int metrics_port_ = 0;
};

// Asks grpc.health.v1 until it reports SERVING for `service` or the deadline
// passes. Waits for the channel to connect first.
Status WaitForServing(const std::shared_ptr<grpc::Channel>& channel, const std::string& service,
                      std::chrono::milliseconds timeout);

// Waits for a port file written by a child that is no gRPC server (e.g.
// pleo_sim's Modbus port) while the child lives: the port, or -1.
int WaitForPortFile(const std::string& path, ChildProcess* child,
                    std::chrono::milliseconds timeout = std::chrono::milliseconds(20000));

}  // namespace kinemo::process
