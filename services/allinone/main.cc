// kinemo_allinone: every kinemo service in one process (the embedded
// default). The coordinator listens on the configured address; prosody,
// inference, planner, cube_tracker and robot_bridge are served on an internal
// loopback server, and the coordinator calls them through in-process
// channels (no network hop).
//
//   kinemo_allinone [--config allinone.textproto] [--host H] [--port P] [--port-file F]
#include <iostream>

#include "common/config/options.h"
#include "common/logging/log.h"
#include "common/server/service_host.h"
#include "kinemo/coordinator/v1/allinone.pb.h"
#include "services/coordinator/coordinator_service.h"
#include "services/cube_tracker/cube_tracker_service.h"
#include "services/inference/inference_service.h"
#include "services/planner/planner_service.h"
#include "services/prosody/prosody_service.h"
#include "services/robot_bridge/robot_bridge_service.h"

namespace {

using kinemo::StatusOr;
using kinemo::server::HostedService;

StatusOr<std::vector<HostedService>> MakeInternalServices(
    const kinemo::coordinator::v1::AllInOneOptions& o) {
  std::vector<HostedService> out;
  out.push_back({std::make_shared<kinemo::prosody::ProsodyServiceImpl>(o.prosody()),
                 kinemo::prosody::v1::ProsodyService::service_full_name()});
  kinemo::inference::v1::InferenceOptions inference = o.inference();
  if (inference.model_dir().empty()) inference.set_model_dir("models");
  KINEMO_ASSIGN_OR_RETURN(auto inf, kinemo::inference::InferenceServiceImpl::Create(inference));
  out.push_back({inf, kinemo::inference::v1::InferenceService::service_full_name()});
  KINEMO_ASSIGN_OR_RETURN(auto planner, kinemo::planner::PlannerServiceImpl::Create(o.planner()));
  out.push_back({planner, kinemo::planner::v1::PlannerService::service_full_name()});
  KINEMO_ASSIGN_OR_RETURN(auto cube,
                          kinemo::cube_tracker::CubeTrackerService::Create(o.cube_tracker()));
  out.push_back({cube, kinemo::cube_tracker::v1::CubeTrackerService::service_full_name()});
  if (o.robot_bridge().robots_size() > 0) {
    KINEMO_ASSIGN_OR_RETURN(auto bridge,
                            kinemo::robot_bridge::RobotBridgeServiceImpl::Create(o.robot_bridge()));
    out.push_back({bridge, kinemo::robot_bridge::v1::RobotBridgeService::service_full_name()});
  }
  return out;
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
  kinemo::coordinator::v1::AllInOneOptions options;
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

  auto internal_services = MakeInternalServices(options);
  if (!internal_services.ok()) {
    kinemo::log::Error("start_failed", {{"error", std::string(internal_services.status().message())}});
    return internal_services.status().code() == absl::StatusCode::kInvalidArgument ? 2 : 1;
  }
  const bool has_bridge = options.robot_bridge().robots_size() > 0;
  kinemo::common::v1::ServerOptions internal_options = server_options;
  internal_options.set_host("127.0.0.1");
  internal_options.set_port(0);
  internal_options.clear_tls();
  auto internal = kinemo::server::ServiceHost::Start(internal_options, "allinone_internal",
                                                     std::move(*internal_services));
  if (!internal.ok()) {
    kinemo::log::Error("start_failed", {{"error", std::string(internal.status().message())}});
    return 1;
  }
  kinemo::log::Info("internal_listening", {{"address", (*internal)->address()}});

  const auto args = kinemo::server::ChannelArgsForMessageLimit(server_options.max_message_bytes());
  auto channel = (*internal)->InProcessChannel(args);
  kinemo::coordinator::ServiceChannels channels{channel, channel, channel, channel,
                                                has_bridge ? channel : nullptr};
  kinemo::coordinator::v1::CoordinatorOptions coordinator_options = options.coordinator();
  coordinator_options.clear_services();
  *coordinator_options.mutable_server() = server_options;
  auto coordinator =
      kinemo::coordinator::CoordinatorServiceImpl::Create(coordinator_options, channels);
  if (!coordinator.ok()) {
    kinemo::log::Error("start_failed", {{"error", std::string(coordinator.status().message())}});
    return coordinator.status().code() == absl::StatusCode::kInvalidArgument ? 2 : 1;
  }
  auto host = kinemo::server::ServiceHost::Start(
      server_options, kName,
      {{*coordinator, kinemo::coordinator::v1::CoordinatorService::service_full_name()}});
  if (!host.ok()) {
    kinemo::log::Error("start_failed", {{"error", std::string(host.status().message())}});
    return 1;
  }
  if (!command_line->port_file.empty()) {
    if (auto s = kinemo::config::WriteFileAtomically(command_line->port_file,
                                                     kinemo::StrCat((*host)->port(), "\n"));
        !s.ok()) {
      kinemo::log::Error("start_failed", {{"error", std::string(s.message())}});
      return 1;
    }
  }
  kinemo::log::Info("listening", {{"address", (*host)->address()}, {"port", (*host)->port()}});
  const int sig = kinemo::server::WaitForTerminationSignal();
  kinemo::log::Info("shutting_down", {{"signal", sig}});
  (*host)->Shutdown();
  (*coordinator)->Stop();
  (*internal)->Shutdown();
  host->reset();
  internal->reset();
  kinemo::log::Info("stopped");
  return 0;
}
