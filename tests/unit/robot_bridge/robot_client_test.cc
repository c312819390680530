// Bridge core against a real Modbus peer (in-process pleo_sim on loopback).
#include <array>

#include "gtest/gtest.h"
#include "services/robot_bridge/core/fault_injecting_link.h"
#include "services/robot_bridge/core/robot_bridge.h"
#include "services/robot_bridge/core/robot_client.h"
#include "tests/unit/robot_bridge/sim_fixture.h"

namespace kinemo::robot {
namespace {

using testing::InProcessSim;
using testing::WaitFor;

// A raw libmodbus link to poke the simulator's registers directly.
std::unique_ptr<ModbusLink> RawLink(const InProcessSim& sim, int response_timeout_ms = 200) {
  LinkOptions o;
  o.endpoint.host = "127.0.0.1";
  o.endpoint.port = sim.port();
  o.response_timeout_ms = response_timeout_ms;
  auto link = NewLibmodbusLink(o);
  EXPECT_TRUE(link->Connect().ok());
  return link;
}

struct Fixture {
  InProcessSim sim;
  FaultInjectingLink* faults = nullptr;
  std::unique_ptr<RobotClient> client;

  explicit Fixture(pleo_sim::ServerOptions o = InProcessSim::Defaults(),
                   std::function<void(RobotConfig&)> tweak = nullptr)
      : sim(o) {
    RobotConfig c = sim.Config();
    if (tweak) tweak(c);
    EXPECT_TRUE(ValidateRobotConfig(c).ok());
    auto inner = NewLibmodbusLink(c.link);
    auto wrapped = std::make_unique<FaultInjectingLink>(std::move(inner));
    faults = wrapped.get();
    client = std::make_unique<RobotClient>(c, std::move(wrapped));
  }
};

TEST(EndpointTest, ParsesTcpAndRtu) {
  auto tcp = ParseEndpoint("tcp://127.0.0.1:1502");
  ASSERT_TRUE(tcp.ok()) << tcp.status();
  EXPECT_EQ(tcp->kind, Endpoint::Kind::kTcp);
  EXPECT_EQ(tcp->host, "127.0.0.1");
  EXPECT_EQ(tcp->port, 1502);
  auto rtu = ParseEndpoint("rtu:///dev/pts/3?baud=9600&parity=E");
  ASSERT_TRUE(rtu.ok()) << rtu.status();
  EXPECT_EQ(rtu->device, "/dev/pts/3");
  EXPECT_EQ(rtu->baud, 9600);
  EXPECT_EQ(rtu->parity, 'E');
  auto round = ParseEndpoint(rtu->ToString());
  ASSERT_TRUE(round.ok());
  EXPECT_EQ(round->device, "/dev/pts/3");
  EXPECT_FALSE(ParseEndpoint("tcp://host").ok());
  EXPECT_FALSE(ParseEndpoint("tcp://host:99999").ok());
  EXPECT_FALSE(ParseEndpoint("udp://x:1").ok());
  EXPECT_FALSE(ParseEndpoint("rtu:///dev/x?baud=fast").ok());
  EXPECT_FALSE(ParseEndpoint("rtu:///dev/x?speed=1").ok());
  // IPv6: printed in brackets and parsed back to the same endpoint, bare or
  // bracketed; brackets twice (found by fuzz_robot_registers) are refused.
  for (const char* text : {"tcp://[::1]:502", "tcp://::1:502", "tcp://[::]:502"}) {
    auto v6 = ParseEndpoint(text);
    ASSERT_TRUE(v6.ok()) << text << ": " << v6.status();
    auto again = ParseEndpoint(v6->ToString());
    ASSERT_TRUE(again.ok()) << v6->ToString();
    EXPECT_EQ(again->host, v6->host) << text;
    EXPECT_EQ(again->ToString(), v6->ToString()) << text;
  }
  EXPECT_EQ(ParseEndpoint("tcp://::1:502")->ToString(), "tcp://[::1]:502");
  auto twice = ParseEndpoint("tcp://[[::]]:502");
  ASSERT_FALSE(twice.ok());
  EXPECT_TRUE(absl::IsInvalidArgument(twice.status())) << twice.status();
  EXPECT_NE(std::string(twice.status().message()).find("endpoint"), std::string::npos) << twice.status();
}

TEST(ConfigTest, RejectsBadValuesNamingTheField) {
  RobotConfig c;
  c.name = "pleo";
  EXPECT_TRUE(ValidateRobotConfig(c).ok());
  c.link.unit_id = 0;
  auto s = ValidateRobotConfig(c);
  EXPECT_TRUE(absl::IsInvalidArgument(s));
  EXPECT_NE(s.message().find("unit_id"), absl::string_view::npos) << s;
  c.link.unit_id = 1;
  c.watchdog_ms = 300;
  c.heartbeat_interval_ms = 500;
  s = ValidateRobotConfig(c);
  EXPECT_NE(s.message().find("watchdog_ms"), absl::string_view::npos) << s;
  c.watchdog_ms = 2000;
  c.name = "bad name";
  EXPECT_FALSE(ValidateRobotConfig(c).ok());
}

TEST(RobotClientTest, OutOfRangeValuesAreRefusedBeforeAnythingIsWritten) {
  Fixture f;
  for (auto [e, i] : {std::pair{3, 500}, std::pair{-1, 500}, std::pair{1, 1001},
                      std::pair{1, -5}}) {
    auto r = f.client->SetEmotion(e, i);
    ASSERT_FALSE(r.ok());
    EXPECT_TRUE(absl::IsInvalidArgument(r.status())) << r.status();
  }
  EXPECT_EQ(f.faults->connects(), 0);
  EXPECT_EQ(f.faults->writes(), 0);
  EXPECT_EQ(f.faults->operations(), 0);
}

TEST(RobotClientTest, SetEmotionIsAcknowledgedAndShown) {
  Fixture f;
  CommandOptions opts;
  opts.wait_shown = true;
  auto r = f.client->SetEmotion(static_cast<int>(Emotion::kHappy), 700, opts);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_TRUE(r->shown);
  EXPECT_EQ(r->attempts, 1);
  auto st = f.client->ReadStatus();
  ASSERT_TRUE(st.ok()) << st.status();
  EXPECT_EQ(st->shown_emotion, Emotion::kHappy);
  EXPECT_EQ(st->shown_intensity_permille, 700);
  EXPECT_EQ(st->applied_sequence, r->sequence);
  EXPECT_EQ(st->state, RobotState::kFollowing);
  EXPECT_EQ(st->firmware_version, 0x0100);
  EXPECT_TRUE(st->in_sync);
  // What the robot holds, read independently.
  auto raw = RawLink(f.sim);
  std::array<uint16_t, 3> cmd{};
  ASSERT_TRUE(raw->ReadHoldingRegisters(reg::kCmdEmotion, cmd).ok());
  EXPECT_EQ(cmd[0], 1);
  EXPECT_EQ(cmd[1], 700);
  EXPECT_EQ(cmd[2], r->sequence);
}

TEST(RobotClientTest, LostAnswerIsRetriedWithTheSameSequenceNumber) {
  Fixture f;
  ASSERT_TRUE(f.client->SetEmotion(0, 100).ok());
  f.faults->LoseNextWriteAnswers(1);
  auto r = f.client->SetEmotion(2, 900);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->attempts, 2);
  auto st = f.client->ReadStatus();
  ASSERT_TRUE(st.ok());
  EXPECT_EQ(st->applied_sequence, r->sequence);
  EXPECT_EQ(st->commanded_sequence, r->sequence);
}

TEST(RobotClientTest, DevicesWithoutWriteAndReadGetTwoTransactions) {
  Fixture f;
  f.faults->RefuseWriteAndRead(true);
  for (int e : {1, 2}) {
    auto r = f.client->SetEmotion(e, 300, {.timeout_ms = 2000, .wait_shown = true});
    ASSERT_TRUE(r.ok()) << r.status();
    EXPECT_EQ(r->attempts, 1);
    EXPECT_TRUE(r->shown);
  }
}

TEST(RobotClientTest, TransientFailuresAreRetriedWithBackoff) {
  Fixture f;
  ASSERT_TRUE(f.client->ReadStatus().ok());  // connected: faults hit the command itself
  f.faults->FailNext(2);
  auto r = f.client->SetEmotion(1, 500);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->attempts, 3);
}

