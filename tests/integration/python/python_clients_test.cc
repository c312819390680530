// Clients in another language against the real binaries: proto/ is compiled
// to Python at test time and Debian's python3-grpcio calls every service.
//  - malformed.py sends malformed bytes raw (invalid UTF-8 in a string field,
//    a body that is no message, an undefined enum number, a NaN) to every
//    unary and server-streaming RPC of every service: directly, through the
//    coordinator (which forwards the bytes: the callee answers) and to the
//    all-in-one; each must answer INVALID_ARGUMENT naming the field.
//  - clients.py makes one real call per service: prosody Analyze on real
//    speech, inference PushArtifact + Infer, planner Visemes, cube_tracker
//    Track on a rendered frame, robot_bridge SetEmotion against pleo_sim,
//    coordinator OpenSession + Act.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "common/image/png.h"
#include "common/testing/process.h"
#include "common/testing/python.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "kinemo/cube_tracker/v1/cube_tracker.grpc.pb.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "kinemo/prosody/v1/prosody.grpc.pb.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"
#include "services/cube_tracker/core/camera.h"
#include "services/cube_tracker/core/cube_model.h"
#include "services/cube_tracker/render/renderer.h"
#include "tests/integration/stores/stores_fixture.h"

namespace kinemo {
namespace {

using namespace std::chrono_literals;
using stores_test::Binary;
using testing::ChildProcess;
using testing::ServiceProcess;

const std::string kSource = KINEMO_SOURCE_DIR;
const std::string kData = KINEMO_TEST_DATA_DIR;
const std::string kScripts = kSource + "/tests/integration/python";

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// Every service as its own process, a coordinator in front of them, and an
// all-in-one beside them, started once for the suite.
class PythonClients : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { stack_ = new Stack(); stack_->Start(); }
  static void TearDownTestSuite() {
    delete stack_;
    stack_ = nullptr;
  }

  struct Stack {
    testing::TempDir dir;
    std::string skip;  // why the suite cannot run here, or ""
    std::string error;  // a start-up failure
    std::unique_ptr<ChildProcess> sim;
    int sim_port = 0;
    std::unique_ptr<ServiceProcess> prosody, inference, planner, cube_tracker, robot_bridge, coordinator, allinone;
    static constexpr int kFrames = 5;
    std::string frames;  // the rendered frames (PNG files, comma-separated)
    int top_face = -1;   // their top face (CubeFace number)

    std::string File(const std::string& name) const { return dir.File(name); }

    void Start() {
      if (Status s = testing::PythonGrpcAvailable(dir.path()); !s.ok()) {
        skip = std::string(s.message());
        return;
      }
      if (Status s = testing::CompileProtosForPython(kSource + "/proto", File("gen")); !s.ok()) {
        error = std::string(s.message());
        return;
      }
      error = StartAll();
    }

