#include "bench/robot/robot_bench.h"

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "absl/strings/str_cat.h"
#include "common/config/options.h"
#include "common/grpc/status_mapping.h"
#include "common/process/process.h"
#include "common/server/service_host.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"
#include "services/robot_bridge/robot_bridge_service.h"

namespace kinemo::robot_bridge {

namespace {

using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

// A child process started here and stopped here (kinemo_process): SIGTERM on
// scope exit, SIGKILL if it has not exited 3 s later.
class Child {
 public:
  static StatusOr<std::unique_ptr<Child>> Spawn(const std::vector<std::string>& argv,
                                                const std::string& log) {
    auto child = process::ChildProcess::Spawn(argv, log);
    if (!child.ok()) {
      return absl::FailedPreconditionError(absl::StrCat("cannot start ", child.status().message()));
    }
    auto c = std::unique_ptr<Child>(new Child());
    c->child_ = std::move(*child);
    return c;
  }
  ~Child() { (void)child_->Stop(SIGTERM, std::chrono::seconds(3)); }
  bool Running() { return child_->Running(); }

 private:
  Child() = default;
  std::unique_ptr<process::ChildProcess> child_;
};

std::string Slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

template <typename Pred>
bool WaitUntil(Pred pred, std::chrono::milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  while (Clock::now() < deadline) {
    if (pred()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return pred();
}

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  size_t rank = static_cast<size_t>(std::ceil(p / 100.0 * v.size()));
  return v[std::clamp<size_t>(rank, 1, v.size()) - 1];
}

Status Time(v1::RobotBridgeService::Stub& stub, const std::string& robot, int warmup, int n,
            std::vector<double>& ms_out, double& total_s) {
  for (int i = 0; i < warmup + n; ++i) {
    v1::SetEmotionRequest req;
    req.set_robot_id(robot);
    req.set_emotion(static_cast<common::v1::Emotion>(1 + i % 3));
    req.set_intensity((i % 11) / 10.0);
    v1::SetEmotionResponse resp;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(2));
    const auto t0 = Clock::now();
    grpc::Status s = stub.SetEmotion(&ctx, req, &resp);
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    if (!s.ok()) return Annotate(FromGrpcStatus(s, "robot_bridge"), absl::StrCat("SetEmotion #", i));
    if (i >= warmup) {
      ms_out.push_back(ms);
      total_s += ms / 1000.0;
    }
  }
  return absl::OkStatus();
}

}  // namespace

std::string FindPleoSim(const std::string& argv0) {
  std::error_code ec;
  fs::path self = fs::read_symlink("/proc/self/exe", ec);
  if (ec) self = fs::absolute(argv0, ec);
  const fs::path dir = self.parent_path();
  for (const fs::path& p : {dir / "pleo_sim", dir / ".." / "pleo_sim" / "pleo_sim"}) {
    if (fs::exists(p, ec)) return fs::weakly_canonical(p, ec).string();
  }
  return "";
}

StatusOr<BenchResult> RunRobotBench(const BenchOptions& o) {
  if (o.pleo_sim.empty() || access(o.pleo_sim.c_str(), X_OK) != 0) {
    return absl::FailedPreconditionError(
        absl::StrCat("pleo_sim: '", o.pleo_sim, "' is not an executable (use --pleo-sim PATH)"));
  }
  if (o.tcp_commands < 1 || o.rtu_commands < 1) {
    return absl::InvalidArgumentError("commands: must be >= 1");
  }
  char tmpl[] = "/tmp/kinemo_robot_bench_XXXXXX";
  if (mkdtemp(tmpl) == nullptr) return absl::InternalError("cannot create a temporary directory");
  const std::string dir = tmpl;
  struct Cleanup {
    std::string dir;
    ~Cleanup() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  } cleanup{dir};

  BenchResult result;
  // pleo_sim on loopback TCP, port chosen by the OS.
  const std::string port_file = dir + "/sim.port";
  KINEMO_ASSIGN_OR_RETURN(auto tcp_sim,
                          Child::Spawn({o.pleo_sim, "--tcp", "127.0.0.1:0", "--port-file",
                                        port_file},
                                       dir + "/sim_tcp.log"));
  int port = 0;
  WaitUntil(
      [&] {
        std::string s = Slurp(port_file);
        if (!s.empty() && s.back() == '\n') port = std::atoi(s.c_str());
        return port > 0 || !tcp_sim->Running();
      },
      std::chrono::seconds(10));
  if (port <= 0) {
    return absl::UnavailableError(
        absl::StrCat("pleo_sim did not report its port: ", Slurp(dir + "/sim_tcp.log")));
  }

  v1::RobotBridgeOptions options;
  auto* tcp = options.add_robots();
  tcp->set_robot_id("bench_tcp");
  tcp->mutable_tcp()->set_host("127.0.0.1");
  tcp->mutable_tcp()->set_port(static_cast<uint32_t>(port));

  // pleo_sim on a socat pty pair at 115200 baud.
  std::unique_ptr<Child> socat, rtu_sim;
  if (o.rtu) {
    auto s = Child::Spawn({"/usr/bin/socat", "-d", "-d", "pty,raw,echo=0", "pty,raw,echo=0"},
                          dir + "/socat.log");
    std::vector<std::string> ptys;
    if (s.ok()) {
      socat = std::move(*s);
      WaitUntil(
          [&] {
            ptys.clear();
            std::string log = Slurp(dir + "/socat.log");
            std::regex re("PTY is (\\S+)");
            for (auto it = std::sregex_iterator(log.begin(), log.end(), re);
                 it != std::sregex_iterator(); ++it) {
              ptys.push_back((*it)[1]);
            }
            return (ptys.size() >= 2 &&
                    log.find("starting data transfer loop") != std::string::npos) ||
                   !socat->Running();
          },
          std::chrono::seconds(10));
    }
    if (ptys.size() < 2) {
      result.rtu_skipped = s.ok() ? "socat did not create a pty pair" : std::string(s.status().message());
    } else {
      auto sim = Child::Spawn({o.pleo_sim, "--rtu", ptys[0], "--baud", std::to_string(o.rtu_baud)},
                              dir + "/sim_rtu.log");
      if (!sim.ok()) return sim.status();
      rtu_sim = std::move(*sim);
      auto* rtu = options.add_robots();
      rtu->set_robot_id("bench_rtu");
      rtu->mutable_rtu()->set_device(ptys[1]);
      rtu->mutable_rtu()->set_baud(static_cast<uint32_t>(o.rtu_baud));
    }
  } else {
    result.rtu_skipped = "--no-rtu";
  }

  KINEMO_ASSIGN_OR_RETURN(auto service, RobotBridgeServiceImpl::Create(options));
  common::v1::ServerOptions server;
  server.set_host("127.0.0.1");
  server.set_port(0);
  server.set_log_level("warn");
  config::ApplyServerDefaults(&server);
  KINEMO_ASSIGN_OR_RETURN(
      auto host, server::ServiceHost::Start(server, "robot_bridge_bench",
                                            {{service, v1::RobotBridgeService::service_full_name()}}));
  auto channel = grpc::CreateChannel(host->address(), grpc::InsecureChannelCredentials());
  auto stub = v1::RobotBridgeService::NewStub(channel);

  // Ready when a Modbus read through the bridge succeeds.
  auto ready = [&](const std::string& robot) {
    return WaitUntil(
        [&] {
          v1::GetStatusRequest req;
          req.set_robot_id(robot);
          v1::RobotStatus st;
          grpc::ClientContext ctx;
          ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(1));
          return stub->GetStatus(&ctx, req, &st).ok();
        },
        std::chrono::seconds(10));
  };
  if (!ready("bench_tcp")) return absl::UnavailableError("bench_tcp: pleo_sim not reachable");

