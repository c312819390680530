// kinemo_allinone: every kinemo service in one process (the embedded
// default), all on one address (`server`, with its TLS when configured):
// prosody, inference, planner, cube_tracker and (when robots are configured)
// robot_bridge are registered on that server; the coordinator runs on an
// in-process-only server, reached from the public address through the
// forwarder (services/coordinator/forwarder.h), and calls the others through
// the public server's in-process channel. There is no other port.
//
// One artifact store for the process (docs/store.md): AllInOneOptions.store_dir
// (default $KINEMO_STORE_DIR, else $HOME/.local/share/kinemo/store) and a
// seed store (default share/kinemo/store beside the binary) fill every
// service's own fields that are empty.
//
//   kinemo_allinone [--config allinone.textproto] [--host H] [--port P] [--port-file F]
#include <cstdlib>
#include <filesystem>
#include <iostream>

#include "common/config/options.h"
#include "common/logging/log.h"
#include "common/server/request_guard.h"
#include "common/server/service_host.h"
#include "kinemo/coordinator/v1/allinone.pb.h"
#include "services/coordinator/coordinator_service.h"
#include "services/coordinator/forwarder.h"
#include "services/cube_tracker/cube_tracker_service.h"
#include "services/inference/inference_service.h"
#include "services/planner/rpc/planner_service.h"
#include "services/prosody/prosody_service.h"
#include "services/robot_bridge/robot_bridge_service.h"