    std::string StartAll() {
      auto s = ChildProcess::Spawn({Binary("pleo_sim"), "--tcp", "127.0.0.1:0", "--port-file", File("sim.port"),
                                    "--switch-ms", "100"},
                                   File("sim.log"));
      if (!s.ok()) return std::string(s.status().message());
      sim = std::move(*s);
      sim_port = testing::WaitForPortFile(File("sim.port"), sim.get());
      if (sim_port <= 0) return "pleo_sim did not start: " + sim->ReadLog();
      const std::string robots = "robots { robot_id: \"pleo\" tcp { host: \"127.0.0.1\" port: " +
                                 std::to_string(sim_port) + " } timing { poll_s: 0.05 max_backoff_s: 0.2 } }\n";

      // A real frame of the cube on a table, and the camera it was seen with.
      auto model = cube::LoadCubeModel(kData + "/cube/vleo.cube");
      if (!model.ok()) return std::string(model.status().message());
      auto script = cube::LoadRenderScript(kData + "/cube/lift_rotate_place.json");
      if (!script.ok()) return std::string(script.status().message());
      auto renderer = cube::SequenceRenderer::Create(*model, *script);
      if (!renderer.ok()) return std::string(renderer.status().message());
      for (int i = 0; i < kFrames; ++i) {
        cv::Mat frame;
        cube::TruthFrame truth;
        if (Status st = renderer->Next(&frame, &truth); !st.ok()) return std::string(st.message());
        top_face = cube::FaceToProto(truth.top_face);
        image::PixelBuffer pixels{.data = frame.data, .width = frame.cols, .height = frame.rows, .channels = 3,
                                  .stride = frame.step[0], .bgr = true};
        const std::string path = File("frame" + std::to_string(i) + ".png");
        if (Status st = image::WritePngFile(path, pixels); !st.ok()) return std::string(st.message());
        frames += (i > 0 ? "," : "") + path;
      }
      if (Status st = cube::SaveCameraModel(renderer->camera(), File("camera.yaml")); !st.ok()) {
        return std::string(st.message());
      }
      std::filesystem::create_directories(File("library"));

      // A small model for inference, pushed from Python.
      auto corpus = stores_test::TinyCorpus(File("corpus"));
      if (!corpus.ok()) return std::string(corpus.status().message());
      if (Status st = stores_test::WriteTinyModel(*corpus, File("tiny.kmodel"), "tiny"); !st.ok()) {
        return std::string(st.message());
      }

      auto start = [&](const std::string& name, const std::string& config, const std::string& health,
                       std::unique_ptr<ServiceProcess>* out) -> std::string {
        std::ofstream(File(name + ".textproto")) << "server { shutdown_grace_s: 0.5 }\n" << config;
        auto p = ServiceProcess::Start(
            {.binary = Binary(name), .args = {"--config", File(name + ".textproto")}, .health_service = health});
        if (!p.ok()) return name + ": " + std::string(p.status().message());
        *out = std::move(*p);
        return "";
      };
      const std::string cube_options = "cubes {\n" + ReadFile(kData + "/cube/vleo.cube") + "}\n" +
                                       "default_intrinsics_file: \"" + File("camera.yaml") + "\"\n";
      std::string e;
      if (!(e = start("prosody", "recognizer { disabled: true }\n", prosody::v1::ProsodyService::service_full_name(),
                      &prosody))
               .empty() ||
          !(e = start("inference", "store_dir: \"" + File("inference_store") + "\"\n",
                      inference::v1::InferenceService::service_full_name(), &inference))
               .empty() ||
          !(e = start("planner",
                      "store_dir: \"" + File("planner_store") + "\"\nlibrary_root: \"" + File("library") + "\"\n",
                      planner::v1::PlannerService::service_full_name(), &planner))
               .empty() ||
          !(e = start("cube_tracker", cube_options + "store_dir: \"" + File("cube_store") + "\"\n",
                      cube_tracker::v1::CubeTrackerService::service_full_name(), &cube_tracker))
               .empty() ||
          !(e = start("robot_bridge", robots, robot_bridge::v1::RobotBridgeService::service_full_name(),
                      &robot_bridge))
               .empty()) {
        return e;
      }
      const std::string services = "services {\n  prosody { address: \"" + prosody->address() +
                                   "\" }\n  inference { address: \"" + inference->address() +
                                   "\" }\n  planner { address: \"" + planner->address() +
                                   "\" }\n  cube_tracker { address: \"" + cube_tracker->address() +
                                   "\" }\n  robot_bridge { address: \"" + robot_bridge->address() +
                                   "\" max_reconnect_backoff_s: 0.2 }\n}\n";
      if (!(e = start("coordinator", services, coordinator::v1::CoordinatorService::service_full_name(),
                      &coordinator))
               .empty()) {
        return e;
      }
      const std::string allinone_config = "store_dir: \"" + File("allinone_store") + "\"\n" +
                                          "prosody { recognizer { disabled: true } }\n" +
                                          "cube_tracker { " + cube_options + "}\n" + "robot_bridge { " + robots +
                                          "}\n";
      return start("kinemo_allinone", allinone_config, coordinator::v1::CoordinatorService::service_full_name(),
                   &allinone);
    }
  };

  void SetUp() override {
    if (!stack_->skip.empty()) GTEST_SKIP() << stack_->skip;
    ASSERT_TRUE(stack_->error.empty()) << stack_->error;
  }

