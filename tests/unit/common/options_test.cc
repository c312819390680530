#include "common/config/options.h"

#include <gtest/gtest.h>

#include <fstream>

#include "common/testing/process.h"
#include "kinemo/coordinator/v1/options.pb.h"
#include "kinemo/cube_tracker/v1/options.pb.h"
#include "kinemo/inference/v1/options.pb.h"
#include "kinemo/planner/v1/options.pb.h"
#include "kinemo/prosody/v1/options.pb.h"
#include "kinemo/robot_bridge/v1/options.pb.h"
#include "kinemo/studio/v1/options.pb.h"

namespace kinemo::config {
namespace {

using common::v1::ServerOptions;

StatusOr<ServerCommandLine> Parse(std::vector<std::string> args) {
  args.insert(args.begin(), "svc");
  std::vector<const char*> argv;
  for (const auto& a : args) argv.push_back(a.c_str());
  return ParseServerCommandLine(static_cast<int>(argv.size()), argv.data(), "svc");
}

TEST(Options, TextProtoParsesIntoTheMessage) {
  ServerOptions o;
  ASSERT_TRUE(ParseTextProto("host: \"0.0.0.0\"\nport: 5005\nmax_message_bytes: 2048\n"
                             "tls { cert_file: \"a.pem\" key_file: \"b.pem\" }",
                             "t", &o)
                  .ok());
  EXPECT_EQ(o.host(), "0.0.0.0");
  EXPECT_EQ(o.port(), 5005u);
  EXPECT_EQ(o.tls().key_file(), "b.pem");
}

TEST(Options, ParseErrorsNameSourceLineAndColumnAndChangeNothing) {
  ServerOptions o;
  o.set_host("keep");
  const Status s = ParseTextProto("port: 1\nhots: \"x\"\n", "svc.textproto", &o);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("svc.textproto:2:"), std::string::npos) << s;
  EXPECT_NE(s.message().find("hots"), std::string::npos) << s;
  EXPECT_EQ(o.host(), "keep");
  EXPECT_EQ(o.port(), 0u);  // the good first line was not applied either
}

TEST(Options, WrongTypeIsAnError) {
  ServerOptions o;
  const Status s = ParseTextProto("port: \"fifty\"", "f", &o);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("f:1:"), std::string::npos) << s;
}

TEST(Options, FlagsOverrideTheFile) {
  kinemo::testing::TempDir dir;
  const std::string path = dir.File("server.textproto");
  std::ofstream(path) << "host: \"0.0.0.0\"\nport: 7000\nlog_level: \"debug\"\n";
  auto cl = Parse({"--config", path, "--port", "0", "--port-file", dir.File("p")});
  ASSERT_TRUE(cl.ok()) << cl.status();
  ServerOptions o;
  ASSERT_TRUE(LoadServiceOptions(*cl, &o).ok());
  EXPECT_EQ(o.host(), "0.0.0.0");    // from the file
  EXPECT_EQ(o.port(), 0u);           // flag wins
  EXPECT_EQ(o.log_level(), "debug");
  EXPECT_EQ(o.max_message_bytes(), 16u << 20);  // default filled in
  EXPECT_EQ(cl->port_file, dir.File("p"));
}

TEST(Options, LaterConfigFilesMergeOverEarlierOnes) {
  kinemo::testing::TempDir dir;
  for (const char* f : {"c.pem", "c.key", "ca.pem"}) std::ofstream(dir.File(f)) << "-----BEGIN X-----\n";
  std::ofstream(dir.File("base.textproto"))
      << "server { host: \"0.0.0.0\" port: 7000 }\n"
      << "services { prosody { address: \"prosody:50051\" deadline_s: 3 } }\nresend_s: 1\n";
  std::ofstream(dir.File("overlay.textproto"))
      << "server { tls { cert_file: \"" << dir.File("c.pem") << "\" key_file: \"" << dir.File("c.key")
      << "\" client_ca_file: \"" << dir.File("ca.pem") << "\" } }\n"
      << "services { prosody { ca_file: \"ca.pem\" } }\nresend_s: 2\n";
  auto cl = Parse({"--config", dir.File("base.textproto"), "--config", dir.File("overlay.textproto")});
  ASSERT_TRUE(cl.ok()) << cl.status();
  ASSERT_EQ(cl->config_paths.size(), 2u);
  coordinator::v1::CoordinatorOptions o;
  ASSERT_TRUE(LoadServiceOptions(*cl, &o).ok());
  EXPECT_EQ(o.server().host(), "0.0.0.0");  // kept from the base
  EXPECT_EQ(o.server().port(), 7000u);
  EXPECT_EQ(o.server().tls().client_ca_file(), dir.File("ca.pem"));  // added by the overlay
  EXPECT_EQ(o.services().prosody().address(), "prosody:50051");
  EXPECT_EQ(o.services().prosody().deadline_s(), 3);
  EXPECT_EQ(o.services().prosody().ca_file(), "ca.pem");
  EXPECT_EQ(o.resend_s(), 2);  // a scalar: the later file wins
  // An error in the second file names it, and the options stay as they were.
  std::ofstream(dir.File("bad.textproto")) << "server { tsl { } }\n";
  auto bad = Parse({"--config", dir.File("base.textproto"), "--config", dir.File("bad.textproto")});
  ASSERT_TRUE(bad.ok());
  coordinator::v1::CoordinatorOptions untouched;
  const Status s = LoadServiceOptions(*bad, &untouched);
  EXPECT_NE(s.message().find("bad.textproto:1:"), std::string::npos) << s;
}

