// kinemo robot set|status|watch|bench — talk to a running robot_bridge, or
// benchmark the bridge against pleo_sim.
#include <google/protobuf/util/json_util.h>
#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <iostream>

#include "nlohmann/json.hpp"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"
#include "services/cli/channel.h"
#include "services/cli/commands.h"
#include "services/cli/proto_json.h"
#include "bench/robot/robot_bench.h"

namespace kinemo::cli {

namespace {
namespace cmd_robot {  // this file's own helpers (the unity build puts files together)

namespace v1 = ::kinemo::robot_bridge::v1;
constexpr const char* kDefaultBridge = "127.0.0.1:50055";

std::string Json(const google::protobuf::Message& m) { return ProtoJson(m); }

std::string EmotionName(int e) {
  switch (e) {
    case common::v1::EMOTION_NEUTRAL: return "neutral";
    case common::v1::EMOTION_HAPPY: return "happy";
    case common::v1::EMOTION_ANGRY: return "angry";
    default: return "unknown";
  }
}

[[noreturn]] void Fail(const std::string& what, const grpc::Status& s) {
  static const char* kCodes[] = {"OK", "CANCELLED", "UNKNOWN", "INVALID_ARGUMENT",
                                 "DEADLINE_EXCEEDED", "NOT_FOUND", "ALREADY_EXISTS",
                                 "PERMISSION_DENIED", "RESOURCE_EXHAUSTED",
                                 "FAILED_PRECONDITION", "ABORTED", "OUT_OF_RANGE",
                                 "UNIMPLEMENTED", "INTERNAL", "UNAVAILABLE", "DATA_LOSS",
                                 "UNAUTHENTICATED"};
  const int code = static_cast<int>(s.error_code());
  std::cerr << "kinemo robot " << what << ": " << (code >= 0 && code <= 16 ? kCodes[code] : "?")
            << ": " << s.error_message() << "\n";
  throw CliExit{s.error_code() == grpc::StatusCode::INVALID_ARGUMENT ? 2 : 1};
}

std::unique_ptr<v1::RobotBridgeService::Stub> Stub(const std::string& address) {
  return v1::RobotBridgeService::NewStub(ServerChannel(address));
}

void PrintStatus(const v1::RobotStatus& s) {
  std::printf("%s: %s", s.robot_id().c_str(), s.connected() ? "connected" : "NOT CONNECTED");
  if (!s.firmware_version().empty()) {
    const char* states[] = {"unknown", "following", "switching", "autonomous", "sleeping"};
    std::printf(", shows %s (%.2f), state %s, battery %.1f%%, applied seq %u",
                EmotionName(s.shown_emotion()).c_str(), s.shown_intensity(),
                states[std::clamp(static_cast<int>(s.state()), 0, 4)], s.battery_percent(),
                s.last_applied_sequence());
  }
  if (s.last_commanded_sequence() != 0) {
    std::printf(", commanded %s seq %u%s", EmotionName(s.commanded_emotion()).c_str(),
                s.last_commanded_sequence(), s.in_sync() ? " (in sync)" : " (pending)");
  }
  for (const auto& f : s.faults()) std::printf(", fault %s", f.c_str());
  std::string touched;
  for (const auto& t : s.touch_sensors()) {
    if (t.touched()) touched += (touched.empty() ? "" : ",") + t.name();
  }
  if (!touched.empty()) std::printf(", touched %s", touched.c_str());
  if (!s.last_error().empty()) std::printf(", last error: %s", s.last_error().c_str());
  std::printf("\n");
}

}  // namespace cmd_robot
}  // namespace

void RegisterRobotCommands(CLI::App& app) {
  using namespace cmd_robot;
  auto* robot = app.add_subcommand("robot", "Drive a robot through robot_bridge; benchmark it");
  robot->require_subcommand(1);

  // set
  {
    auto* cmd = robot->add_subcommand("set", "Command an emotion: kinemo robot set ROBOT EMOTION");
    struct Args {
      std::string bridge = kDefaultBridge, robot, emotion;
      double intensity = 0.5, timeout_s = 2.0;
      bool wait = false, json = false;
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("robot", a->robot, "robot id")->required();
    cmd->add_option("emotion", a->emotion, "neutral | happy | angry")->required();
    cmd->add_option("-i,--intensity", a->intensity, "intensity in [0, 1]")->capture_default_str();
    cmd->add_flag("-w,--wait", a->wait, "wait until the robot shows it");
    cmd->add_option("--bridge", a->bridge, "robot_bridge address")->capture_default_str();
    cmd->add_option("--timeout-s", a->timeout_s, "deadline of the call")->capture_default_str();
    cmd->add_flag("--json", a->json, "print the response as JSON");
    cmd->callback([a] {
      std::string e = a->emotion;
      std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
      v1::SetEmotionRequest req;
      req.set_robot_id(a->robot);
      if (e == "neutral") req.set_emotion(common::v1::EMOTION_NEUTRAL);
      else if (e == "happy") req.set_emotion(common::v1::EMOTION_HAPPY);
      else if (e == "angry") req.set_emotion(common::v1::EMOTION_ANGRY);
      else {
        std::cerr << "kinemo robot set: emotion: '" << a->emotion
                  << "' is not neutral, happy or angry\n";
        throw CliExit{2};
      }
      req.set_intensity(a->intensity);
      req.set_wait_applied(a->wait);
      v1::SetEmotionResponse resp;
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::milliseconds(static_cast<int64_t>(a->timeout_s * 1000)));
      grpc::Status s = Stub(a->bridge)->SetEmotion(&ctx, req, &resp);
      if (!s.ok()) Fail("set", s);
      if (a->json) {
        std::printf("%s\n", Json(resp).c_str());
      } else {
        std::printf("%s: %s (%.2f) seq %u acknowledged%s in %.1f ms, %u retries\n",
                    a->robot.c_str(), e.c_str(), a->intensity, resp.sequence_number(),
                    resp.shown() ? " and shown" : "", resp.round_trip_ms(), resp.retries());
      }
    });
  }

  // status
  {
    auto* cmd = robot->add_subcommand("status", "Status of one robot, or of all (no ROBOT)");
    struct Args {
      std::string bridge = kDefaultBridge, robot;
      bool json = false;
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("robot", a->robot, "robot id (empty = list every robot)");
    cmd->add_option("--bridge", a->bridge, "robot_bridge address")->capture_default_str();
    cmd->add_flag("--json", a->json, "print JSON");
    cmd->callback([a] {
      auto stub = Stub(a->bridge);
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(2));
      if (a->robot.empty()) {
        v1::ListRobotsResponse resp;
        grpc::Status s = stub->ListRobots(&ctx, v1::ListRobotsRequest(), &resp);
        if (!s.ok()) Fail("status", s);
        if (a->json) {
          std::printf("%s\n", Json(resp).c_str());
          return;
        }
        for (const auto& r : resp.robots()) {
          std::printf("[%s unit %u] ", r.endpoint().c_str(), r.unit_id());
          PrintStatus(r.status());
        }
        return;
      }
      v1::GetStatusRequest req;
      req.set_robot_id(a->robot);
      v1::RobotStatus resp;
      grpc::Status s = stub->GetStatus(&ctx, req, &resp);
      if (!s.ok()) Fail("status", s);
      if (a->json) {
        std::printf("%s\n", Json(resp).c_str());
      } else {
        PrintStatus(resp);
      }
    });
  }

  // watch
  {
    auto* cmd = robot->add_subcommand("watch", "Stream status changes (Ctrl-C to stop)");
    struct Args {
      std::string bridge = kDefaultBridge, robot;
      int count = 0;
      double min_interval_s = 0;
      bool json = false;
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("robot", a->robot, "robot id (empty = every robot)");
    cmd->add_option("-n,--count", a->count, "stop after N messages (0 = never)");
    cmd->add_option("--min-interval-s", a->min_interval_s, "shortest gap per robot");
    cmd->add_option("--bridge", a->bridge, "robot_bridge address")->capture_default_str();
    cmd->add_flag("--json", a->json, "one JSON object per line");
    cmd->callback([a] {
      v1::WatchStatusRequest req;
      req.set_robot_id(a->robot);
      req.set_min_interval_s(a->min_interval_s);
      grpc::ClientContext ctx;
      auto reader = Stub(a->bridge)->WatchStatus(&ctx, req);
      v1::RobotStatus st;
      int n = 0;
      while (reader->Read(&st)) {
        if (a->json) {
          std::printf("%s\n", Json(st).c_str());
        } else {
          PrintStatus(st);
        }
        std::fflush(stdout);
        if (a->count > 0 && ++n >= a->count) {
          ctx.TryCancel();
          break;
        }
      }
      grpc::Status s = reader->Finish();
      if (!s.ok() && !(a->count > 0 && n >= a->count)) Fail("watch", s);
    });
  }

  // bench
  {
    auto* cmd = robot->add_subcommand(
        "bench", "SetEmotion round trips against pleo_sim over loopback TCP and RTU (socat pty)");
    struct Args {
      robot_bridge::BenchOptions o;
      bool json = false, no_rtu = false;
    };
    auto a = std::make_shared<Args>();
    cmd->add_flag("--json", a->json,
                  "print {tcp_p50_ms, tcp_p99_ms, rtu_p99_ms, commands_per_s, ...}");
    cmd->add_option("--pleo-sim", a->o.pleo_sim, "pleo_sim binary (default: beside kinemo)");
    cmd->add_option("--commands", a->o.tcp_commands, "timed commands over TCP")
        ->capture_default_str();
    cmd->add_option("--rtu-commands", a->o.rtu_commands, "timed commands over RTU")
        ->capture_default_str();
    cmd->add_option("--baud", a->o.rtu_baud, "RTU baud rate")->capture_default_str();
    cmd->add_flag("--no-rtu", a->no_rtu, "skip the RTU part");
    cmd->callback([a] {
      robot_bridge::BenchOptions o = a->o;
      o.rtu = !a->no_rtu;
      if (o.pleo_sim.empty()) o.pleo_sim = robot_bridge::FindPleoSim("kinemo");
      auto r = robot_bridge::RunRobotBench(o);
      if (!r.ok()) {
        std::cerr << "kinemo robot bench: " << r.status().message() << "\n";
        throw CliExit{1};
      }
      nlohmann::json j;
      j["tcp_p50_ms"] = r->tcp_p50_ms;
      j["tcp_p99_ms"] = r->tcp_p99_ms;
      j["rtu_p99_ms"] = r->rtu_commands > 0 ? nlohmann::json(r->rtu_p99_ms) : nlohmann::json();
      j["commands_per_s"] = r->commands_per_s;
      j["rtu_p50_ms"] = r->rtu_commands > 0 ? nlohmann::json(r->rtu_p50_ms) : nlohmann::json();
      j["tcp_max_ms"] = r->tcp_max_ms;
      j["rtu_max_ms"] = r->rtu_commands > 0 ? nlohmann::json(r->rtu_max_ms) : nlohmann::json();
      j["tcp_commands"] = r->tcp_commands;
      j["rtu_commands"] = r->rtu_commands;
      j["rtu_baud"] = o.rtu_baud;
      if (!r->rtu_skipped.empty()) j["rtu_skipped"] = r->rtu_skipped;
      j["path"] = "gRPC loopback -> robot_bridge -> Modbus -> pleo_sim, acknowledged";
      if (a->json) {
        std::printf("%s\n", j.dump().c_str());
      } else {
        std::printf("SetEmotion round trip (%s)\n", j["path"].get<std::string>().c_str());
        std::printf("  TCP: p50 %.3f ms, p99 %.3f ms, max %.3f ms over %d commands; %.0f commands/s\n",
                    r->tcp_p50_ms, r->tcp_p99_ms, r->tcp_max_ms, r->tcp_commands,
                    r->commands_per_s);
        if (r->rtu_commands > 0) {
          std::printf("  RTU %d baud: p50 %.3f ms, p99 %.3f ms, max %.3f ms over %d commands\n",
                      o.rtu_baud, r->rtu_p50_ms, r->rtu_p99_ms, r->rtu_max_ms, r->rtu_commands);
        } else {
          std::printf("  RTU skipped: %s\n", r->rtu_skipped.c_str());
        }
      }
    });
  }
}

}  // namespace kinemo::cli