  // Runs a script of this directory; its JSON summary line.
  static nlohmann::json Run(const std::string& script, std::vector<std::string> args, int* exit_code) {
    args.insert(args.begin(), {"--gen", stack_->File("gen")});
    std::string log;
    auto code = testing::RunPython(kScripts + "/" + script, args, stack_->File(script + ".log"), &log);
    *exit_code = code.ok() ? *code : -1;
    auto json = nlohmann::json::parse(testing::LastJsonLine(log), nullptr, false);
    if (json.is_discarded()) json = nlohmann::json{{"log", log}};
    return json;
  }

  static Stack* stack_;
};

PythonClients::Stack* PythonClients::stack_ = nullptr;

TEST_F(PythonClients, MalformedBytesGetInvalidArgumentNamingTheFieldOnEveryRpc) {
  const std::string inner = "kinemo.prosody.v1.ProsodyService,kinemo.inference.v1.InferenceService,"
                            "kinemo.planner.v1.PlannerService,kinemo.cube_tracker.v1.CubeTrackerService";
  const std::string all = inner + ",kinemo.robot_bridge.v1.RobotBridgeService,kinemo.coordinator.v1.CoordinatorService";
  int code = -1;
  const nlohmann::json result = Run(
      "malformed.py",
      {"--target", "prosody", stack_->prosody->address(), "kinemo.prosody.v1.ProsodyService",
       "--target", "inference", stack_->inference->address(), "kinemo.inference.v1.InferenceService",
       "--target", "planner", stack_->planner->address(), "kinemo.planner.v1.PlannerService",
       "--target", "cube_tracker", stack_->cube_tracker->address(), "kinemo.cube_tracker.v1.CubeTrackerService",
       "--target", "robot_bridge", stack_->robot_bridge->address(), "kinemo.robot_bridge.v1.RobotBridgeService",
       // The coordinator's own RPCs and, forwarded byte for byte, the inner services'.
       "--target", "coordinator", stack_->coordinator->address(), inner + ",kinemo.coordinator.v1.CoordinatorService",
       "--target", "allinone", stack_->allinone->address(), all},
      &code);
  EXPECT_EQ(code, 0) << result.dump(1);
  std::printf("[malformed.py] calls per target: %s\n", result.value("calls", nlohmann::json()).dump().c_str());
  ASSERT_TRUE(result.contains("failures")) << result.dump(1);
  EXPECT_TRUE(result["failures"].empty()) << result["failures"].dump(1);
  // Every target was called (a few cases per RPC).
  for (const char* target : {"prosody", "inference", "planner", "cube_tracker", "robot_bridge", "coordinator",
                             "allinone"}) {
    EXPECT_GE(result["calls"].value(target, 0), 3) << target;
  }
  // The services are still healthy after all of it.
  for (ServiceProcess* p : {stack_->prosody.get(), stack_->coordinator.get(), stack_->allinone.get()}) {
    EXPECT_TRUE(p->process().Running());
    EXPECT_TRUE(testing::WaitForServing(p->Channel(), "", 10s).ok());
  }
}

TEST_F(PythonClients, EachServiceAnswersARealCall) {
  int code = -1;
  const nlohmann::json result =
      Run("clients.py",
          {"--prosody", stack_->prosody->address(), "--inference", stack_->inference->address(), "--planner",
           stack_->planner->address(), "--cube-tracker", stack_->cube_tracker->address(), "--robot-bridge",
           stack_->robot_bridge->address(), "--coordinator", stack_->coordinator->address(), "--speech",
           kData + "/speech/sense_and_sensibility_01_austen_64kb-0880.wav", "--model", stack_->File("tiny.kmodel"),
           "--frames", stack_->frames, "--top-face", std::to_string(stack_->top_face),
           // No message may show where the server keeps its files.
           "--hide", stack_->dir.path()},
          &code);
  EXPECT_EQ(code, 0) << result.dump(1);
  std::printf("[clients.py] %s\n", result.dump().c_str());
  ASSERT_TRUE(result.contains("checks")) << result.dump(1);
  for (const char* check : {"prosody_syllables", "inference_beliefs", "planner_visemes", "planner_missing_path",
                            "cube_top_face", "robot_happy", "coordinator_session"}) {
    EXPECT_TRUE(result["checks"].value(check, false)) << check << ": " << result.dump(1);
  }
}

}  // namespace
}  // namespace kinemo