  std::vector<double> tcp_ms;
  double tcp_s = 0;
  KINEMO_RETURN_IF_ERROR(Time(*stub, "bench_tcp", o.warmup, o.tcp_commands, tcp_ms, tcp_s));
  result.tcp_commands = static_cast<int>(tcp_ms.size());
  result.tcp_p50_ms = Percentile(tcp_ms, 50);
  result.tcp_p99_ms = Percentile(tcp_ms, 99);
  result.tcp_max_ms = Percentile(tcp_ms, 100);
  result.commands_per_s = tcp_s > 0 ? tcp_ms.size() / tcp_s : 0;

  if (rtu_sim) {
    if (!ready("bench_rtu")) return absl::UnavailableError("bench_rtu: pleo_sim not reachable");
    std::vector<double> rtu_ms;
    double rtu_s = 0;
    KINEMO_RETURN_IF_ERROR(Time(*stub, "bench_rtu", o.warmup, o.rtu_commands, rtu_ms, rtu_s));
    result.rtu_commands = static_cast<int>(rtu_ms.size());
    result.rtu_p50_ms = Percentile(rtu_ms, 50);
    result.rtu_p99_ms = Percentile(rtu_ms, 99);
    result.rtu_max_ms = Percentile(rtu_ms, 100);
  }
  host->Shutdown();
  host.reset();
  service.reset();  // stops the heartbeats before the simulators go
  return result;
}

}  // namespace kinemo::robot_bridge
