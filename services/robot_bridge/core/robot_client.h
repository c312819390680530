// RobotClient: one robot reached over one ModbusLink.
//
// - SetEmotion validates values before anything is written, writes
//   [emotion, intensity, sequence] in one request, verifies by reading back,
//   waits for the firmware's acknowledgement (APPLIED_SEQUENCE), and retries
//   with exponential backoff using the *same* sequence number (idempotent).
// - A heartbeat thread feeds the robot's watchdog, refreshes the status,
//   reconnects after loss (with backoff) and reconciles: if the robot lost the
//   last command (reboot, outage) it is written again, so the robot ends in
//   the last commanded state once it is back.
// Thread-safe: any number of threads may call any method.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "common/status/status.h"
#include "services/robot_bridge/core/modbus_link.h"
#include "services/robot_bridge/core/register_map.h"

namespace kinemo::robot {

struct RetryPolicy {
  int max_attempts = 4;          // 1 = no retry
  int initial_backoff_ms = 10;
  int max_backoff_ms = 200;
  double multiplier = 2.0;
};

// Base addresses of the register blocks (docs/robot_bridge_registers.md);
// a robot whose board puts them elsewhere only changes these.
struct RegisterMapConfig {
  int command_base = reg::kCmdEmotion;   // holding: emotion, intensity, sequence
  int heartbeat = reg::kHeartbeat;       // holding
  int watchdog = reg::kWatchdogMs;       // holding; < 0 = do not configure
  int status_base = reg::kShownEmotion;  // input: 11 registers
  int touch_base = reg::kTouchBase;      // discrete inputs
  int touch_count = reg::kTouchCount;    // 0 = robot has no touch sensors
};

struct RobotConfig {
  std::string name;  // unique, [A-Za-z0-9_.-]+
  LinkOptions link;
  RetryPolicy retry;
  RegisterMapConfig map;
  int ack_timeout_ms = 500;          // wait for APPLIED_SEQUENCE == sequence
  int heartbeat_interval_ms = 500;   // HEARTBEAT write period
  int status_poll_interval_ms = 200; // status refresh + reconciliation period
  int watchdog_ms = 2000;            // written to WATCHDOG_MS on connect (0 = off)
  int reconnect_backoff_initial_ms = 50;
  int reconnect_backoff_max_ms = 500;
  bool verify_readback = true;
};

Status ValidateRobotConfig(const RobotConfig& config);

// What the bridge knows about a robot.
struct RobotStatus {
  std::string name;
  std::string endpoint;  // Describe() of the link
  bool connected = false;
  // From the robot (valid when `has_robot_data`).
  bool has_robot_data = false;
  Emotion shown_emotion = Emotion::kNeutral;
  uint16_t shown_intensity_permille = 0;
  Emotion target_emotion = Emotion::kNeutral;
  uint16_t applied_sequence = 0;
  RobotState state = RobotState::kAutonomous;
  uint16_t battery_permille = 0;
  uint16_t fault_flags = 0;
  uint16_t firmware_version = 0;
  uint32_t uptime_s = 0;
  uint8_t touch_mask = 0;  // bit i = kTouchNames[i]
  // Bridge side.
  bool has_command = false;
  Emotion commanded_emotion = Emotion::kNeutral;
  uint16_t commanded_intensity_permille = 0;
  uint16_t commanded_sequence = 0;
  bool in_sync = false;  // robot shows the commanded emotion and acknowledged it
  std::string last_error;  // empty when the last exchange succeeded
  std::chrono::system_clock::time_point updated{};
  uint64_t reconnects = 0;
  uint64_t resends = 0;  // commands re-sent by reconciliation
};

struct CommandOptions {
  int timeout_ms = 2000;    // whole call, retries included
  bool wait_shown = false;  // also wait until SHOWN_EMOTION == emotion, following
};

struct CommandResult {
  uint16_t sequence = 0;
  int attempts = 0;
  bool shown = false;  // the robot was seen showing it before returning
};

class RobotClient {
 public:
  // The client owns `link`. Does not connect; call Start() for the heartbeat.
  RobotClient(RobotConfig config, std::unique_ptr<ModbusLink> link);
  ~RobotClient();
  RobotClient(const RobotClient&) = delete;
  RobotClient& operator=(const RobotClient&) = delete;

  // Builds the client with a libmodbus link after validating `config`.
  static StatusOr<std::unique_ptr<RobotClient>> Create(RobotConfig config);

  const std::string& name() const { return config_.name; }
  const RobotConfig& config() const { return config_; }

  // Starts / stops the heartbeat thread. Stop() is idempotent.
  void Start();
  void Stop();

  // INVALID_ARGUMENT (nothing written) when emotion is not 0..2 or intensity
  // not 0..1000; UNAVAILABLE when the robot cannot be reached within the
  // timeout (the command stays pending: the heartbeat keeps trying);
  // ABORTED when a newer command superseded this one during retries;
  // DATA_LOSS when the read-back disagreed on every attempt;
  // DEADLINE_EXCEEDED when wait_shown and the animation did not show in time.
  StatusOr<CommandResult> SetEmotion(int emotion, int intensity_permille,
                                     const CommandOptions& options = {});

  // Reads the robot now (connects if needed). UNAVAILABLE if unreachable.
  StatusOr<RobotStatus> ReadStatus();
  // The last known status, without touching the link.
  RobotStatus CachedStatus() const;

  // One heartbeat tick (what the thread does each period). Public for tests.
  Status HeartbeatOnce();

  // Calls `fn` on the heartbeat thread after every refresh. `fn` must be
  // quick and must not call Unsubscribe. After Unsubscribe returns, `fn` is
  // not running and will not be called again.
  int Subscribe(std::function<void(const RobotStatus&)> fn);
  void Unsubscribe(int id);

 private:
  using Clock = std::chrono::steady_clock;
  struct Command {
    uint16_t emotion = 0;
    uint16_t intensity = 0;
    uint16_t sequence = 0;
  };

  Status EnsureConnectedLocked();
  Status WriteCommandLocked(const Command& cmd, Clock::time_point deadline);
  Status ReadRobotLocked();  // updates status_ robot fields
  uint16_t NextSequenceLocked();
  void RecordError(const Status& s, bool connected);
  void Publish();
  void HeartbeatLoop();

  const RobotConfig config_;
  std::unique_ptr<ModbusLink> link_;

  // Guards link_ and the sequence bookkeeping.
  mutable std::mutex link_mu_;
  uint16_t last_sequence_ = 0;
  uint16_t robot_applied_ = 0;
  uint16_t heartbeat_counter_ = 0;
  bool use_write_and_read_ = true;  // FC 23 until the device refuses it
  bool ever_connected_ = false;
  int reconnect_backoff_ms_ = 0;
  Clock::time_point next_connect_attempt_{};
  Clock::time_point last_heartbeat_{};

  // Guards status_ and desired_.
  mutable std::mutex state_mu_;
  RobotStatus status_;
  std::optional<Command> desired_;
  uint64_t desired_generation_ = 0;  // bumped by each SetEmotion

  std::mutex subscribers_mu_;
  std::map<int, std::function<void(const RobotStatus&)>> subscribers_;
  int next_subscriber_id_ = 1;

  std::mutex thread_mu_;
  std::condition_variable thread_cv_;
  bool stop_ = false;
  std::thread thread_;
};

}  // namespace kinemo::robot
