// Mutual TLS between real processes, with the material deploy/certs.sh makes
// (a CA, a certificate per service and one for the CLI; an expired client
// certificate and one from another CA): every server requires a client
// certificate from the CA, the coordinator presents its own to the robot
// bridge, the cube tracker, prosody and the planner, and the kinemo tools
// present theirs (--ca/--cert/--key or KINEMO_TLS_*).
//   - the Vleo scenario: a rendered cube video, played through the cube
//     tracker into a cube session, moves Pleo (pleo_sim, through the bridge);
//   - Animate: speech -> prosody -> planner (BodySpeech) -> BVH, from `kinemo animate`;
//   - strangers (no certificate, another CA's, an expired one, plaintext) are
//     refused with UNAVAILABLE during the handshake, by the servers and by
//     the coordinator's own channels, and the services stay healthy;
//   - server reflection v1 answers over mutual TLS.
#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <fstream>
#include <sstream>
#include <thread>

#include "common/grpc/tls_credentials.h"
#include "common/testing/process.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "grpc/reflection/v1/reflection.grpc.pb.h"
#include "gtest/gtest.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "kinemo/prosody/v1/prosody.grpc.pb.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"

namespace kinemo {
namespace {

using kinemo::testing::ChildProcess;
using kinemo::testing::ServiceProcess;
using namespace std::chrono_literals;
namespace v1 = ::kinemo::coordinator::v1;
namespace rb = ::kinemo::robot_bridge::v1;
using grpc::health::v1::Health;
using grpc::health::v1::HealthCheckRequest;
using grpc::health::v1::HealthCheckResponse;

const std::string kBin = KINEMO_BINARY_DIR;
const std::string kSource = KINEMO_SOURCE_DIR;
const std::string kKinemo = kBin + "/services/cli/kinemo";
const std::string kHealth = kBin + "/services/cli/kinemo-health";

// Runs a shell command to its end (at most 2 minutes); returns its exit code,
// with its output (stdout and stderr) in *out.
int RunShell(const std::string& command, std::string* out) {
  kinemo::testing::TempDir dir;
  auto code = ChildProcess::Run({"/bin/sh", "-c", command}, dir.File("log"), 120s, out);
  return code.ok() ? *code : -1;
}

std::string Slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

class MutualTls : public ::testing::Test {
 protected:
  // One set of material for the suite, made by the deployment's own script.
  static void SetUpTestSuite() {
    certs_ = new kinemo::testing::TempDir();
    std::string out;
    const int rc = RunShell(
        "bash " + kSource + "/deploy/certs.sh --test-extras " + certs_->path() + " 2>&1", &out);
    ASSERT_EQ(rc, 0) << out;
  }
  static void TearDownTestSuite() {
    delete certs_;
    certs_ = nullptr;
  }
  static std::string Cert(const std::string& file) { return certs_->File(file); }

