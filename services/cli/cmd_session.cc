// kinemo session open|act|watch|get|list|close — drive Vleo-Pleo sessions on
// a running coordinator.
#include <google/protobuf/util/json_util.h>
#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <iostream>

#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "services/cli/channel.h"
#include "services/cli/commands.h"
#include "services/cli/proto_json.h"

namespace kinemo::cli {

namespace {
namespace cmd_session {  // this file's own helpers (the unity build puts files together)

namespace v1 = ::kinemo::coordinator::v1;
constexpr const char* kDefaultCoordinator = "localhost:50050";

std::string Json(const google::protobuf::Message& m) { return ProtoJson(m); }

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

const char* EmotionWord(int e) {
  switch (e) {
    case common::v1::EMOTION_NEUTRAL: return "neutral";
    case common::v1::EMOTION_HAPPY: return "happy";
    case common::v1::EMOTION_ANGRY: return "angry";
    default: return "-";
  }
}

const char* ActionWord(int a) {
  switch (a) {
    case common::v1::ACTION_IDLE: return "idle";
    case common::v1::ACTION_KISSES: return "kisses";
    case common::v1::ACTION_SHOUTING: return "shouting";
    default: return "-";
  }
}

[[noreturn]] void Fail(const std::string& what, const grpc::Status& s) {
  std::cerr << "kinemo session " << what << ": " << s.error_message() << " (code "
            << static_cast<int>(s.error_code()) << ")\n";
  throw CliExit{s.error_code() == grpc::StatusCode::INVALID_ARGUMENT ? 2 : 1};
}

std::unique_ptr<v1::CoordinatorService::Stub> Stub(const std::string& address) {
  return v1::CoordinatorService::NewStub(ServerChannel(address));
}

void Deadline(grpc::ClientContext* ctx, double s) {
  ctx->set_deadline(std::chrono::system_clock::now() +
                    std::chrono::milliseconds(static_cast<int64_t>(s * 1000)));
}

void PrintSession(const v1::Session& s) {
  std::printf("%s: robot %s, %s %.2f, valence %+.3f, emotion %s, robot shows %s%s%s, %.1f s\n",
              s.session_id().c_str(), s.robot_id().c_str(), ActionWord(s.action()),
              s.intensity(), s.valence(), EmotionWord(s.emotion()), EmotionWord(s.robot_emotion()),
              s.robot_connected() ? "" : " (robot not connected)",
              s.cube_attached() ? ", cube attached" : "", s.session_time_s());
}

void PrintEvent(const v1::SessionEvent& e) {
  std::printf("[%8.3f s] %s ", e.session_time_s(), e.session_id().c_str());
  switch (e.event_case()) {
    case v1::SessionEvent::kSnapshot:
      std::printf("snapshot: ");
      PrintSession(e.snapshot());
      return;
    case v1::SessionEvent::kActionChanged:
      std::printf("action %s %.2f%s\n", ActionWord(e.action_changed().action()),
                  e.action_changed().intensity(), e.action_changed().from_cube() ? " (cube)" : "");
      return;
    case v1::SessionEvent::kEmotionChanged:
      std::printf("emotion %s -> %s (valence %+.3f, %s)\n",
                  EmotionWord(e.emotion_changed().from_emotion()),
                  EmotionWord(e.emotion_changed().to_emotion()), e.emotion_changed().valence(),
                  ActionWord(e.emotion_changed().action()));
      return;
    case v1::SessionEvent::kRobotCommanded:
      if (e.robot_commanded().error().empty()) {
        std::printf("robot commanded %s, seq %u, %.2f ms\n",
                    EmotionWord(e.robot_commanded().emotion()),
                    e.robot_commanded().sequence_number(), e.robot_commanded().latency_ms());
      } else {
        std::printf("robot command %s failed: %s\n", EmotionWord(e.robot_commanded().emotion()),
                    e.robot_commanded().error().c_str());
      }
      return;
    case v1::SessionEvent::kRobotStatusChanged:
      std::printf("robot %s, shows %s\n",
                  e.robot_status_changed().connected() ? "connected" : "NOT CONNECTED",
                  EmotionWord(e.robot_status_changed().shown_emotion()));
      return;
    case v1::SessionEvent::kCubeStatusChanged:
      std::printf("cube %s%s\n", e.cube_status_changed().attached() ? "attached" : "detached",
                  e.cube_status_changed().visible() ? ", visible" : "");
      return;
    case v1::SessionEvent::kSessionClosed:
      std::printf("closed (%s)\n", e.session_closed().reason().c_str());
      return;
    default:
      std::printf("?\n");
  }
}

}  // namespace cmd_session
}  // namespace

void RegisterSessionCommands(CLI::App& app) {
  using namespace cmd_session;
  auto* session = app.add_subcommand("session", "Vleo-Pleo sessions on a running coordinator");
  session->require_subcommand(1);
  struct Common {
    std::string coordinator = kDefaultCoordinator;
    double timeout_s = 5.0;
    bool json = false;
  };
  auto add_common = [](CLI::App* cmd, Common* c) {
    cmd->add_option("--coordinator", c->coordinator, "coordinator address")->capture_default_str();
    cmd->add_option("--timeout-s", c->timeout_s, "deadline of the call")->capture_default_str();
    cmd->add_flag("--json", c->json, "print JSON");
  };

  {
    auto* cmd = session->add_subcommand("open", "Open a session: kinemo session open ROBOT [--id ID]");
    struct Args : Common {
      std::string robot, id, name, initial = "neutral", vleo = "client";
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("robot", a->robot, "robot id, as the robot bridge knows it")->required();
    cmd->add_option("--id", a->id, "session id ([a-z0-9_-]{1,64}; empty = generated)");
    cmd->add_option("--name", a->name, "Vleo user's display name");
    cmd->add_option("--initial", a->initial, "initial emotion: neutral | happy | angry")
        ->capture_default_str();
    cmd->add_option("--vleo", a->vleo, "client | cube")->capture_default_str();
    add_common(cmd, a.get());
    cmd->callback([a] {
      v1::OpenSessionRequest req;
      req.set_session_id(a->id);
      req.set_robot_id(a->robot);
      req.set_vleo_name(a->name);
      const std::string e = Lower(a->initial);
      if (e == "neutral") req.set_initial_emotion(common::v1::EMOTION_NEUTRAL);
      else if (e == "happy") req.set_initial_emotion(common::v1::EMOTION_HAPPY);
      else if (e == "angry") req.set_initial_emotion(common::v1::EMOTION_ANGRY);
      else {
        std::cerr << "kinemo session open: --initial: '" << a->initial
                  << "' is not neutral, happy or angry\n";
        throw CliExit{2};
      }
      const std::string k = Lower(a->vleo);
      if (k == "client") req.set_vleo(v1::VLEO_KIND_CLIENT);
      else if (k == "cube") req.set_vleo(v1::VLEO_KIND_CUBE);
      else {
        std::cerr << "kinemo session open: --vleo: '" << a->vleo << "' is not client or cube\n";
        throw CliExit{2};
      }
      v1::OpenSessionResponse resp;
      grpc::ClientContext ctx;
      Deadline(&ctx, a->timeout_s);
      grpc::Status s = Stub(a->coordinator)->OpenSession(&ctx, req, &resp);
      if (!s.ok()) Fail("open", s);
      if (a->json) std::printf("%s\n", Json(resp.session()).c_str());
      else PrintSession(resp.session());
    });
  }

  {
    auto* cmd = session->add_subcommand(
        "act", "The Vleo acts: kinemo session act ID idle|kisses|shouting [-i INTENSITY]");
    struct Args : Common {
      std::string id, action;
      double intensity = 0.0;
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("id", a->id, "session id")->required();
    cmd->add_option("action", a->action, "idle | kisses | shouting")->required();
    cmd->add_option("-i,--intensity", a->intensity, "intensity in [-1, 1]")->capture_default_str();
    add_common(cmd, a.get());
    cmd->callback([a] {
      v1::ActRequest req;
      req.set_session_id(a->id);
      const std::string act = Lower(a->action);
      if (act == "idle") req.set_action(common::v1::ACTION_IDLE);
      else if (act == "kisses" || act == "kiss") req.set_action(common::v1::ACTION_KISSES);
      else if (act == "shouting" || act == "shout") req.set_action(common::v1::ACTION_SHOUTING);
      else {
        std::cerr << "kinemo session act: action: '" << a->action
                  << "' is not idle, kisses or shouting\n";
        throw CliExit{2};
      }
      req.set_intensity(a->intensity);
      v1::ActResponse resp;
      grpc::ClientContext ctx;
      Deadline(&ctx, a->timeout_s);
      grpc::Status s = Stub(a->coordinator)->Act(&ctx, req, &resp);
      if (!s.ok()) Fail("act", s);
      if (a->json) std::printf("%s\n", Json(resp.session()).c_str());
      else PrintSession(resp.session());
    });
  }

  {
    auto* cmd = session->add_subcommand(
        "watch", "Stream a session's events (or every session's, without ID); Ctrl-C to stop");
    struct Args : Common {
      std::string id;
      int count = 0;
      double duration_s = 0;
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("id", a->id, "session id (empty = every session)");
    cmd->add_option("-n,--count", a->count, "stop after N events (0 = never)");
    cmd->add_option("--duration-s", a->duration_s, "stop after this long (0 = never)");
    add_common(cmd, a.get());
    cmd->callback([a] {
      v1::WatchSessionRequest req;
      req.set_session_id(a->id);
      grpc::ClientContext ctx;
      if (a->duration_s > 0) Deadline(&ctx, a->duration_s);
      auto reader = Stub(a->coordinator)->WatchSession(&ctx, req);
      v1::SessionEvent e;
      int n = 0;
      while (reader->Read(&e)) {
        if (a->json) std::printf("%s\n", Json(e).c_str());
        else PrintEvent(e);
        std::fflush(stdout);
        if (a->count > 0 && ++n >= a->count) {
          ctx.TryCancel();
          break;
        }
      }
      grpc::Status s = reader->Finish();
      if (!s.ok() && s.error_code() != grpc::StatusCode::CANCELLED &&
          !(a->duration_s > 0 && s.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED)) {
        Fail("watch", s);
      }
    });
  }

  {
    auto* cmd = session->add_subcommand("get", "One session's state");
    struct Args : Common {
      std::string id;
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("id", a->id, "session id")->required();
    add_common(cmd, a.get());
    cmd->callback([a] {
      v1::GetSessionRequest req;
      req.set_session_id(a->id);
      v1::Session resp;
      grpc::ClientContext ctx;
      Deadline(&ctx, a->timeout_s);
      grpc::Status s = Stub(a->coordinator)->GetSession(&ctx, req, &resp);
      if (!s.ok()) Fail("get", s);
      if (a->json) std::printf("%s\n", Json(resp).c_str());
      else PrintSession(resp);
    });
  }

  {
    auto* cmd = session->add_subcommand("list", "Every open session (or those of --robot)");
    struct Args : Common {
      std::string robot;
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("--robot", a->robot, "only sessions of this robot");
    add_common(cmd, a.get());
    cmd->callback([a] {
      v1::ListSessionsRequest req;
      req.set_robot_id(a->robot);
      v1::ListSessionsResponse resp;
      grpc::ClientContext ctx;
      Deadline(&ctx, a->timeout_s);
      grpc::Status s = Stub(a->coordinator)->ListSessions(&ctx, req, &resp);
      if (!s.ok()) Fail("list", s);
      if (a->json) {
        std::printf("%s\n", Json(resp).c_str());
        return;
      }
      for (const auto& x : resp.sessions()) PrintSession(x);
    });
  }

  {
    auto* cmd = session->add_subcommand("close", "Close a session");
    struct Args : Common {
      std::string id;
      bool reset = false;
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("id", a->id, "session id")->required();
    cmd->add_flag("--reset-robot", a->reset, "set the robot back to neutral");
    add_common(cmd, a.get());
    cmd->callback([a] {
      v1::CloseSessionRequest req;
      req.set_session_id(a->id);
      req.set_reset_robot(a->reset);
      v1::CloseSessionResponse resp;
      grpc::ClientContext ctx;
      Deadline(&ctx, a->timeout_s);
      grpc::Status s = Stub(a->coordinator)->CloseSession(&ctx, req, &resp);
      if (!s.ok()) Fail("close", s);
      if (a->json) std::printf("%s\n", Json(resp.session()).c_str());
      else PrintSession(resp.session());
    });
  }
}

}  // namespace kinemo::cli