namespace {

namespace fs = std::filesystem;
using kinemo::Status;
using kinemo::StatusOr;
using kinemo::server::HostedService;
using kinemo::coordinator::v1::AllInOneOptions;

// AllInOneOptions.store_dir's default.
StatusOr<std::string> DefaultStoreDir() {
  if (const char* env = std::getenv("KINEMO_STORE_DIR"); env != nullptr && *env) return std::string(env);
  if (const char* home = std::getenv("HOME"); home != nullptr && *home) {
    return (fs::path(home) / ".local" / "share" / "kinemo" / "store").string();
  }
  return absl::FailedPreconditionError("store_dir: not set, and neither $KINEMO_STORE_DIR nor $HOME is");
}

// AllInOneOptions.seed_store_dir's default: share/kinemo/store beside the
// binary (<prefix>/bin/kinemo_allinone -> <prefix>/share/kinemo/store; in
// the build tree, build/services/allinone/kinemo_allinone ->
// build/share/kinemo/store), or "" when there is none.
std::string DefaultSeedStoreDir() {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  if (ec) return "";
  for (const fs::path& prefix : {self.parent_path().parent_path(), self.parent_path().parent_path().parent_path()}) {
    const fs::path seed = prefix / "share" / "kinemo" / "store";
    if (fs::is_directory(seed, ec)) return seed.string();
  }
  return "";
}

// Fills every service's store_dir / seed_store_dir left empty.
Status ApplyStoreDefaults(AllInOneOptions* o) {
  std::string store = o->store_dir();
  if (store.empty()) {
    KINEMO_ASSIGN_OR_RETURN(store, DefaultStoreDir());
  }
  const std::string seed = !o->seed_store_dir().empty() ? o->seed_store_dir() : DefaultSeedStoreDir();
  auto* inference = o->mutable_inference();
  if (inference->store_dir().empty() && inference->model_dir().empty()) inference->set_store_dir(store);
  if (inference->seed_store_dir().empty()) inference->set_seed_store_dir(seed);
  auto* planner = o->mutable_planner();
  if (planner->store_dir().empty()) planner->set_store_dir(store);
  if (planner->seed_store_dir().empty()) planner->set_seed_store_dir(seed);
  auto* prosody = o->mutable_prosody();  // face models
  if (prosody->store_dir().empty()) prosody->set_store_dir(store);
  if (prosody->seed_store_dir().empty()) prosody->set_seed_store_dir(seed);
  auto* cube = o->mutable_cube_tracker();
  if (cube->store_dir().empty()) cube->set_store_dir(store);
  if (cube->seed_store_dir().empty()) cube->set_seed_store_dir(seed);
  // The coordinator's durable sessions (sessions.db) beside the artifacts.
  auto* coordinator = o->mutable_coordinator();
  if (coordinator->store_dir().empty()) coordinator->set_store_dir(store);
  kinemo::log::Info("store", {{"store_dir", store}, {"seed_store_dir", seed}});
  return absl::OkStatus();
}

StatusOr<std::vector<HostedService>> MakeServices(const AllInOneOptions& o) {
  std::vector<HostedService> out;
  out.push_back({std::make_shared<kinemo::prosody::ProsodyServiceImpl>(o.prosody()),
                 kinemo::prosody::v1::ProsodyService::service_full_name()});
  KINEMO_ASSIGN_OR_RETURN(auto inf, kinemo::inference::InferenceServiceImpl::Create(o.inference()));
  out.push_back({inf, kinemo::inference::v1::InferenceService::service_full_name()});
  KINEMO_ASSIGN_OR_RETURN(auto planner, kinemo::planner::PlannerServiceImpl::Create(o.planner()));
  out.push_back({planner, kinemo::planner::v1::PlannerService::service_full_name()});
  KINEMO_ASSIGN_OR_RETURN(auto cube, kinemo::cube_tracker::CubeTrackerService::Create(o.cube_tracker()));
  out.push_back({cube, kinemo::cube_tracker::v1::CubeTrackerService::service_full_name()});
  if (o.robot_bridge().robots_size() > 0) {
    KINEMO_ASSIGN_OR_RETURN(auto bridge, kinemo::robot_bridge::RobotBridgeServiceImpl::Create(o.robot_bridge()));
    out.push_back({bridge, kinemo::robot_bridge::v1::RobotBridgeService::service_full_name()});
  }
  return out;
}

int Fail(const Status& s) {
  kinemo::log::Error("start_failed", {{"error", std::string(s.message())}});
  return s.code() == absl::StatusCode::kInvalidArgument ? 2 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  kinemo::server::BlockTerminationSignals();
  constexpr const char* kName = "kinemo_allinone";
  auto command_line = kinemo::config::ParseServerCommandLine(argc, argv, kName);
  if (!command_line.ok()) {
    std::cerr << kName << ": " << command_line.status().message() << "\n";
    return 2;
  }
  if (command_line->help) {
    std::cout << command_line->usage;
    return 0;
  }
  AllInOneOptions options;
  // The embedded default listens where clients look first (`--port 0` for an
  // ephemeral port: a zero in the options file cannot override this).
  options.mutable_server()->set_port(50050);
  if (auto s = kinemo::config::LoadServiceOptions(*command_line, &options); !s.ok()) {
    std::cerr << kName << ": " << s.message() << "\n";
    return 2;
  }
  const auto& server_options = options.server();
  kinemo::log::Configure(*kinemo::log::ParseLevel(server_options.log_level()),
                         *kinemo::log::ParseFormat(server_options.log_format()), kName);
  if (Status s = ApplyStoreDefaults(&options); !s.ok()) return Fail(s);
  kinemo::server::RedactOptionPaths(options);  // no configured root in the messages clients get

  auto services = MakeServices(options);
  if (!services.ok()) return Fail(services.status());
  // Coordinator calls reach the coordinator through the forwarder; it is
  // started once the server it calls runs, so calls wait for it briefly.
  const std::string coordinator_name = kinemo::coordinator::v1::CoordinatorService::service_full_name();
  auto forwarder = std::make_shared<kinemo::coordinator::Forwarder>(
      std::map<std::string, kinemo::coordinator::ForwardTarget>{}, std::map<std::string, std::string>{}, false);
  forwarder->Expect(coordinator_name, std::chrono::seconds(30));
  services->push_back({.generic = forwarder});
  auto host = kinemo::server::ServiceHost::Start(server_options, kName, std::move(*services));
  if (!host.ok()) return Fail(host.status());

  const auto args = kinemo::server::ChannelArgsForMessageLimit(server_options.max_message_bytes());
  auto channel = (*host)->InProcessChannel(args);
  const bool has_bridge = options.robot_bridge().robots_size() > 0;
  kinemo::coordinator::ServiceChannels channels{channel, channel, channel, channel, has_bridge ? channel : nullptr};
  kinemo::coordinator::v1::CoordinatorOptions coordinator_options = options.coordinator();
  coordinator_options.clear_services();
  *coordinator_options.mutable_server() = server_options;
  auto coordinator = kinemo::coordinator::CoordinatorServiceImpl::Create(coordinator_options, channels);
  if (!coordinator.ok()) return Fail(coordinator.status());
  auto coordinator_host = kinemo::server::ServiceHost::StartInProcess(
      "allinone_coordinator", {{*coordinator, coordinator_name}}, server_options.max_message_bytes());
  if (!coordinator_host.ok()) return Fail(coordinator_host.status());
  forwarder->SetTarget(coordinator_name, {(*coordinator_host)->InProcessChannel(args), ""});
  (*host)->SetServing(coordinator_name, true);
  auto metrics = kinemo::server::StartMetricsEndpoint(server_options, *command_line);
  if (!metrics.ok()) return Fail(metrics.status());

  if (!command_line->port_file.empty()) {
    if (auto s = kinemo::config::WriteFileAtomically(command_line->port_file, kinemo::StrCat((*host)->port(), "\n"));
        !s.ok()) {
      return Fail(s);
    }
  }
  kinemo::log::Info("listening", {{"address", (*host)->address()},
                                  {"port", (*host)->port()},
                                  {"tls", server_options.has_tls() && !server_options.tls().cert_file().empty()}});
  const int sig = kinemo::server::WaitForTerminationSignal();
  kinemo::log::Info("shutting_down", {{"signal", sig}});
  // The coordinator's background calls (relays, cube streams) end first,
  // while the services they call still run.
  (*coordinator)->Stop();
  (*host)->Shutdown();
  (*coordinator_host)->Shutdown();
  host->reset();
  coordinator_host->reset();
  metrics->reset();
  kinemo::log::Info("stopped");
  return 0;
}