  // What `name` presents as a client, trusting kinemo's CA.
  static ClientTlsFiles As(const std::string& name, const std::string& ca = "ca") {
    ClientTlsFiles f;
    f.ca_file = Cert(ca + ".pem");
    if (!name.empty()) {
      f.cert_file = Cert(name + ".pem");
      f.key_file = Cert(name + ".key");
    }
    return f;
  }
  // The kinemo tools' flags for the same.
  static std::string Flags(const std::string& name) {
    return " --ca " + Cert("ca.pem") + " --cert " + Cert(name + ".pem") + " --key " +
           Cert(name + ".key");
  }
  // A server's options: its certificate, and client certificates required.
  static std::string ServerTls(const std::string& name) {
    return "server { shutdown_grace_s: 0.2 tls { cert_file: \"" + Cert(name + ".pem") +
           "\" key_file: \"" + Cert(name + ".key") + "\" client_ca_file: \"" + Cert("ca.pem") +
           "\" } }\n";
  }
  // A coordinator endpoint's TLS fields, presenting the coordinator's certificate.
  static std::string EndpointTls() {
    return " ca_file: \"" + Cert("ca.pem") + "\" cert_file: \"" + Cert("coordinator.pem") +
           "\" key_file: \"" + Cert("coordinator.key") + "\" ";
  }
  static std::shared_ptr<grpc::Channel> Channel(const std::string& address,
                                                const ClientTlsFiles& files) {
    auto credentials = MakeChannelCredentials(files);
    EXPECT_TRUE(credentials.ok()) << credentials.status();
    return grpc::CreateChannel(address, *credentials);
  }
  // A service binary with mutual TLS, ready (health over mutual TLS, as the CLI).
  std::unique_ptr<ServiceProcess> Start(const std::string& service, const std::string& options,
                                        const std::string& health_service = "") {
    const std::string config = dir_.File(service + ".textproto");
    std::ofstream(config) << ServerTls(service) << options;
    auto p = ServiceProcess::Start({.binary = kBin + "/services/" + service + "/" + service,
                                    .args = {"--config", config},
                                    .health_service = health_service,
                                    .tls = As("cli")});
    EXPECT_TRUE(p.ok()) << p.status();
    return p.ok() ? std::move(*p) : nullptr;
  }
  std::unique_ptr<ChildProcess> StartPleoSim(int* port) {
    auto sim = ChildProcess::Spawn({kBin + "/services/pleo_sim/pleo_sim", "--tcp", "127.0.0.1:0",
                                    "--port-file", dir_.File("sim.port"), "--switch-ms", "100"},
                                   dir_.File("sim.log"));
    EXPECT_TRUE(sim.ok());
    if (!sim.ok()) return nullptr;
    const auto until = std::chrono::steady_clock::now() + 20s;
    while (std::chrono::steady_clock::now() < until && (*sim)->Running()) {
      std::ifstream in(dir_.File("sim.port"));
      if (in >> *port && *port > 0) return std::move(*sim);
      std::this_thread::sleep_for(20ms);
    }
    ADD_FAILURE() << "pleo_sim wrote no port: " << (*sim)->ReadLog();
    return nullptr;
  }

  static kinemo::testing::TempDir* certs_;
  kinemo::testing::TempDir dir_;
};

kinemo::testing::TempDir* MutualTls::certs_ = nullptr;

grpc::Status CheckHealth(const std::shared_ptr<grpc::Channel>& channel,
                         HealthCheckResponse* response) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 5s);
  return Health::NewStub(channel)->Check(&ctx, HealthCheckRequest(), response);
}

// Services listed by grpc.reflection.v1 (empty on failure).
std::vector<std::string> ListServicesV1(const std::shared_ptr<grpc::Channel>& channel) {
  namespace refl = ::grpc::reflection::v1;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 5s);
  auto stream = refl::ServerReflection::NewStub(channel)->ServerReflectionInfo(&ctx);
  refl::ServerReflectionRequest request;
  request.set_list_services("");
  std::vector<std::string> names;
  refl::ServerReflectionResponse response;
  if (stream->Write(request) && stream->WritesDone() && stream->Read(&response)) {
    for (const auto& s : response.list_services_response().service()) names.push_back(s.name());
  }
  (void)stream->Finish();
  return names;
}