// Every overlay of deploy/config/tls/ parses over its service's deployment
// options and turns mutual TLS on (paths under /etc/kinemo-tls).
TEST(Options, DeploymentTlsOverlaysMergeOverTheDeploymentOptions) {
  const std::string deploy = std::string(KINEMO_TEST_DATA_DIR) + "/../../deploy/config/";
  prosody::v1::ProsodyOptions prosody;
  inference::v1::InferenceOptions inference;
  planner::v1::PlannerOptions planner;
  cube_tracker::v1::CubeTrackerOptions cube_tracker;
  robot_bridge::v1::RobotBridgeOptions robot_bridge;
  coordinator::v1::CoordinatorOptions coordinator;
  const std::pair<std::string, google::protobuf::Message*> services[] = {
      {"prosody", &prosody}, {"inference", &inference}, {"planner", &planner},
      {"cube_tracker", &cube_tracker}, {"robot_bridge", &robot_bridge}, {"coordinator", &coordinator}};
  for (const auto& [name, options] : services) {
    ASSERT_TRUE(LoadTextProtoFile(deploy + name + ".textproto", options).ok()) << name;
    const std::uint32_t port = MutableServerOptions(options)->port();
    ASSERT_TRUE(LoadTextProtoFile(deploy + "tls/" + name + ".textproto", options).ok()) << name;
    const ServerOptions& server = *MutableServerOptions(options);
    EXPECT_EQ(server.port(), port) << name;
    EXPECT_EQ(server.tls().cert_file(), "/etc/kinemo-tls/" + name + ".pem") << name;
    EXPECT_EQ(server.tls().key_file(), "/etc/kinemo-tls/" + name + ".key") << name;
    EXPECT_EQ(server.tls().client_ca_file(), "/etc/kinemo-tls/ca.pem") << name;
  }
  for (const auto* e : {&coordinator.services().prosody(), &coordinator.services().inference(),
                        &coordinator.services().planner(), &coordinator.services().cube_tracker(),
                        &coordinator.services().robot_bridge()}) {
    EXPECT_FALSE(e->address().empty());
    EXPECT_EQ(e->ca_file(), "/etc/kinemo-tls/ca.pem");
    EXPECT_EQ(e->cert_file(), "/etc/kinemo-tls/coordinator.pem");
    EXPECT_EQ(e->key_file(), "/etc/kinemo-tls/coordinator.key");
  }
}

