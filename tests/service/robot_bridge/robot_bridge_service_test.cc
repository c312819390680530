// RobotBridgeService in-process (ServiceHost + in-process channel) against a
// real Modbus peer: pleo_sim's server on a loopback TCP port.
#include <cmath>

#include <google/protobuf/text_format.h>
#include <grpcpp/grpcpp.h>

#include "common/config/options.h"
#include "common/server/service_host.h"
#include "gtest/gtest.h"
#include "services/robot_bridge/robot_bridge_service.h"
#include "tests/unit/robot_bridge/sim_fixture.h"

namespace kinemo::robot_bridge {
namespace {

using robot::testing::InProcessSim;
using robot::testing::WaitFor;

int FreePort() {
  InProcessSim tmp;  // bind, note the port, release it
  return tmp.port();
}

class ServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    v1::RobotBridgeOptions o;
    auto* r = o.add_robots();
    r->set_robot_id("pleo");
    r->mutable_tcp()->set_host("127.0.0.1");
    r->mutable_tcp()->set_port(static_cast<uint32_t>(sim_.port()));
    r->mutable_timing()->set_poll_s(0.05);
    r->mutable_timing()->set_heartbeat_s(0.1);
    auto* gone = o.add_robots();
    gone->set_robot_id("gone");
    gone->mutable_tcp()->set_host("127.0.0.1");
    gone->mutable_tcp()->set_port(static_cast<uint32_t>(FreePort()));
    gone->mutable_timing()->set_retries(1);
    o.set_watch_min_interval_s(0.01);
    auto service = RobotBridgeServiceImpl::Create(o);
    ASSERT_TRUE(service.ok()) << service.status();
    service_ = *service;
    common::v1::ServerOptions server;
    server.set_host("127.0.0.1");
    config::ApplyServerDefaults(&server);
    auto host = server::ServiceHost::Start(
        server, "robot_bridge_test", {{service_, v1::RobotBridgeService::service_full_name()}});
    ASSERT_TRUE(host.ok()) << host.status();
    host_ = std::move(*host);
    stub_ = v1::RobotBridgeService::NewStub(host_->InProcessChannel());
  }
  void TearDown() override {
    if (host_) host_->Shutdown();
  }

  grpc::Status Set(const std::string& robot, int emotion, double intensity, bool wait,
                   v1::SetEmotionResponse* resp) {
    v1::SetEmotionRequest req;
    req.set_robot_id(robot);
    req.set_emotion(static_cast<common::v1::Emotion>(emotion));
    req.set_intensity(intensity);
    req.set_wait_applied(wait);
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(3));
    return stub_->SetEmotion(&ctx, req, resp);
  }

  InProcessSim sim_;
  std::shared_ptr<RobotBridgeServiceImpl> service_;
  std::unique_ptr<server::ServiceHost> host_;
  std::unique_ptr<v1::RobotBridgeService::Stub> stub_;
};

TEST_F(ServiceTest, SetEmotionThenGetStatus) {
  v1::SetEmotionResponse resp;
  grpc::Status s = Set("pleo", common::v1::EMOTION_ANGRY, 0.75, /*wait=*/true, &resp);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_TRUE(resp.applied());
  EXPECT_TRUE(resp.shown());
  EXPECT_GT(resp.sequence_number(), 0u);
  EXPECT_EQ(resp.status().commanded_emotion(), common::v1::EMOTION_ANGRY);

  v1::GetStatusRequest req;
  req.set_robot_id("pleo");
  v1::RobotStatus st;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(2));
  s = stub_->GetStatus(&ctx, req, &st);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_TRUE(st.connected());
  EXPECT_EQ(st.shown_emotion(), common::v1::EMOTION_ANGRY);
  EXPECT_DOUBLE_EQ(st.shown_intensity(), 0.75);
  EXPECT_EQ(st.last_applied_sequence(), resp.sequence_number());
  EXPECT_EQ(st.state(), v1::ROBOT_STATE_FOLLOWING);
  EXPECT_EQ(st.firmware_version(), "1.0");
  EXPECT_EQ(st.touch_sensors_size(), 8);
  EXPECT_TRUE(st.in_sync());
}