TEST_F(MutualTls, VleoScenarioAcrossProcesses) {
  std::string out;
  // The scripted cube video (kisses, then shouting) and its camera.
  ASSERT_EQ(RunShell(kKinemo + " cube render --model " + kSource +
                         "/tests/data/cube/vleo.cube --script " + kSource +
                         "/tests/data/cube/vleo_scenario.json --out " + dir_.File("v.avi") +
                         " --camera " + dir_.File("cam.yml") + " 2>&1",
                     &out),
            0)
      << out;
  int sim_port = 0;
  auto sim = StartPleoSim(&sim_port);
  ASSERT_NE(sim, nullptr);
  auto bridge =
      Start("robot_bridge", "robots { robot_id: \"pleo\" tcp { host: \"127.0.0.1\" port: " +
                                std::to_string(sim_port) + " } timing { poll_s: 0.05 } }\n");
  ASSERT_NE(bridge, nullptr);
  auto tracker = Start("cube_tracker", "cubes {\n" + Slurp(kSource + "/tests/data/cube/vleo.cube") +
                                           "}\nfile_root: \"" + dir_.path() + "\"\n");
  ASSERT_NE(tracker, nullptr);
  // The bridge by name ("localhost", a DNS subjectAltName), the tracker by IP.
  auto coordinator =
      Start("coordinator",
            "services {\n  robot_bridge { address: \"localhost:" + std::to_string(bridge->port()) +
                "\"" + EndpointTls() + "}\n  cube_tracker { address: \"" + tracker->address() +
                "\"" + EndpointTls() + "}\n}\nemotion { rate_per_s: 0.4 }\n",
            v1::CoordinatorService::service_full_name());
  ASSERT_NE(coordinator, nullptr);
  const std::string at = " --coordinator " + coordinator->address();

  // The CLI opens the cube session over mutual TLS.
  ASSERT_EQ(RunShell(kKinemo + " session open pleo --id vleo --vleo cube --initial angry --json" +
                         at + Flags("cli") + " 2>&1",
                     &out),
            0)
      << out;
  EXPECT_NE(out.find("EMOTION_ANGRY"), std::string::npos) << out;
  // A client of the coordinator (mutual TLS) watches it and attaches the video.
  auto stub = v1::CoordinatorService::NewStub(coordinator->Channel());
  grpc::ClientContext watch;
  watch.set_deadline(std::chrono::system_clock::now() + 90s);
  v1::WatchSessionRequest w;
  w.set_session_id("vleo");
  auto reader = stub->WatchSession(&watch, w);
  {
    v1::AttachCubeRequest a;
    a.set_session_id("vleo");
    a.mutable_source()->set_video_file(dir_.File("v.avi"));
    a.mutable_source()->set_realtime(true);
    a.mutable_config()->set_cube_id("vleo");
    a.mutable_config()->set_intrinsics_file(dir_.File("cam.yml"));
    v1::AttachCubeResponse r;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 10s);
    const grpc::Status s = stub->AttachCube(&ctx, a, &r);
    ASSERT_TRUE(s.ok()) << s.error_message();
  }
  std::vector<std::string> emotions;
  int robot_commands = 0;
  v1::SessionEvent e;
  while (reader->Read(&e)) {
    if (e.has_emotion_changed())
      emotions.push_back(common::v1::Emotion_Name(e.emotion_changed().to_emotion()));
    if (e.has_robot_commanded() && e.robot_commanded().error().empty()) ++robot_commands;
    if (e.has_cube_status_changed() && !e.cube_status_changed().attached()) break;
  }
  watch.TryCancel();
  (void)reader->Finish();
  // Kisses took Pleo through neutral to happy, shouting back to angry; every
  // step was sent to the robot over the coordinator's mutual-TLS channel.
  EXPECT_EQ(emotions, (std::vector<std::string>{"EMOTION_NEUTRAL", "EMOTION_HAPPY",
                                                "EMOTION_NEUTRAL", "EMOTION_ANGRY"}));
  EXPECT_GE(robot_commands, 4);
  // pleo_sim shows it, read by the CLI through the bridge over mutual TLS.
  const std::string status_cmd =
      kKinemo + " robot status pleo --bridge localhost:" + std::to_string(bridge->port()) +
      Flags("cli") + " 2>&1";
  bool shown = false;
  for (int i = 0; i < 100 && !shown; ++i) {
    shown = RunShell(status_cmd, &out) == 0 && out.find("shows angry") != std::string::npos;
    if (!shown) std::this_thread::sleep_for(50ms);
  }
  EXPECT_TRUE(shown) << out;
  ASSERT_EQ(RunShell(kKinemo + " session close vleo --json" + at + Flags("cli") + " 2>&1", &out), 0)
      << out;
  EXPECT_NE(out.find("EMOTION_ANGRY"), std::string::npos) << out;
}