// The options deploy/k8s mounts: every service's metrics on (all addresses,
// deploy/prometheus' ports); the coordinator's cluster overlay merged over
// deploy/config names a dns:/// target and a policy for each service; the
// robot bridge files (base and dev overlay) parse.
TEST(Options, KubernetesOptionsParseAndMerge) {
  const std::string root = std::string(KINEMO_TEST_DATA_DIR) + "/../../deploy/";
  coordinator::v1::CoordinatorOptions coordinator;
  ASSERT_TRUE(LoadTextProtoFile(root + "config/coordinator.textproto", &coordinator).ok());
  EXPECT_TRUE(coordinator.server().metrics().enabled());
  EXPECT_EQ(coordinator.server().metrics().host(), "0.0.0.0");
  EXPECT_EQ(coordinator.server().metrics().port(), 9460u);
  const Status merged = LoadTextProtoFile(root + "k8s/base/config/coordinator.textproto", &coordinator);
  ASSERT_TRUE(merged.ok()) << merged;
  EXPECT_EQ(coordinator.server().port(), 50050u);  // untouched by the overlay
  EXPECT_EQ(coordinator.services().planner().address(), "dns:///planner.kinemo.svc.cluster.local:50053");
  EXPECT_EQ(coordinator.services().planner().deadline_s(), 10);  // from deploy/config
  EXPECT_EQ(coordinator.services().planner().lb_policy(), "round_robin");
  EXPECT_EQ(coordinator.services().robot_bridge().lb_policy(), "pick_first");
  // The studio attaches cubes from its cube_dir inside the cube tracker's
  // file_root where they share a file system (compose, local stack), not in
  // Kubernetes (the overlay clears it).
  studio::v1::StudioOptions studio;
  cube_tracker::v1::CubeTrackerOptions tracker;
  ASSERT_TRUE(LoadTextProtoFile(root + "config/studio.textproto", &studio).ok());
  ASSERT_TRUE(LoadTextProtoFile(root + "config/cube_tracker.textproto", &tracker).ok());
  EXPECT_EQ(studio.cube_dir().rfind(tracker.file_root() + "/", 0), 0u) << studio.cube_dir();
  const Status studio_k8s = LoadTextProtoFile(root + "k8s/base/config/studio.textproto", &studio);
  ASSERT_TRUE(studio_k8s.ok()) << studio_k8s;
  EXPECT_EQ(studio.cube_dir(), "");
  EXPECT_EQ(studio.coordinator().address(), "coordinator:50050");  // untouched by the overlay
  for (const char* file : {"k8s/base/config/robot_bridge.textproto", "k8s/overlays/dev/robot_bridge.textproto"}) {
    robot_bridge::v1::RobotBridgeOptions bridge;
    const Status s = LoadTextProtoFile(root + file, &bridge);
    ASSERT_TRUE(s.ok()) << file << ": " << s;
    EXPECT_EQ(bridge.robots_size(), 1) << file;
    EXPECT_EQ(bridge.server().metrics().port(), 9465u) << file;
  }
}

TEST(Options, BadFlagsAreClearErrors) {
  EXPECT_FALSE(Parse({"--port", "70000"}).ok());
  EXPECT_FALSE(Parse({"--bogus"}).ok());
  const auto missing = Parse({"--config", "/nonexistent/x.textproto"});
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.status().message().find("--config"), std::string::npos) << missing.status();
  auto help = Parse({"--help"});
  ASSERT_TRUE(help.ok());
  EXPECT_TRUE(help->help);
  EXPECT_NE(help->usage.find("--port-file"), std::string::npos);
}

TEST(Options, ValidationNamesTheField) {
  auto check = [](const std::string& text, const std::string& field) {
    ServerOptions o;
    ASSERT_TRUE(ParseTextProto(text, "t", &o).ok()) << text;
    ApplyServerDefaults(&o);
    const Status s = ValidateServerOptions(o);
    ASSERT_FALSE(s.ok()) << text;
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(s.message().find(field), std::string::npos) << s;
  };
  check("port: 70000", "server.port");
  check("max_message_bytes: 2000000000", "server.max_message_bytes");
  check("max_message_bytes: 10", "server.max_message_bytes");
  check("log_level: \"chatty\"", "server.log_level");
  check("log_format: \"xml\"", "server.log_format");
  check("shutdown_grace_s: -1", "server.shutdown_grace_s");
  check("host: \"unix:\"", "server.host");
  check("host: \"a b\"", "server.host");
  check("tls { cert_file: \"/etc/hostname\" }", "server.tls.key_file");
  check("tls { client_ca_file: \"/etc/hostname\" }", "server.tls.client_ca_file");
  check("tls { cert_file: \"/nonexistent.pem\" key_file: \"/nonexistent.pem\" }",
        "server.tls.cert_file");
}

TEST(Options, DefaultsAreValid) {
  ServerOptions o;
  ApplyServerDefaults(&o);
  EXPECT_TRUE(ValidateServerOptions(o).ok());
  EXPECT_EQ(o.host(), "127.0.0.1");
}

TEST(Options, MessagesWithoutServerFieldAreRejected) {
  ServerCommandLine cl;
  common::v1::TlsOptions not_a_service;
  EXPECT_EQ(LoadServiceOptions(cl, &not_a_service).code(), absl::StatusCode::kInternal);
}

TEST(Options, AtomicWriteLeavesNoTemporaryBehind) {
  kinemo::testing::TempDir dir;
  ASSERT_TRUE(WriteFileAtomically(dir.File("port"), "1234\n").ok());
  std::ifstream in(dir.File("port"));
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "1234");
  EXPECT_FALSE(WriteFileAtomically("/nonexistent-dir/port", "1").ok());
}

}  // namespace
}  // namespace kinemo::config
