// The bridge core against the real pleo_sim binary (TCP on an ephemeral port,
// RTU on a socat pty pair), interop with mbpoll and pymodbus, and fault tests.
#include <fcntl.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <random>

#include "gtest/gtest.h"
#include "services/robot_bridge/core/robot_client.h"
#include "tests/integration/robot_bridge/process_util.h"

namespace kinemo::robot {
namespace {

using testing::Child;
using testing::ParseMbpoll;
using testing::PtyPair;
using testing::ReadFile;
using testing::TempDir;
using testing::WaitForPortFile;
using testing::WaitUntil;
using Clock = std::chrono::steady_clock;

const std::string kPleoSim = std::string(KINEMO_BINARY_DIR) + "/services/pleo_sim/pleo_sim";
const std::string kPymodbusScript = std::string(ROBOT_TEST_DIR) + "/pymodbus_pleo.py";

// pleo_sim on TCP. Restartable on the same port (the one the OS gave first).
struct TcpSim {
  const TempDir& dir;
  std::vector<std::string> extra;
  Child child;
  int port = 0;

  TcpSim(const TempDir& d, std::vector<std::string> x = {}) : dir(d), extra(std::move(x)) {}

  bool Start() {
    std::string port_file = dir.File("sim.port");
    std::remove(port_file.c_str());
    std::vector<std::string> argv = {kPleoSim, "--tcp", "127.0.0.1:" + std::to_string(port),
                                     "--port-file", port_file, "--switch-ms", "100", "-v"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    child = Child::Start(argv, dir.File("sim.log"));
    port = WaitForPortFile(port_file);
    return port > 0;
  }
};

RobotConfig TcpConfig(int port) {
  RobotConfig c;
  c.name = "pleo";
  c.link.endpoint.port = port;
  c.link.response_timeout_ms = 200;
  c.heartbeat_interval_ms = 200;
  c.watchdog_ms = 1000;
  c.reconnect_backoff_max_ms = 200;
  return c;
}

RobotConfig RtuConfig(const std::string& device) {
  RobotConfig c;
  c.name = "pleo_rtu";
  c.link.endpoint.kind = Endpoint::Kind::kRtu;
  c.link.endpoint.device = device;
  c.link.endpoint.baud = 115200;
  c.link.response_timeout_ms = 200;
  c.heartbeat_interval_ms = 200;
  c.watchdog_ms = 1000;
  c.reconnect_backoff_max_ms = 200;
  return c;
}

std::string MbpollTcp(int port, const std::string& args, int* rc = nullptr) {
  return testing::Run("/usr/bin/mbpoll -m tcp -p " + std::to_string(port) + " -a 1 -0 -1 " + args,
                      rc);
}

// Waits until the robot is seen in the last commanded state; returns the
// time it took, or a negative value on timeout.
double WaitInSync(RobotClient& client, Emotion want,
                  std::chrono::milliseconds timeout = std::chrono::seconds(10)) {
  const auto start = Clock::now();
  bool ok = WaitUntil(
      [&] {
        RobotStatus st = client.CachedStatus();
        return st.in_sync && st.shown_emotion == want && st.commanded_emotion == want;
      },
      timeout);
  return ok ? std::chrono::duration<double, std::milli>(Clock::now() - start).count() : -1;
}

TEST(PleoSimTcp, BridgeCommandsAndMbpollSeesTheShownEmotion) {
  TempDir dir;
  TcpSim sim(dir);
  ASSERT_TRUE(sim.Start()) << ReadFile(dir.File("sim.log"));
  auto client = RobotClient::Create(TcpConfig(sim.port));
  ASSERT_TRUE(client.ok()) << client.status();
  auto r = (*client)->SetEmotion(2, 850, {.timeout_ms = 3000, .wait_shown = true});
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_TRUE(r->shown);
  auto regs = ParseMbpoll(MbpollTcp(sim.port, "-t 3 -r 0 -c 3 127.0.0.1"));
  ASSERT_EQ(regs.size(), 3u);
  EXPECT_EQ(regs[0].second, 2);    // SHOWN_EMOTION angry
  EXPECT_EQ(regs[1].second, 850);  // SHOWN_INTENSITY
  EXPECT_EQ(regs[2].second, r->sequence);
}

TEST(PleoSimTcp, MbpollCommandsAndTheBridgeReadsIt) {
  TempDir dir;
  TcpSim sim(dir);
  ASSERT_TRUE(sim.Start());
  int rc = -1;
  std::string out = MbpollTcp(sim.port, "-t 4 -r 0 127.0.0.1 1 300 77", &rc);
  ASSERT_EQ(rc, 0) << out;
  auto client = RobotClient::Create(TcpConfig(sim.port));
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE(WaitUntil([&] {
    auto st = (*client)->ReadStatus();
    return st.ok() && st->shown_emotion == Emotion::kHappy && st->state == RobotState::kFollowing;
  })) << (*client)->CachedStatus().last_error;
  auto st = (*client)->ReadStatus();
  ASSERT_TRUE(st.ok());
  EXPECT_EQ(st->applied_sequence, 77);
  EXPECT_EQ(st->shown_intensity_permille, 300);
  // Out-of-range values written by a third party are refused by the firmware.
  out = MbpollTcp(sim.port, "-t 4 -r 0 127.0.0.1 9", &rc);
  EXPECT_NE(rc, 0);
  EXPECT_NE(out.find("Illegal data value"), std::string::npos) << out;
  // A fresh bridge continues numbering after 77.
  auto r = (*client)->SetEmotion(0, 0);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->sequence, 78);
}

TEST(PleoSimTcp, ManyClientsAtOnce) {
  TempDir dir;
  TcpSim sim(dir);
  ASSERT_TRUE(sim.Start());
  std::vector<std::unique_ptr<RobotClient>> clients;
  for (int i = 0; i < 8; ++i) {
    RobotConfig c = TcpConfig(sim.port);
    c.name = "reader" + std::to_string(i);
    auto client = RobotClient::Create(c);
    ASSERT_TRUE(client.ok());
    clients.push_back(std::move(*client));
  }
  for (auto& c : clients) ASSERT_TRUE(c->ReadStatus().ok());  // all connected at once
  auto r = clients[0]->SetEmotion(1, 500, {.timeout_ms = 3000, .wait_shown = true});
  ASSERT_TRUE(r.ok()) << r.status();
  for (auto& c : clients) {
    auto st = c->ReadStatus();
    ASSERT_TRUE(st.ok()) << st.status();
    EXPECT_EQ(st->shown_emotion, Emotion::kHappy);
  }
}

TEST(PleoSimTcp, RestartMidStreamEndsInTheLastCommandedState) {
  TempDir dir;
  TcpSim sim(dir);
  ASSERT_TRUE(sim.Start());
  auto client = RobotClient::Create(TcpConfig(sim.port));
  ASSERT_TRUE(client.ok());
  (*client)->Start();
  std::atomic<bool> stop{false};
  std::atomic<int> ok{0}, failed{0};
  std::atomic<int> last{0};
  std::thread commander([&] {
    for (int i = 0; !stop; ++i) {
      int e = i % 3;
      last = e;
      auto r = (*client)->SetEmotion(e, 100 + i % 900, {.timeout_ms = 300});
      (r.ok() ? ok : failed)++;
      if (!r.ok()) {
        EXPECT_TRUE(absl::IsUnavailable(r.status()) || absl::IsDeadlineExceeded(r.status()) ||
                    absl::IsAborted(r.status()))
            << r.status();
      }
    }
  });
  ASSERT_TRUE(WaitUntil([&] { return ok.load() >= 20; }));
  sim.child.Stop(SIGKILL);  // the robot dies mid-stream
  ASSERT_TRUE(WaitUntil([&] { return failed.load() >= 2; }));
  ASSERT_TRUE(sim.Start()) << ReadFile(dir.File("sim.log"));  // same port
  const int before = ok.load();
  ASSERT_TRUE(WaitUntil([&] { return ok.load() >= before + 10; }));
  stop = true;
  commander.join();
  const double recovery_ms = WaitInSync(**client, static_cast<Emotion>(last.load()));
  EXPECT_GE(recovery_ms, 0) << (*client)->CachedStatus().last_error;
  std::printf("restart: commands ok=%d failed=%d, in sync %.0f ms after the last command\n",
              ok.load(), failed.load(), recovery_ms);
  // Now the robot dies after the last command and comes back empty.
  ASSERT_TRUE((*client)->SetEmotion(1, 640, {.timeout_ms = 2000}).ok());
  sim.child.Stop(SIGKILL);
  ASSERT_TRUE(sim.Start());
  const auto back = Clock::now();
  const double ms = WaitInSync(**client, Emotion::kHappy);
  ASSERT_GE(ms, 0) << (*client)->CachedStatus().last_error;
  const double since_back =
      std::chrono::duration<double, std::milli>(Clock::now() - back).count();
  std::printf("restart: robot shows the last command %.0f ms after it came back (target 2000)\n",
              since_back);
  auto regs = ParseMbpoll(MbpollTcp(sim.port, "-t 3 -r 0 -c 2 127.0.0.1"));
  ASSERT_EQ(regs.size(), 2u);
  EXPECT_EQ(regs[0].second, 1);
  EXPECT_EQ(regs[1].second, 640);
  EXPECT_GE((*client)->CachedStatus().resends, 1u);
  (*client)->Stop();
}

// Sets a pleo_sim fault through its control registers.
void SetFault(int port, SimFault fault, int delay_ms, int count) {
  int rc = -1;
  std::string out = MbpollTcp(port, "-t 4 -r 100 127.0.0.1 " +
                                        std::to_string(static_cast<int>(fault)) + " " +
                                        std::to_string(delay_ms) + " " + std::to_string(count),
                              &rc);
  ASSERT_EQ(rc, 0) << out;
}

TEST(PleoSimTcp, ClosedSocketsSlowAnswersAndGarbageAreSurvived) {
  TempDir dir;
  TcpSim sim(dir);
  ASSERT_TRUE(sim.Start());
  auto client = RobotClient::Create(TcpConfig(sim.port));
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE((*client)->SetEmotion(0, 0).ok());
  (*client)->Start();
  struct Case {
    SimFault fault;
    int delay_ms;
    int count;
  };
  const Case cases[] = {{SimFault::kDrop, 0, 3},     {SimFault::kDelay, 400, 3},
                        {SimFault::kCorrupt, 0, 3},  {SimFault::kNoise, 0, 3},
                        {SimFault::kBusy, 0, 6},     {SimFault::kSilent, 0, 3},
                        {SimFault::kDrop, 0, 0}};
  int e = 1;
  for (const Case& c : cases) {
    SetFault(sim.port, c.fault, c.delay_ms, c.count);
    auto r = (*client)->SetEmotion(e, 500, {.timeout_ms = 1500});
    // Either it got through on a retry, or it failed clearly and stays pending.
    if (!r.ok()) {
      EXPECT_TRUE(absl::IsUnavailable(r.status()) || absl::IsDeadlineExceeded(r.status()))
          << r.status();
      EXPECT_FALSE(r.status().message().empty());
    }
    if (c.count == 0) SetFault(sim.port, SimFault::kNone, 0, 0);  // "until cleared"
    const double ms = WaitInSync(**client, static_cast<Emotion>(e));
    EXPECT_GE(ms, 0) << SimFaultName(c.fault) << ": " << (*client)->CachedStatus().last_error;
    std::printf("fault %-7s: SetEmotion %s; in sync %.0f ms later\n",
                std::string(SimFaultName(c.fault)).c_str(),
                r.ok() ? "succeeded" : std::string(r.status().message()).c_str(), ms);
    e = (e + 1) % 3;
  }
  (*client)->Stop();
}

TEST(PleoSimTcp, WatchdogFallsBackToAutonomyWithoutHeartbeat) {
  TempDir dir;
  TcpSim sim(dir, {"--autonomous-period-ms", "50"});
  ASSERT_TRUE(sim.Start());
  RobotConfig c = TcpConfig(sim.port);
  c.watchdog_ms = 300;
  c.heartbeat_interval_ms = 100;
  auto client = RobotClient::Create(c);
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE((*client)->SetEmotion(2, 500, {.timeout_ms = 2000, .wait_shown = true}).ok());
  // No heartbeat thread: the robot goes autonomous.
  ASSERT_TRUE(WaitUntil([&] {
    auto st = (*client)->ReadStatus();
    return st.ok() && st->state == RobotState::kAutonomous &&
           (st->fault_flags & kFaultWatchdogExpired) != 0;
  }));
  (*client)->Start();
  EXPECT_GE(WaitInSync(**client, Emotion::kAngry), 0);
  EXPECT_EQ((*client)->CachedStatus().fault_flags & kFaultWatchdogExpired, 0);
  (*client)->Stop();
}

TEST(PleoSimTcp, BatteryDrainsAndEmptyBatterySleeps) {
  TempDir dir;
  TcpSim sim(dir, {"--battery-permille", "160", "--drain-permille-per-min", "6000"});
  ASSERT_TRUE(sim.Start());
  auto client = RobotClient::Create(TcpConfig(sim.port));
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE(WaitUntil([&] {
    auto st = (*client)->ReadStatus();
    return st.ok() && (st->fault_flags & kFaultBatteryLow) != 0;
  }));
  ASSERT_TRUE(WaitUntil([&] {
    auto st = (*client)->ReadStatus();
    return st.ok() && st->state == RobotState::kSleeping && st->battery_permille == 0;
  }));
  // Commands are acknowledged but not shown while asleep.
  auto r = (*client)->SetEmotion(1, 500, {.timeout_ms = 600, .wait_shown = true});
  EXPECT_TRUE(absl::IsDeadlineExceeded(r.status())) << r.status();
  EXPECT_NE(r.status().message().find("sleeping"), absl::string_view::npos) << r.status();
}

TEST(PleoSimTcp, TouchSensorsAreDiscreteInputs) {
  TempDir dir;
  TcpSim sim(dir);
  ASSERT_TRUE(sim.Start());
  int rc = -1;
  MbpollTcp(sim.port, "-t 4 -r 103 127.0.0.1 5", &rc);  // head + back
  ASSERT_EQ(rc, 0);
  auto client = RobotClient::Create(TcpConfig(sim.port));
  ASSERT_TRUE(client.ok());
  auto st = (*client)->ReadStatus();
  ASSERT_TRUE(st.ok());
  EXPECT_EQ(st->touch_mask, 5);
  auto bits = ParseMbpoll(MbpollTcp(sim.port, "-t 1 -r 0 -c 8 127.0.0.1"));
  ASSERT_EQ(bits.size(), 8u);
  EXPECT_EQ(bits[0].second, 1);
  EXPECT_EQ(bits[1].second, 0);
  EXPECT_EQ(bits[2].second, 1);
}

struct RtuRig {
  TempDir dir;
  std::optional<PtyPair> ptys;
  Child sim;