TEST_F(MutualTls, AnimateAcrossProcesses) {
  auto prosody = Start("prosody", "");
  ASSERT_NE(prosody, nullptr);
  auto planner = Start(
      "planner", "store_dir: \"" + dir_.File("planner_store") + "\"\nlibrary_root: \"" + kSource +
                     "/tests/data\"\n"
                     "preload { library_id: \"bundled\" paths: \"planner_gesture\" }\n"
                     "preload_gesture_graphs { graph_id: \"bundled\" library_id: \"bundled\" "
                     "params { stroke_phrases: true } }\n");
  ASSERT_NE(planner, nullptr);
  auto coordinator =
      Start("coordinator",
            "services {\n  prosody { address: \"" + prosody->address() + "\"" + EndpointTls() +
                "}\n  planner { address: \"localhost:" + std::to_string(planner->port()) + "\"" +
                EndpointTls() +
                "deadline_s: 30 }\n}\n"
                "animate { default_method: METHOD_BODYSPEECH models { gesture_graph_id: "
                "\"bundled\" } }\n",
            v1::CoordinatorService::service_full_name());
  ASSERT_NE(coordinator, nullptr);
  std::string out;
  const std::string bvh = dir_.File("out.bvh");
  ASSERT_EQ(
      RunShell(kKinemo + " animate " + kSource +
                   "/tests/data/speech/sense_and_sensibility_01_austen_64kb-0880.wav" + " -o " +
                   bvh + " --coordinator " + coordinator->address() + Flags("cli") + " 2>&1",
               &out),
      0)
      << out;
  ASSERT_EQ(RunShell(kKinemo + " bvh info " + bvh + " 2>&1", &out), 0) << out;
  std::istringstream info(out);
  std::string line;
  int frames = 0;
  while (std::getline(info, line)) {
    if (line.rfind("frames:", 0) == 0) frames = std::stoi(line.substr(7));
  }
  EXPECT_GT(frames, 30) << out;  // seconds of motion, not an empty clip
  // The same through the environment instead of flags.
  const std::string env = "KINEMO_TLS_CA=" + Cert("ca.pem") +
                          " KINEMO_TLS_CERT=" + Cert("cli.pem") +
                          " KINEMO_TLS_KEY=" + Cert("cli.key") + " ";
  EXPECT_EQ(
      RunShell(env + kKinemo + " animate " + kSource +
                   "/tests/data/speech/sense_and_sensibility_01_austen_64kb-0880.wav -o " +
                   dir_.File("env.bvh") + " --coordinator " + coordinator->address() + " 2>&1",
               &out),
      0)
      << out;
  // Without a certificate the CLI is refused.
  EXPECT_EQ(RunShell(kKinemo + " animate " + kSource +
                         "/tests/data/speech/sense_and_sensibility_01_austen_64kb-0880.wav" +
                         " -o " + dir_.File("refused.bvh") + " --timeout-s 3 --coordinator " +
                         coordinator->address() + " --ca " + Cert("ca.pem") + " 2>&1",
                     &out),
            1)
      << out;
}

