// The `kinemo session`, `kinemo demo vleo` and `kinemo animate --stream`
// commands against real processes (pleo_sim, robot_bridge, coordinator; the
// demo starts its own; the stream runs over prosody, inference and planner
// processes with a model `kinemo crf train` made and a controller
// `kinemo controller build --server` had the planner build).
#include <signal.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <thread>

#include "common/testing/process.h"
#include "gtest/gtest.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"
#include "nlohmann/json.hpp"
#include "tests/integration/coordinator/vleo_stack.h"

namespace kinemo::coordinator {
namespace {

using kinemo::testing::ChildProcess;
using kinemo::testing::ServiceProcess;
using namespace std::chrono_literals;
namespace v1 = ::kinemo::coordinator::v1;
using vleo_test::WaitForPortFile;

const std::string kBin = KINEMO_BINARY_DIR;
const std::string kKinemo = kBin + "/services/cli/kinemo";
const std::string kSource = KINEMO_SOURCE_DIR;

// Runs a command; returns its exit code and stdout.
int RunShell(const std::string& command, std::string* out) {
  FILE* p = ::popen(command.c_str(), "r");
  if (p == nullptr) return -1;
  std::array<char, 4096> buf;
  out->clear();
  std::size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) out->append(buf.data(), n);
  const int st = ::pclose(p);
  return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

TEST(CoordinatorCli, SessionOpenActWatchListClose) {
  kinemo::testing::TempDir dir;
  auto sim = ChildProcess::Spawn({kBin + "/services/pleo_sim/pleo_sim", "--tcp", "127.0.0.1:0",
                                  "--port-file", dir.File("sim.port"), "--switch-ms", "100"},
                                 dir.File("sim.log"));
  ASSERT_TRUE(sim.ok());
  const int sim_port = WaitForPortFile(dir.File("sim.port"), sim->get());
  ASSERT_GT(sim_port, 0);
  std::ofstream(dir.File("rb.textproto"))
      << "robots { robot_id: \"pleo\" tcp { host: \"127.0.0.1\" port: " << sim_port << " } }\n";
  auto bridge = ServiceProcess::Start({.binary = kBin + "/services/robot_bridge/robot_bridge",
                                       .args = {"--config", dir.File("rb.textproto")}});
  ASSERT_TRUE(bridge.ok()) << bridge.status();
  std::ofstream(dir.File("co.textproto"))
      << "services { robot_bridge { address: \"" << (*bridge)->address() << "\" } }\n"
      << "emotion { rate_per_s: 0.5 }\n";  // neutral after 1.4 s, happy after 3 s
  auto coordinator = ServiceProcess::Start({.binary = kBin + "/services/coordinator/coordinator",
                                            .args = {"--config", dir.File("co.textproto")}});
  ASSERT_TRUE(coordinator.ok()) << coordinator.status();
  const std::string c = " --coordinator " + (*coordinator)->address();
  std::string out;
  ASSERT_EQ(RunShell(kKinemo + " session open pleo --id vleo --initial angry --json" + c, &out), 0);
  auto opened = nlohmann::json::parse(out);
  EXPECT_EQ(opened["session_id"], "vleo");
  EXPECT_EQ(opened["emotion"], "EMOTION_ANGRY");
  ASSERT_EQ(RunShell(kKinemo + " session act vleo kisses -i 1 --json" + c, &out), 0);
  EXPECT_EQ(nlohmann::json::parse(out)["action"], "ACTION_KISSES");
  // Watch until the robot was commanded happy (snapshot + changes).
  ASSERT_EQ(RunShell(kKinemo + " session watch vleo --json --duration-s 10" + c + " | grep -m1 -B100 "
                "'\"robot_commanded\":{\"emotion\":\"EMOTION_HAPPY\"'",
                &out),
            0)
      << out;
  std::istringstream lines(out);
  std::string line;
  std::vector<std::string> emotions;
  while (std::getline(lines, line)) {
    auto j = nlohmann::json::parse(line);
    if (j.contains("emotion_changed")) emotions.push_back(j["emotion_changed"]["to_emotion"]);
  }
  EXPECT_EQ(emotions, (std::vector<std::string>{"EMOTION_NEUTRAL", "EMOTION_HAPPY"}));
  ASSERT_EQ(RunShell(kKinemo + " session list --json" + c, &out), 0);
  EXPECT_EQ(nlohmann::json::parse(out)["sessions"].size(), 1u);
  // One session's state: the session the watch saw turn happy.
  ASSERT_EQ(RunShell(kKinemo + " session get vleo --json" + c, &out), 0);
  auto got = nlohmann::json::parse(out);
  EXPECT_EQ(got["session_id"], "vleo") << out;
  EXPECT_EQ(got["emotion"], "EMOTION_HAPPY") << out;
  ASSERT_EQ(RunShell(kKinemo + " session close vleo --json" + c, &out), 0);
  EXPECT_EQ(nlohmann::json::parse(out)["emotion"], "EMOTION_HAPPY");
  EXPECT_EQ(RunShell(kKinemo + " session act vleo kisses" + c + " 2>/dev/null", &out), 1);
  EXPECT_EQ(RunShell(kKinemo + " session act vleo dance" + c + " 2>/dev/null", &out), 2);
}

TEST(CoordinatorCli, DemoVleoPrintsPleosStateChangesAndPleoSimFollows) {
  kinemo::testing::TempDir dir;
  std::string out;
  const int rc = RunShell("cd " + kSource + " && " + kKinemo + " demo vleo --json --out " + dir.path() +
                         " 2>" + dir.File("demo.err"),
                     &out);
  std::ifstream err(dir.File("demo.err"));
  std::stringstream es;
  es << err.rdbuf();
  ASSERT_EQ(rc, 0) << es.str();  // 0: pleo_sim ends in the model's emotion
  std::istringstream lines(out);
  std::string line;
  std::vector<std::string> seq;
  double last_t = 0;
  while (std::getline(lines, line)) {
    auto j = nlohmann::json::parse(line);
    ASSERT_TRUE(j.contains("time_s") && j.contains("action") && j.contains("intensity"));
    EXPECT_GE(j["time_s"].get<double>(), last_t);
    last_t = j["time_s"];
    seq.push_back(j["action"].get<std::string>() + ":" + j["emotion"].get<std::string>());
  }
  // The scripted cube: kisses (turned up to full intensity), then shouting.
  EXPECT_EQ(seq, (std::vector<std::string>{"kisses:neutral", "kisses:happy", "shouting:neutral",
                                           "shouting:angry"}));
}


// The cube scenario with real processes (pleo_sim, robot_bridge, cube_tracker,
// coordinator); the cube tracker is killed mid-video and restarted on its
// port: the coordinator resumes the video where it stopped and Pleo still
// ends angry.
TEST(CoordinatorCli, CubeScenarioSurvivesACubeTrackerRestart) {
  kinemo::testing::TempDir dir;
  std::string out;
  ASSERT_EQ(RunShell(kKinemo + " cube render --model " + kSource + "/tests/data/cube/vleo.cube" +
                         " --script " + kSource + "/tests/data/cube/vleo_scenario.json --out " +
                         dir.File("v.avi") + " --camera " + dir.File("cam.yml") + " 2>&1",
                     &out),
            0)
      << out;
  auto sim = ChildProcess::Spawn({kBin + "/services/pleo_sim/pleo_sim", "--tcp", "127.0.0.1:0",
                                  "--port-file", dir.File("sim.port"), "--switch-ms", "100"},
                                 dir.File("sim.log"));
  ASSERT_TRUE(sim.ok());
  const int sim_port = WaitForPortFile(dir.File("sim.port"), sim->get());
  ASSERT_GT(sim_port, 0);
  std::ofstream(dir.File("rb.textproto"))
      << "robots { robot_id: \"pleo\" tcp { host: \"127.0.0.1\" port: " << sim_port << " } }\n";
  auto bridge = ServiceProcess::Start({.binary = kBin + "/services/robot_bridge/robot_bridge",
                                       .args = {"--config", dir.File("rb.textproto")}});
  ASSERT_TRUE(bridge.ok()) << bridge.status();
  {
    std::ifstream cube(kSource + "/tests/data/cube/vleo.cube");
    std::stringstream cs;
    cs << cube.rdbuf();
    std::ofstream(dir.File("ct.textproto")) << "server { shutdown_grace_s: 0.2 }\ncubes {\n"
                                            << cs.str() << "}\nfile_root: \"" << dir.path()
                                            << "\"\n";
  }
  int tracker_port = 0;
  std::unique_ptr<ChildProcess> tracker;
  auto start_tracker = [&] {
    std::remove(dir.File("ct.port").c_str());
    auto t = ChildProcess::Spawn({kBin + "/services/cube_tracker/cube_tracker", "--config",
                                  dir.File("ct.textproto"), "--host", "127.0.0.1", "--port",
                                  std::to_string(tracker_port), "--port-file", dir.File("ct.port")},
                                 dir.File("ct.log"));
    ASSERT_TRUE(t.ok());
    tracker = std::move(*t);
    tracker_port = WaitForPortFile(dir.File("ct.port"), tracker.get());
    ASSERT_GT(tracker_port, 0) << tracker->ReadLog();
  };
  ASSERT_NO_FATAL_FAILURE(start_tracker());
  std::ofstream(dir.File("co.textproto"))
      << "services {\n  robot_bridge { address: \"" << (*bridge)->address() << "\" }\n"
      << "  cube_tracker { address: \"127.0.0.1:" << tracker_port
      << "\" max_reconnect_backoff_s: 0.2 }\n}\nemotion { rate_per_s: 0.4 }\n";
  auto coordinator = ServiceProcess::Start({.binary = kBin + "/services/coordinator/coordinator",
                                            .args = {"--config", dir.File("co.textproto")}});
  ASSERT_TRUE(coordinator.ok()) << coordinator.status();
  auto stub = v1::CoordinatorService::NewStub((*coordinator)->Channel());
  {
    v1::OpenSessionRequest open;
    open.set_session_id("cube");
    open.set_robot_id("pleo");
    open.set_vleo(v1::VLEO_KIND_CUBE);
    open.set_initial_emotion(common::v1::EMOTION_ANGRY);
    v1::OpenSessionResponse r;
    grpc::ClientContext ctx;
    ASSERT_TRUE(stub->OpenSession(&ctx, open, &r).ok());
  }
  grpc::ClientContext watch;
  watch.set_deadline(std::chrono::system_clock::now() + 90s);
  v1::WatchSessionRequest w;
  w.set_session_id("cube");
  auto reader = stub->WatchSession(&watch, w);
  {
    v1::AttachCubeRequest a;
    a.set_session_id("cube");
    a.mutable_source()->set_video_file(dir.File("v.avi"));
    a.mutable_source()->set_realtime(true);
    a.mutable_config()->set_cube_id("vleo");
    a.mutable_config()->set_intrinsics_file(dir.File("cam.yml"));
    v1::AttachCubeResponse r;
    grpc::ClientContext ctx;
    grpc::Status s = stub->AttachCube(&ctx, a, &r);
    ASSERT_TRUE(s.ok()) << s.error_message();
  }
  // Kill the tracker while the cube throws kisses at full intensity.
  v1::SessionEvent e;
  bool full = false;
  while (!full && reader->Read(&e)) {
    full = e.has_action_changed() && e.action_changed().intensity() > 0.95;
  }
  ASSERT_TRUE(full);
  ASSERT_TRUE(tracker->Stop(SIGKILL, 5s).ok());
  std::this_thread::sleep_for(500ms);  // an outage the coordinator has to ride out
  ASSERT_NO_FATAL_FAILURE(start_tracker());
  std::vector<std::string> emotions;
  while (reader->Read(&e)) {
    if (e.has_emotion_changed()) {
      emotions.push_back(common::v1::Emotion_Name(e.emotion_changed().to_emotion()));
    }
    if (e.has_cube_status_changed() && !e.cube_status_changed().attached()) break;
  }
  watch.TryCancel();
  (void)reader->Finish();
  EXPECT_EQ(emotions.back(), "EMOTION_ANGRY") << ::testing::PrintToString(emotions);
  EXPECT_TRUE(std::find(emotions.begin(), emotions.end(), "EMOTION_HAPPY") != emotions.end());
  // pleo_sim, read through the bridge, shows it.
  auto bstub = kinemo::robot_bridge::v1::RobotBridgeService::NewStub((*bridge)->Channel());
  bool shown = false;
  for (int i = 0; i < 100 && !shown; ++i) {
    kinemo::robot_bridge::v1::GetStatusRequest g;
    g.set_robot_id("pleo");
    kinemo::robot_bridge::v1::RobotStatus st;
    grpc::ClientContext ctx;
    shown = bstub->GetStatus(&ctx, g, &st).ok() && st.shown_emotion() == common::v1::EMOTION_ANGRY;
    if (!shown) std::this_thread::sleep_for(50ms);
  }
  EXPECT_TRUE(shown);
}


TEST(CoordinatorCli, AnimateStreamWritesTheBvhOfTheWholeRecordingAndTheLagFigures) {
  kinemo::testing::TempDir dir;
  const std::string data = kSource + "/tests/data";
  const std::string speech = data + "/speech/sense_and_sensibility_01_austen_64kb-";
  std::string out;
  // A model from `kinemo crf train` (synthetic pairing of tests/data speech
  // and gesture clips), pushed to the inference service; a controller the
  // planner builds from it over its library.
  ASSERT_EQ(RunShell(kKinemo + " crf corpus --out " + dir.File("corpus") + " --data-root " + data + " --speech " +
                         speech + "0880.wav " + speech + "0930.wav --gestures " + data +
                         "/planner_controller/dataset-1_bow_normal_001.bvh " + data +
                         "/planner_controller/dataset-1_guide_normal_001.bvh --renditions 2",
                     &out),
            0);
  ASSERT_EQ(RunShell(kKinemo + " crf train --corpus " + dir.File("corpus") +
                         " --states 4 --window 2 --clusters 3 --restarts 2 --out " + dir.File("live.kmodel"),
                     &out),
            0);
  std::ofstream(dir.File("inference.textproto")) << "store_dir: \"" << dir.File("inference-store") << "\"\n";
  std::ofstream(dir.File("planner.textproto"))
      << "library_root: \"" << data << "/planner_controller\"\n"
      << "preload { library_id: \"gestures\" paths: \"manifest.json\" }\n";
  auto prosody = ServiceProcess::Start({.binary = kBin + "/services/prosody/prosody"});
  auto inference = ServiceProcess::Start(
      {.binary = kBin + "/services/inference/inference", .args = {"--config", dir.File("inference.textproto")}});
  auto planner = ServiceProcess::Start(
      {.binary = kBin + "/services/planner/planner", .args = {"--config", dir.File("planner.textproto")}});
  ASSERT_TRUE(prosody.ok() && inference.ok() && planner.ok());
  ASSERT_EQ(RunShell(kKinemo + " model push " + dir.File("live.kmodel") + " --id live --server " +
                         (*inference)->address() + " 2>/dev/null",
                     &out),
            0);
  ASSERT_EQ(RunShell(kKinemo + " controller build --server " + (*planner)->address() + " --inference-server " +
                         (*inference)->address() + " --library-id gestures --model-id live --id live 2>/dev/null",
                     &out),
            0);
  std::ofstream(dir.File("co.textproto"))
      << "services {\n  prosody { address: \"" << (*prosody)->address() << "\" }\n  inference { address: \""
      << (*inference)->address() << "\" }\n  planner { address: \"" << (*planner)->address() << "\" }\n}\n";
  auto coordinator = ServiceProcess::Start(
      {.binary = kBin + "/services/coordinator/coordinator", .args = {"--config", dir.File("co.textproto")}});
  ASSERT_TRUE(coordinator.ok()) << coordinator.status();

  const std::string wav = speech + "0870.wav";
  const int rc = RunShell(kKinemo + " animate " + wav + " --stream --realtime --json -o " + dir.File("out.bvh") +
                              " --model-id live --controller-id live --coordinator " + (*coordinator)->address() + " 2>" +
                              dir.File("animate.err"),
                          &out);
  std::ifstream err(dir.File("animate.err"));
  std::stringstream es;
  es << err.rdbuf();
  ASSERT_EQ(rc, 0) << es.str();
  const auto j = nlohmann::json::parse(out);
  for (const char* k : {"motion_lag_p50_ms", "motion_lag_p99_ms", "first_frame_ms", "max_frame_gap_ms"}) {
    ASSERT_TRUE(j.contains(k)) << out;
    EXPECT_GE(j[k].get<double>(), 0.0) << k;
  }
  EXPECT_GE(j["motion_lag_p99_ms"].get<double>(), j["motion_lag_p50_ms"].get<double>());
  EXPECT_NEAR(j["audio_s"].get<double>(), 7.1, 0.01);
  // The BVH covers the whole recording: one frame per 1/30 s of audio.
  ASSERT_EQ(RunShell(kKinemo + " bvh info " + dir.File("out.bvh") + " --json", &out), 0);
  const auto info = nlohmann::json::parse(out);
  const int frames = info["num_frames"];
  EXPECT_EQ(frames, j["frames"].get<int>());
  EXPECT_EQ(frames, static_cast<int>(std::ceil(j["audio_s"].get<double>() / info["frame_time_s"].get<double>() - 1e-3)));
  EXPECT_EQ(info["num_joints"], 22);
  // Animate without --stream names the flags that do not apply.
  EXPECT_EQ(RunShell(kKinemo + " animate " + wav + " --realtime -o " + dir.File("x.bvh") + " 2>/dev/null", &out), 2);
}

}  // namespace
}  // namespace kinemo::coordinator