TEST(RobotClientTest, PersistentFailureReportsUnavailableAndHeartbeatCatchesUp) {
  Fixture f;
  f.faults->FailNext(1000);
  auto r = f.client->SetEmotion(2, 800);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(absl::IsUnavailable(r.status())) << r.status();
  EXPECT_NE(r.status().message().find("after 4 attempt(s)"), absl::string_view::npos)
      << r.status();
  EXPECT_FALSE(f.client->CachedStatus().last_error.empty());
  // The line comes back: the pending command reaches the robot without a new call.
  f.faults->FailNext(0);
  ASSERT_TRUE(f.client->HeartbeatOnce().ok());
  auto st = f.client->ReadStatus();
  ASSERT_TRUE(st.ok());
  EXPECT_EQ(st->applied_sequence, st->commanded_sequence);
  EXPECT_EQ(st->target_emotion, Emotion::kAngry);
  EXPECT_GE(st->resends, 1u);
}

TEST(RobotClientTest, ReconnectsAfterTheSocketIsDropped) {
  Fixture f;
  ASSERT_TRUE(f.client->SetEmotion(1, 500).ok());
  f.faults->DropConnectionOnNext();
  auto r = f.client->SetEmotion(2, 500);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_GE(r->attempts, 2);
  EXPECT_GE(f.client->CachedStatus().reconnects, 1u);
}