TEST_F(ServiceTest, ErrorsHaveTheRightCodes) {
  v1::SetEmotionResponse resp;
  EXPECT_EQ(Set("nobody", common::v1::EMOTION_HAPPY, 0.5, false, &resp).error_code(),
            grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(Set("", common::v1::EMOTION_HAPPY, 0.5, false, &resp).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(Set("pleo", common::v1::EMOTION_UNSPECIFIED, 0.5, false, &resp).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(Set("pleo", 42, 0.5, false, &resp).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(Set("pleo", common::v1::EMOTION_HAPPY, 1.5, false, &resp).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  grpc::Status nan = Set("pleo", common::v1::EMOTION_HAPPY, std::nan(""), false, &resp);
  EXPECT_EQ(nan.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(nan.error_message().find("intensity"), std::string::npos) << nan.error_message();
  grpc::Status gone = Set("gone", common::v1::EMOTION_HAPPY, 0.5, false, &resp);
  EXPECT_EQ(gone.error_code(), grpc::StatusCode::UNAVAILABLE) << gone.error_message();
  EXPECT_NE(gone.error_message().find("gone"), std::string::npos) << gone.error_message();

  v1::GetStatusRequest req;
  req.set_robot_id("gone");
  v1::RobotStatus st;
  grpc::ClientContext ctx;
  EXPECT_EQ(stub_->GetStatus(&ctx, req, &st).error_code(), grpc::StatusCode::UNAVAILABLE);
}

TEST_F(ServiceTest, ListRobotsShowsEveryRobot) {
  ASSERT_TRUE(WaitFor([&] {
    return service_->bridge().Find("pleo").value()->CachedStatus().connected;
  }));
  v1::ListRobotsResponse resp;
  grpc::ClientContext ctx;
  ASSERT_TRUE(stub_->ListRobots(&ctx, v1::ListRobotsRequest(), &resp).ok());
  ASSERT_EQ(resp.robots_size(), 2);
  EXPECT_EQ(resp.robots(0).robot_id(), "gone");
  EXPECT_FALSE(resp.robots(0).status().connected());
  EXPECT_FALSE(resp.robots(0).status().last_error().empty());
  EXPECT_EQ(resp.robots(1).robot_id(), "pleo");
  EXPECT_EQ(resp.robots(1).endpoint(), "tcp://127.0.0.1:" + std::to_string(sim_.port()));
  EXPECT_TRUE(resp.robots(1).status().connected());
}

TEST_F(ServiceTest, WatchStatusStreamsTheChange) {
  grpc::ClientContext ctx;
  v1::WatchStatusRequest req;
  req.set_robot_id("pleo");
  auto reader = stub_->WatchStatus(&ctx, req);
  v1::RobotStatus st;
  ASSERT_TRUE(reader->Read(&st));  // the current status first
  EXPECT_EQ(st.robot_id(), "pleo");
  v1::SetEmotionResponse resp;
  ASSERT_TRUE(Set("pleo", common::v1::EMOTION_HAPPY, 0.3, false, &resp).ok());
  bool seen = false;
  for (int i = 0; i < 500 && reader->Read(&st); ++i) {
    if (st.shown_emotion() == common::v1::EMOTION_HAPPY && st.in_sync() &&
        st.last_applied_sequence() == resp.sequence_number()) {
      seen = true;
      break;
    }
  }
  EXPECT_TRUE(seen);
  ctx.TryCancel();
  while (reader->Read(&st)) {
  }
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::CANCELLED);
}

TEST_F(ServiceTest, WatchStatusUnknownRobotIsNotFound) {
  grpc::ClientContext ctx;
  v1::WatchStatusRequest req;
  req.set_robot_id("nobody");
  auto reader = stub_->WatchStatus(&ctx, req);
  v1::RobotStatus st;
  EXPECT_FALSE(reader->Read(&st));
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST(OptionsTest, TheExampleConfigLoads) {
  v1::RobotBridgeOptions o;
  Status s = config::LoadTextProtoFile(
      std::string(KINEMO_TEST_DATA_DIR) + "/../../services/robot_bridge/robot_bridge.example.textproto",
      &o);
  ASSERT_TRUE(s.ok()) << s;
  auto c = ToCoreConfigs(o);
  ASSERT_TRUE(c.ok()) << c.status();
  ASSERT_EQ(c->size(), 1u);
  EXPECT_EQ((*c)[0].link.endpoint.port, 1502);
  EXPECT_EQ(o.server().port(), 50055u);
}

TEST(OptionsTest, DefaultsAndErrors) {
  v1::RobotBridgeOptions o;
  EXPECT_TRUE(absl::IsInvalidArgument(ToCoreConfigs(o).status()));
  ASSERT_TRUE(google::protobuf::TextFormat::ParseFromString(R"pb(
    default_timing { response_timeout_s: 0.3 retries: 5 }
    robots { robot_id: "a" tcp { port: 1502 } address_offset: 1000 }
    robots { robot_id: "b" rtu { device: "/dev/ttyX" } timing { response_timeout_s: 0.1 } }
  )pb", &o));
  auto c = ToCoreConfigs(o);
  ASSERT_TRUE(c.ok()) << c.status();
  ASSERT_EQ(c->size(), 2u);
  EXPECT_EQ((*c)[0].link.endpoint.host, "127.0.0.1");
  EXPECT_EQ((*c)[0].link.endpoint.port, 1502);
  EXPECT_EQ((*c)[0].link.response_timeout_ms, 300);
  EXPECT_EQ((*c)[0].retry.max_attempts, 6);
  EXPECT_EQ((*c)[0].map.command_base, 1000);
  EXPECT_EQ((*c)[0].map.status_base, 1000);
  EXPECT_EQ((*c)[1].link.endpoint.baud, 115200);
  EXPECT_EQ((*c)[1].link.response_timeout_ms, 100);
  EXPECT_EQ((*c)[1].watchdog_ms, 2000);

  auto expect_error = [](const char* text, const char* field) {
    v1::RobotBridgeOptions bad;
    ASSERT_TRUE(google::protobuf::TextFormat::ParseFromString(text, &bad));
    auto r = ToCoreConfigs(bad);
    ASSERT_FALSE(r.ok()) << text;
    EXPECT_TRUE(absl::IsInvalidArgument(r.status()));
    EXPECT_NE(r.status().message().find(field), absl::string_view::npos) << r.status();
  };
  expect_error(R"pb(robots { robot_id: "a" })pb", "robots[0].transport");
  expect_error(R"pb(robots { robot_id: "a" rtu {} })pb", "robots[0].rtu.device");
  expect_error(R"pb(robots { robot_id: "a" rtu { device: "/x" parity: "Q" } })pb", "parity");
  expect_error(R"pb(robots { robot_id: "a" tcp {} register_map: "aibo" })pb", "register_map");
  expect_error(R"pb(robots { robot_id: "a" tcp {} unit_id: 300 })pb", "unit_id");
  expect_error(R"pb(robots { robot_id: "a b" tcp {} })pb", "name");
  expect_error(R"pb(robots { robot_id: "a" tcp {} timing { heartbeat_s: 3 watchdog_s: 2 } })pb",
               "watchdog_ms");
}

}  // namespace
}  // namespace kinemo::robot_bridge