  bool StartSim(std::vector<std::string> extra = {}) {
    std::vector<std::string> argv = {kPleoSim, "--rtu", ptys->a, "--baud", "115200",
                                     "--switch-ms", "100", "-v"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    sim = Child::Start(argv, dir.File("sim.log"));
    return WaitUntil([&] { return ReadFile(dir.File("sim.log")).find("serving rtu") !=
                                  std::string::npos; });
  }
  bool Start() {
    ptys = PtyPair::Start(dir);
    return ptys && StartSim();
  }
};

TEST(PleoSimRtu, BridgeOverASerialLineAndMbpollReadsIt) {
  RtuRig rig;
  ASSERT_TRUE(rig.Start()) << ReadFile(rig.dir.File("socat.log"));
  {
    auto client = RobotClient::Create(RtuConfig(rig.ptys->b));
    ASSERT_TRUE(client.ok());
    // Ready when a Modbus read succeeds.
    ASSERT_TRUE(WaitUntil([&] { return (*client)->ReadStatus().ok(); }))
        << (*client)->CachedStatus().last_error;
    auto r = (*client)->SetEmotion(1, 420, {.timeout_ms = 3000, .wait_shown = true});
    ASSERT_TRUE(r.ok()) << r.status();
    EXPECT_TRUE(r->shown);
  }  // closes the serial port
  int rc = -1;
  std::string out = testing::Run("/usr/bin/mbpoll -m rtu -b 115200 -P none -a 1 -0 -1 -t 3 -r 0 -c 2 " +
                            rig.ptys->b,
                        &rc);
  ASSERT_EQ(rc, 0) << out;
  auto regs = ParseMbpoll(out);
  ASSERT_EQ(regs.size(), 2u);
  EXPECT_EQ(regs[0].second, 1);
  EXPECT_EQ(regs[1].second, 420);
}

TEST(PleoSimRtu, GarbageOnTheLineAndASimRestartAreSurvived) {
  RtuRig rig;
  ASSERT_TRUE(rig.Start());
  auto client = RobotClient::Create(RtuConfig(rig.ptys->b));
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE(WaitUntil([&] { return (*client)->ReadStatus().ok(); }));
  (*client)->Start();

  // 1. Line noise written onto the bus by a third party while commanding.
  int noise_fd = open(rig.ptys->b.c_str(), O_WRONLY | O_NOCTTY);
  ASSERT_GE(noise_fd, 0);
  std::atomic<bool> stop{false};
  std::thread noise([&] {
    std::minstd_rand rng(7);
    uint8_t buf[24];
    while (!stop) {
      for (uint8_t& b : buf) b = static_cast<uint8_t>(rng());
      ssize_t n = write(noise_fd, buf, sizeof(buf));
      (void)n;
      std::this_thread::sleep_for(std::chrono::milliseconds(30));
    }
  });
  int ok = 0, failed = 0;
  for (int i = 0; i < 30; ++i) {
    auto r = (*client)->SetEmotion(i % 3, 500, {.timeout_ms = 1000});
    (r.ok() ? ok : failed)++;
  }
  stop = true;
  noise.join();
  close(noise_fd);
  std::printf("rtu noise: %d commands ok, %d failed while garbage was on the line\n", ok, failed);
  EXPECT_GT(ok, 0);
  EXPECT_GE(WaitInSync(**client, Emotion::kAngry), 0) << (*client)->CachedStatus().last_error;

  // 2. The firmware's own corrupted answers (bad CRC).
  (*client)->Stop();
  {
    LinkOptions o;
    o.endpoint = RtuConfig(rig.ptys->b).link.endpoint;
    auto raw = NewLibmodbusLink(o);
    ASSERT_TRUE(raw->Connect().ok());
    const std::array<uint16_t, 3> ctl = {static_cast<uint16_t>(SimFault::kCorrupt), 0, 3};
    ASSERT_TRUE(raw->WriteRegisters(reg::kSimFaultMode, ctl).ok());
  }
  (*client)->Start();
  auto r = (*client)->SetEmotion(0, 100, {.timeout_ms = 2000});
  EXPECT_TRUE(r.ok()) << r.status();
  EXPECT_GE(WaitInSync(**client, Emotion::kNeutral), 0) << (*client)->CachedStatus().last_error;

  // 3. The firmware restarts (empty registers) after the last command.
  ASSERT_TRUE((*client)->SetEmotion(2, 900, {.timeout_ms = 2000}).ok());
  rig.sim.Stop(SIGKILL);
  ASSERT_TRUE(WaitUntil([&] { return !(*client)->CachedStatus().last_error.empty(); }));
  ASSERT_TRUE(rig.StartSim());
  const auto back = Clock::now();
  ASSERT_GE(WaitInSync(**client, Emotion::kAngry), 0) << (*client)->CachedStatus().last_error;
  std::printf("rtu restart: last command shown %.0f ms after the firmware came back\n",
              std::chrono::duration<double, std::milli>(Clock::now() - back).count());
  (*client)->Stop();
}

TEST(Pymodbus, BridgeDrivesAnIndependentModbusServer) {
  TempDir dir;
  std::string port_file = dir.File("pymodbus.port");
  Child server = Child::Start({"/usr/bin/python3", kPymodbusScript, port_file},
                              dir.File("pymodbus.log"));
  const int port = WaitForPortFile(port_file, std::chrono::seconds(30));
  ASSERT_GT(port, 0) << ReadFile(dir.File("pymodbus.log"));
  RobotConfig c = TcpConfig(port);
  c.map.watchdog = reg::kWatchdogMs;
  auto client = RobotClient::Create(c);
  ASSERT_TRUE(client.ok());
  for (int e : {1, 2, 0, 2}) {
    auto r = (*client)->SetEmotion(e, 250 * e, {.timeout_ms = 3000, .wait_shown = true});
    ASSERT_TRUE(r.ok()) << r.status() << "\n" << ReadFile(dir.File("pymodbus.log"));
    auto st = (*client)->ReadStatus();
    ASSERT_TRUE(st.ok()) << st.status();
    EXPECT_EQ(st->shown_emotion, static_cast<Emotion>(e));
    EXPECT_EQ(st->applied_sequence, r->sequence);
    EXPECT_EQ(st->firmware_version, 0x0100);
  }
  // Heartbeats and status refreshes work against it too.
  EXPECT_TRUE((*client)->HeartbeatOnce().ok()) << (*client)->CachedStatus().last_error;
  EXPECT_TRUE((*client)->CachedStatus().in_sync);
}

}  // namespace
}  // namespace kinemo::robot