TEST(RobotClientTest, UnreachableRobotIsUnavailableWithTheEndpointInTheMessage) {
  // A port that was just free: nothing listens there.
  int port;
  {
    InProcessSim tmp;
    port = tmp.port();
  }
  RobotConfig c;
  c.name = "gone";
  c.link.endpoint.port = port;
  c.retry.max_attempts = 2;
  auto client = RobotClient::Create(c);
  ASSERT_TRUE(client.ok());
  auto r = (*client)->SetEmotion(1, 500);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(absl::IsUnavailable(r.status())) << r.status();
  EXPECT_NE(r.status().message().find(std::to_string(port)), absl::string_view::npos);
  auto st = (*client)->ReadStatus();
  EXPECT_TRUE(absl::IsUnavailable(st.status()));
  EXPECT_FALSE((*client)->CachedStatus().connected);
}

TEST(RobotClientTest, FreshClientContinuesAfterTheRobotsSequenceNumber) {
  Fixture f;
  auto raw = RawLink(f.sim);
  const std::array<uint16_t, 3> cmd = {1, 500, 41};
  ASSERT_TRUE(raw->WriteRegisters(reg::kCmdEmotion, cmd).ok());
  auto r = f.client->SetEmotion(2, 500);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->sequence, 42);
}

TEST(RobotClientTest, SimulatorFaultsBusyAndCorruptAreRetried) {
  for (SimFault fault : {SimFault::kBusy, SimFault::kCorrupt, SimFault::kNoise}) {
    Fixture f;
    ASSERT_TRUE(f.client->SetEmotion(0, 0).ok());
    auto raw = RawLink(f.sim);
    const std::array<uint16_t, 3> ctl = {static_cast<uint16_t>(fault), 0, 2};
    ASSERT_TRUE(raw->WriteRegisters(reg::kSimFaultMode, ctl).ok());
    CommandOptions opts;
    opts.wait_shown = true;
    auto r = f.client->SetEmotion(1, 600, opts);
    ASSERT_TRUE(r.ok()) << SimFaultName(fault) << ": " << r.status();
    EXPECT_GE(r->attempts, 2) << SimFaultName(fault);
    EXPECT_TRUE(r->shown);
  }
}