TEST_F(MutualTls, StrangersAreRefusedAndServicesStayHealthy) {
  auto prosody = Start("prosody", "");
  ASSERT_NE(prosody, nullptr);
  auto coordinator = Start(
      "coordinator",
      "services { prosody { address: \"" + prosody->address() + "\"" + EndpointTls() + "} }\n",
      v1::CoordinatorService::service_full_name());
  ASSERT_NE(coordinator, nullptr);
  for (const ServiceProcess* service : {prosody.get(), coordinator.get()}) {
    SCOPED_TRACE(service->address());
    HealthCheckResponse health;
    const std::pair<std::string, ClientTlsFiles> strangers[] = {
        {"plaintext", ClientTlsFiles()},
        {"no certificate", As("")},
        {"certificate from another CA", As("stranger")},
        {"expired certificate", As("expired")},
        {"server not trusted (another CA)", As("cli", "other-ca")},
    };
    for (const auto& [who, files] : strangers) {
      const grpc::Status s = CheckHealth(Channel(service->address(), files), &health);
      EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAVAILABLE) << who << ": " << s.error_message();
    }
    // Still serving, over mutual TLS, after the strangers.
    ASSERT_TRUE(CheckHealth(Channel(service->address(), As("cli")), &health).ok());
    EXPECT_EQ(health.status(), HealthCheckResponse::SERVING);
  }
  // The tools: refused without a certificate (exit 1), served with one;
  // inconsistent options are usage errors (exit 2) naming the flag.
  std::string out;
  const std::string list = kKinemo + " session list --coordinator " + coordinator->address();
  EXPECT_EQ(RunShell(list + " 2>&1", &out), 1) << out;
  EXPECT_EQ(RunShell(list + " --ca " + Cert("ca.pem") + " 2>&1", &out), 1) << out;
  EXPECT_EQ(RunShell(list + " --ca " + Cert("ca.pem") + " --cert " + Cert("stranger.pem") +
                         " --key " + Cert("stranger.key") + " 2>&1",
                     &out),
            1)
      << out;
  EXPECT_EQ(RunShell(list + Flags("cli") + " 2>&1", &out), 0) << out;
  EXPECT_EQ(
      RunShell(list + " --ca " + Cert("ca.pem") + " --cert " + Cert("cli.pem") + " 2>&1", &out), 2)
      << out;
  EXPECT_NE(out.find("--key"), std::string::npos) << out;
  EXPECT_EQ(RunShell(list + " --ca " + dir_.File("missing.pem") + " --cert " + Cert("cli.pem") +
                         " --key " + Cert("cli.key") + " 2>&1",
                     &out),
            2)
      << out;
  EXPECT_NE(out.find("--ca"), std::string::npos) << out;
  EXPECT_EQ(RunShell(kHealth + " " + coordinator->address() + Flags("cli") + " 2>&1", &out), 0)
      << out;
  EXPECT_EQ(
      RunShell(kHealth + " " + coordinator->address() + Flags("stranger") + " --fail-fast --timeout-s 10 2>&1",
               &out),
      1)
      << out;

  // The coordinator's own channel without a client certificate is refused
  // by prosody: a call it forwards fails UNAVAILABLE, with a certificate it
  // reaches prosody (which judges the empty request).
  auto misconfigured =
      Start("coordinator", "services { prosody { address: \"" + prosody->address() +
                               "\" ca_file: \"" + Cert("ca.pem") + "\" deadline_s: 3 } }\n");
  ASSERT_NE(misconfigured, nullptr);
  auto analyze = [&](const ServiceProcess& front) {
    prosody::v1::AnalyzeRequest request;
    prosody::v1::AnalyzeResponse response;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 5s);
    return prosody::v1::ProsodyService::NewStub(front.Channel())->Analyze(&ctx, request, &response);
  };
  const grpc::Status refused = analyze(*misconfigured);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::UNAVAILABLE) << refused.error_message();
  const grpc::Status judged = analyze(*coordinator);
  EXPECT_EQ(judged.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << judged.error_message();

  // Server reflection v1 answers over mutual TLS, and lists the coordinator.
  const auto names = ListServicesV1(coordinator->Channel());
  EXPECT_NE(std::find(names.begin(), names.end(), v1::CoordinatorService::service_full_name()),
            names.end());
  EXPECT_TRUE(ListServicesV1(Channel(coordinator->address(), As("stranger"))).empty());
  // Everyone still healthy.
  for (const ServiceProcess* service : {prosody.get(), coordinator.get(), misconfigured.get()}) {
    HealthCheckResponse health;
    EXPECT_TRUE(CheckHealth(service->Channel(), &health).ok());
    EXPECT_EQ(health.status(), HealthCheckResponse::SERVING);
  }
}

}  // namespace
}  // namespace kinemo