TEST(RobotClientTest, SlowRobotTimesOutClearly) {
  // 250 ms against a robot that answers after 1 s: a loaded CI machine can
  // take longer than 50 ms to answer even a healthy robot (the first
  // SetEmotion below once failed that way), never 1 s.
  Fixture f(InProcessSim::Defaults(), [](RobotConfig& c) {
    c.link.response_timeout_ms = 250;
    c.retry.max_attempts = 2;
  });
  ASSERT_TRUE(f.client->SetEmotion(0, 0).ok());
  auto raw = RawLink(f.sim, 5000);  // its writes may queue behind the delayed answers
  const std::array<uint16_t, 3> ctl = {static_cast<uint16_t>(SimFault::kDelay), 1000, 0};
  ASSERT_TRUE(raw->WriteRegisters(reg::kSimFaultMode, ctl).ok());
  auto r = f.client->SetEmotion(1, 500);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(absl::IsUnavailable(r.status())) << r.status();
  EXPECT_NE(r.status().message().find("no response within 250 ms"), absl::string_view::npos)
      << r.status();
  // Clear the fault: the command lands.
  const std::array<uint16_t, 1> off = {0};
  ASSERT_TRUE(raw->WriteRegisters(reg::kSimFaultMode, off).ok());
  EXPECT_TRUE(WaitFor([&] {
    (void)f.client->HeartbeatOnce();
    auto st = f.client->ReadStatus();
    return st.ok() && st->applied_sequence == st->commanded_sequence;
  }));
}

TEST(RobotClientTest, DeviceRefusalsKeepTheirMeaning) {
  InProcessSim sim;
  auto raw = RawLink(sim);
  Status s = raw->WriteRegister(reg::kCmdEmotion, 7);
  EXPECT_TRUE(absl::IsInvalidArgument(s)) << s;
  std::array<uint16_t, 2> out{};
  s = raw->ReadHoldingRegisters(50, out);
  EXPECT_TRUE(absl::IsFailedPrecondition(s)) << s;
  std::array<uint16_t, reg::kInputCount> in{};
  ASSERT_TRUE(raw->ReadInputRegisters(0, in).ok());
  EXPECT_NE(in[reg::kFaultFlags] & kFaultCommandRefused, 0);
  EXPECT_EQ(in[reg::kDeviceId], kDeviceIdValue);
}

TEST(RobotClientTest, HeartbeatBringsTheRobotBackFromAutonomy) {
  auto o = InProcessSim::Defaults();
  o.firmware.autonomous_period_ms = 20;
  Fixture f(o);
  ASSERT_TRUE(f.client->SetEmotion(1, 500, {.timeout_ms = 2000, .wait_shown = true}).ok());
  // Starve the watchdog by setting it short from outside, then wait for autonomy.
  auto raw = RawLink(f.sim);
  ASSERT_TRUE(raw->WriteRegister(reg::kWatchdogMs, 100).ok());
  ASSERT_TRUE(WaitFor([&] {
    std::array<uint16_t, reg::kInputCount> in{};
    return raw->ReadInputRegisters(0, in).ok() &&
           in[reg::kState] == static_cast<uint16_t>(RobotState::kAutonomous);
  }));
  f.client->Start();
  EXPECT_TRUE(WaitFor([&] {
    auto st = f.client->CachedStatus();
    return st.in_sync && st.shown_emotion == Emotion::kHappy;
  })) << f.client->CachedStatus().last_error;
  f.client->Stop();
}

TEST(RobotClientTest, SubscribersSeeEveryRefresh) {
  Fixture f;
  std::atomic<int> calls{0};
  int id = f.client->Subscribe([&](const RobotStatus& s) {
    if (s.connected) ++calls;
  });
  f.client->Start();
  EXPECT_TRUE(WaitFor([&] { return calls.load() >= 3; }));
  f.client->Unsubscribe(id);
  const int seen = calls.load();
  f.client->Stop();
  EXPECT_EQ(calls.load(), seen);
}

TEST(RobotBridgeTest, FindsRobotsByNameAndRejectsDuplicates) {
  InProcessSim sim;
  std::vector<RobotConfig> robots = {sim.Config("b"), sim.Config("a")};
  auto bridge = RobotBridge::Create(robots);
  ASSERT_TRUE(bridge.ok()) << bridge.status();
  EXPECT_EQ((*bridge)->Names(), (std::vector<std::string>{"a", "b"}));
  ASSERT_TRUE((*bridge)->Find("a").ok());
  auto missing = (*bridge)->Find("zed");
  EXPECT_TRUE(absl::IsNotFound(missing.status()));
  EXPECT_NE(missing.status().message().find("known: a, b"), absl::string_view::npos);
  robots.push_back(sim.Config("a"));
  auto dup = RobotBridge::Create(robots);
  EXPECT_TRUE(absl::IsInvalidArgument(dup.status())) << dup.status();
}

}  // namespace
}  // namespace kinemo::robot
