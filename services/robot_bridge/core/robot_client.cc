#include "services/robot_bridge/core/robot_client.h"

#include <algorithm>
#include <array>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "services/robot_bridge/core/errors.h"

namespace kinemo::robot {

namespace {

bool IsRetryable(const Status& s) {
  return absl::IsUnavailable(s) || absl::IsDataLoss(s) || absl::IsDeadlineExceeded(s);
}

bool ValidName(std::string_view n) {
  if (n.empty() || n.size() > 64) return false;
  return std::all_of(n.begin(), n.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
           c == '_' || c == '-' || c == '.';
  });
}

}  // namespace

Status ValidateRobotConfig(const RobotConfig& c) {
  if (!ValidName(c.name)) {
    return BadField("name", "'", c.name, "' must be 1..64 characters of [A-Za-z0-9_.-]");
  }
  Status s = ValidateLinkOptions(c.link);
  if (!s.ok()) return Context(s, absl::StrCat("robot '", c.name, "'"));
  auto bad = [&](std::string_view field, auto value, std::string_view range) {
    return BadField(absl::StrCat("robot '", c.name, "' ", AV(field)), value, " is outside ",
                        AV(range));
  };
  if (c.retry.max_attempts < 1 || c.retry.max_attempts > 100) {
    return bad("retry.max_attempts", c.retry.max_attempts, "1..100");
  }
  if (c.retry.initial_backoff_ms < 0 || c.retry.initial_backoff_ms > 60000) {
    return bad("retry.initial_backoff_ms", c.retry.initial_backoff_ms, "0..60000");
  }
  if (c.retry.max_backoff_ms < c.retry.initial_backoff_ms || c.retry.max_backoff_ms > 60000) {
    return bad("retry.max_backoff_ms", c.retry.max_backoff_ms, "initial_backoff_ms..60000");
  }
  if (c.retry.multiplier < 1.0 || c.retry.multiplier > 10.0) {
    return bad("retry.multiplier", c.retry.multiplier, "1..10");
  }
  if (c.ack_timeout_ms < 1 || c.ack_timeout_ms > 60000) {
    return bad("ack_timeout_ms", c.ack_timeout_ms, "1..60000");
  }
  if (c.heartbeat_interval_ms < 10 || c.heartbeat_interval_ms > 60000) {
    return bad("heartbeat_interval_ms", c.heartbeat_interval_ms, "10..60000");
  }
  if (c.status_poll_interval_ms < 10 || c.status_poll_interval_ms > 60000) {
    return bad("status_poll_interval_ms", c.status_poll_interval_ms, "10..60000");
  }
  if (c.watchdog_ms != 0 && (c.watchdog_ms < kWatchdogMinMs || c.watchdog_ms > kWatchdogMaxMs)) {
    return bad("watchdog_ms", c.watchdog_ms, "0 or 100..60000");
  }
  if (c.watchdog_ms != 0 && c.watchdog_ms <= c.heartbeat_interval_ms) {
    return BadField(absl::StrCat("robot '", c.name, "' watchdog_ms"), c.watchdog_ms,
                        " must exceed heartbeat_interval_ms (", c.heartbeat_interval_ms, ")");
  }
  if (c.reconnect_backoff_initial_ms < 1 ||
      c.reconnect_backoff_max_ms < c.reconnect_backoff_initial_ms ||
      c.reconnect_backoff_max_ms > 60000) {
    return bad("reconnect_backoff_max_ms", c.reconnect_backoff_max_ms,
               "reconnect_backoff_initial_ms..60000");
  }
  const RegisterMapConfig& m = c.map;
  for (auto [field, v] : {std::pair<std::string_view, int>{"map.command_base", m.command_base},
                          {"map.heartbeat", m.heartbeat},
                          {"map.status_base", m.status_base},
                          {"map.touch_base", m.touch_base}}) {
    if (v < 0 || v > 65535 - 16) return bad(field, v, "0..65519");
  }
  if (m.watchdog > 65535) return bad("map.watchdog", m.watchdog, "-1..65535");
  if (m.touch_count < 0 || m.touch_count > 8) return bad("map.touch_count", m.touch_count, "0..8");
  return absl::OkStatus();
}

RobotClient::RobotClient(RobotConfig config, std::unique_ptr<ModbusLink> link)
    : config_(std::move(config)), link_(std::move(link)) {
  status_.name = config_.name;
  status_.endpoint = link_->Describe();
  status_.last_error = "not connected yet";
  reconnect_backoff_ms_ = config_.reconnect_backoff_initial_ms;
}

RobotClient::~RobotClient() { Stop(); }

StatusOr<std::unique_ptr<RobotClient>> RobotClient::Create(RobotConfig config) {
  KINEMO_RETURN_IF_ERROR(ValidateRobotConfig(config));
  auto link = NewLibmodbusLink(config.link);
  return std::make_unique<RobotClient>(std::move(config), std::move(link));
}

void RobotClient::Start() {
  std::lock_guard<std::mutex> lock(thread_mu_);
  if (thread_.joinable()) return;
  stop_ = false;
  thread_ = std::thread([this] { HeartbeatLoop(); });
}

void RobotClient::Stop() {
  {
    std::lock_guard<std::mutex> lock(thread_mu_);
    stop_ = true;
  }
  thread_cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void RobotClient::HeartbeatLoop() {
  std::unique_lock<std::mutex> lock(thread_mu_);
  while (!stop_) {
    lock.unlock();
    (void)HeartbeatOnce();
    int wait_ms;
    {
      std::lock_guard<std::mutex> l(link_mu_);
      const int tick_ms = std::min(config_.heartbeat_interval_ms, config_.status_poll_interval_ms);
      wait_ms = link_->IsConnected() ? tick_ms : std::min(reconnect_backoff_ms_, tick_ms);
    }
    lock.lock();
    thread_cv_.wait_for(lock, std::chrono::milliseconds(wait_ms), [this] { return stop_; });
  }
}

uint16_t RobotClient::NextSequenceLocked() {
  uint16_t s = last_sequence_;
  do {
    s = static_cast<uint16_t>(s + 1);
  } while (s == 0 || s == robot_applied_);
  last_sequence_ = s;
  return s;
}

Status RobotClient::EnsureConnectedLocked() {
  if (link_->IsConnected()) return absl::OkStatus();
  Status s = link_->Connect();
  if (!s.ok()) return s;
  // Configure the watchdog and learn where the robot's sequence numbers are.
  if (config_.map.watchdog >= 0) {
    s = link_->WriteRegister(config_.map.watchdog, static_cast<uint16_t>(config_.watchdog_ms));
  }
  std::array<uint16_t, 3> cmd{};
  std::array<uint16_t, reg::kInputCount> in{};
  if (s.ok()) s = link_->ReadHoldingRegisters(config_.map.command_base, cmd);
  if (s.ok()) s = link_->ReadInputRegisters(config_.map.status_base, in);
  if (!s.ok()) {
    link_->Close();
    return Context(s, "while initialising the connection");
  }
  robot_applied_ = in[reg::kAppliedSequence];
  {
    std::lock_guard<std::mutex> l(state_mu_);
    if (!desired_) {
      // A fresh bridge continues after whatever the robot has seen.
      last_sequence_ = std::max({last_sequence_, cmd[2], robot_applied_});
    } else if ((cmd[2] == desired_->sequence || robot_applied_ == desired_->sequence) &&
               (cmd[0] != desired_->emotion || cmd[1] != desired_->intensity)) {
      // The robot already used our number for something else (another
      // bridge before us): the pending command needs a fresh one.
      last_sequence_ = std::max({last_sequence_, cmd[2], robot_applied_});
      desired_->sequence = NextSequenceLocked();
      status_.commanded_sequence = desired_->sequence;
    }
    if (ever_connected_) ++status_.reconnects;
    status_.connected = true;
  }
  ever_connected_ = true;
  reconnect_backoff_ms_ = config_.reconnect_backoff_initial_ms;
  return absl::OkStatus();
}

Status RobotClient::WriteCommandLocked(const Command& cmd, Clock::time_point deadline) {
  const std::array<uint16_t, 3> values = {cmd.emotion, cmd.intensity, cmd.sequence};
  std::array<uint16_t, 3> back{};
  bool read_back = false;
  if (config_.verify_readback && use_write_and_read_) {
    // One transaction: write the command, read it back (FC 23).
    Status s = link_->WriteAndReadRegisters(config_.map.command_base, values,
                                            config_.map.command_base, back);
    if (absl::IsFailedPrecondition(s)) {
      use_write_and_read_ = false;  // the device lacks FC 23: two transactions from now on
    } else {
      KINEMO_RETURN_IF_ERROR(s);
      read_back = true;
    }
  }
  if (!read_back) {
    KINEMO_RETURN_IF_ERROR(link_->WriteRegisters(config_.map.command_base, values));
    if (config_.verify_readback) {
      KINEMO_RETURN_IF_ERROR(link_->ReadHoldingRegisters(config_.map.command_base, back));
    }
  }
  if (config_.verify_readback) {
    if (back != values) {
      return absl::DataLossError(absl::StrCat(
          link_->Describe(), ": read-back mismatch: wrote [", values[0], ", ", values[1], ", ",
          values[2], "], read [", back[0], ", ", back[1], ", ", back[2], "]"));
    }
  }
  const auto ack_deadline =
      std::min(deadline, Clock::now() + std::chrono::milliseconds(config_.ack_timeout_ms));
  uint16_t applied = 0;
  for (int poll = 0;; ++poll) {
    KINEMO_RETURN_IF_ERROR(
        link_->ReadInputRegisters(config_.map.status_base + reg::kAppliedSequence, {&applied, 1}));
    if (applied == cmd.sequence) break;
    if (Clock::now() >= ack_deadline) {
      return absl::DeadlineExceededError(absl::StrCat(
          link_->Describe(), ": robot did not acknowledge sequence ", cmd.sequence, " within ",
          config_.ack_timeout_ms, " ms (APPLIED_SEQUENCE is ", applied, ")"));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(std::min(poll + 1, 10)));
  }
  robot_applied_ = applied;
  return absl::OkStatus();
}

StatusOr<CommandResult> RobotClient::SetEmotion(int emotion, int intensity_permille,
                                                const CommandOptions& options) {
  if (emotion < 0 || emotion >= kEmotionCount) {
    return BadField("emotion", emotion, " is not a known emotion (0 neutral, 1 happy, 2 angry)");
  }
  if (intensity_permille < 0 || intensity_permille > kIntensityMaxPermille) {
    return BadField("intensity_permille", intensity_permille, " is outside 0..1000");
  }
  if (options.timeout_ms < 1 || options.timeout_ms > 600000) {
    return BadField("timeout_ms", options.timeout_ms, " is outside 1..600000");
  }
  const auto deadline = Clock::now() + std::chrono::milliseconds(options.timeout_ms);
  Command cmd{static_cast<uint16_t>(emotion), static_cast<uint16_t>(intensity_permille), 0};
  uint64_t generation;
  {
    std::lock_guard<std::mutex> l(link_mu_);
    // A fresh client learns the robot's numbering first when it is
    // reachable; failures are handled by the attempts below.
    if (!ever_connected_) (void)EnsureConnectedLocked();
    cmd.sequence = NextSequenceLocked();
    std::lock_guard<std::mutex> s(state_mu_);
    generation = ++desired_generation_;
    desired_ = cmd;
    status_.has_command = true;
    status_.commanded_emotion = static_cast<Emotion>(cmd.emotion);
    status_.commanded_intensity_permille = cmd.intensity;
    status_.commanded_sequence = cmd.sequence;
    status_.in_sync = false;
  }

  CommandResult result;
  result.sequence = cmd.sequence;
  Status last;
  bool connected = false;
  int backoff_ms = config_.retry.initial_backoff_ms;
  for (int attempt = 1; attempt <= config_.retry.max_attempts; ++attempt) {
    result.attempts = attempt;
    {
      std::lock_guard<std::mutex> l(link_mu_);
      {
        std::lock_guard<std::mutex> s(state_mu_);
        if (!desired_ || desired_generation_ != generation) {
          return absl::AbortedError(absl::StrCat("robot '", config_.name, "': sequence ",
                                                 cmd.sequence, " superseded by sequence ",
                                                 desired_ ? desired_->sequence : 0));
        }
      }
      last = EnsureConnectedLocked();
      {
        // Connecting may have renumbered the pending command.
        std::lock_guard<std::mutex> s(state_mu_);
        cmd.sequence = desired_->sequence;
        result.sequence = cmd.sequence;
      }
      if (last.ok()) last = WriteCommandLocked(cmd, deadline);
      connected = link_->IsConnected();
    }
    if (last.ok()) break;
    RecordError(last, connected);
    if (!IsRetryable(last) || attempt == config_.retry.max_attempts) break;
    auto wake = Clock::now() + std::chrono::milliseconds(backoff_ms);
    if (wake >= deadline) break;
    std::this_thread::sleep_until(wake);
    backoff_ms = std::min(config_.retry.max_backoff_ms,
                          static_cast<int>(backoff_ms * config_.retry.multiplier));
  }
  if (!last.ok()) {
    return Status(last.code(), absl::StrCat("robot '", config_.name, "': set emotion ",
                                            AV(EmotionName(static_cast<Emotion>(emotion))),
                                            " failed after ", result.attempts,
                                            " attempt(s): ", last.message()));
  }
  {
    std::lock_guard<std::mutex> s(state_mu_);
    status_.last_error.clear();
    status_.connected = true;
    status_.applied_sequence = cmd.sequence;
    status_.updated = std::chrono::system_clock::now();
  }
  Publish();  // watchers see the new command at once
  if (!options.wait_shown) return result;

  for (int poll = 0;; ++poll) {
    StatusOr<RobotStatus> st = ReadStatus();
    if (st.ok() && st->shown_emotion == static_cast<Emotion>(cmd.emotion) &&
        st->state == RobotState::kFollowing && st->applied_sequence == cmd.sequence) {
      result.shown = true;
      return result;
    }
    if (Clock::now() >= deadline) {
      std::string what = st.ok() ? absl::StrCat("robot shows ", AV(EmotionName(st->shown_emotion)),
                                                 ", state ", AV(RobotStateName(st->state)))
                                 : std::string(st.status().message());
      return absl::DeadlineExceededError(
          absl::StrCat("robot '", config_.name, "': sequence ", cmd.sequence, " acknowledged but ",
                       AV(EmotionName(static_cast<Emotion>(emotion))), " not shown within ",
                       options.timeout_ms, " ms: ", what));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(std::min(2 * (poll + 1), 20)));
  }
}

Status RobotClient::ReadRobotLocked() {
  std::array<uint16_t, reg::kInputCount> in{};
  std::array<uint8_t, reg::kTouchCount> touch{};
  KINEMO_RETURN_IF_ERROR(link_->ReadInputRegisters(config_.map.status_base, in));
  if (config_.map.touch_count > 0) {
    KINEMO_RETURN_IF_ERROR(link_->ReadDiscreteInputs(
        config_.map.touch_base, std::span<uint8_t>(touch.data(), config_.map.touch_count)));
  }
  auto emotion = [](uint16_t v) {
    return v < kEmotionCount ? static_cast<Emotion>(v) : Emotion::kNeutral;
  };
  robot_applied_ = in[reg::kAppliedSequence];
  std::lock_guard<std::mutex> s(state_mu_);
  RobotStatus& st = status_;
  st.connected = true;
  st.has_robot_data = true;
  st.shown_emotion = emotion(in[reg::kShownEmotion]);
  st.shown_intensity_permille = in[reg::kShownIntensity];
  st.applied_sequence = in[reg::kAppliedSequence];
  st.state = in[reg::kState] <= 3 ? static_cast<RobotState>(in[reg::kState])
                                  : RobotState::kAutonomous;
  st.battery_permille = in[reg::kBatteryPermille];
  st.fault_flags = in[reg::kFaultFlags];
  st.firmware_version = in[reg::kFirmwareVersion];
  st.uptime_s = (static_cast<uint32_t>(in[reg::kUptimeHi]) << 16) | in[reg::kUptimeLo];
  st.target_emotion = emotion(in[reg::kTargetEmotion]);
  st.touch_mask = 0;
  for (int i = 0; i < config_.map.touch_count; ++i) {
    if (touch[i]) st.touch_mask |= static_cast<uint8_t>(1u << i);
  }
  st.in_sync = desired_ && st.applied_sequence == desired_->sequence &&
               st.shown_emotion == static_cast<Emotion>(desired_->emotion) &&
               st.state == RobotState::kFollowing;
  st.last_error.clear();
  st.updated = std::chrono::system_clock::now();
  return absl::OkStatus();
}

void RobotClient::RecordError(const Status& s, bool connected) {
  std::lock_guard<std::mutex> l(state_mu_);
  status_.last_error = std::string(s.message());
  status_.connected = connected;
  status_.updated = std::chrono::system_clock::now();
}

StatusOr<RobotStatus> RobotClient::ReadStatus() {
  Status s;
  bool connected = false;
  {
    std::lock_guard<std::mutex> l(link_mu_);
    s = EnsureConnectedLocked();
    if (s.ok()) s = ReadRobotLocked();
    // One more try on a fresh connection if the old one had gone stale.
    if (!s.ok() && absl::IsUnavailable(s) && !link_->IsConnected()) {
      s = EnsureConnectedLocked();
      if (s.ok()) s = ReadRobotLocked();
    }
    connected = link_->IsConnected();
  }
  if (!s.ok()) {
    RecordError(s, connected);
    return Status(s.code(), absl::StrCat("robot '", config_.name, "': ", s.message()));
  }
  return CachedStatus();
}

RobotStatus RobotClient::CachedStatus() const {
  std::lock_guard<std::mutex> l(state_mu_);
  return status_;
}

Status RobotClient::HeartbeatOnce() {
  Status s;
  bool connected = false;
  {
    std::lock_guard<std::mutex> l(link_mu_);
    if (!link_->IsConnected() && Clock::now() < next_connect_attempt_) {
      s = absl::UnavailableError("waiting to reconnect");
    } else {
      s = EnsureConnectedLocked();
    }
    if (!s.ok() && !absl::StrContains(s.message(), "waiting to reconnect")) {
      next_connect_attempt_ = Clock::now() + std::chrono::milliseconds(reconnect_backoff_ms_);
      reconnect_backoff_ms_ = std::min(config_.reconnect_backoff_max_ms, reconnect_backoff_ms_ * 2);
    }
    // The heartbeat is written every heartbeat_interval_ms; status is polled
    // every tick (which may be more often).
    const auto now = Clock::now();
    if (s.ok() && now - last_heartbeat_ >=
                      std::chrono::milliseconds(config_.heartbeat_interval_ms) -
                          std::chrono::milliseconds(1)) {
      s = link_->WriteRegister(config_.map.heartbeat, ++heartbeat_counter_);
      if (s.ok()) last_heartbeat_ = now;
    }
    std::array<uint16_t, 3> cmd{};
    if (s.ok()) s = link_->ReadHoldingRegisters(config_.map.command_base, cmd);
    if (s.ok()) s = ReadRobotLocked();
    if (s.ok()) {
      // Reconcile: the robot must hold and have applied the last command.
      std::optional<Command> want;
      {
        std::lock_guard<std::mutex> st(state_mu_);
        want = desired_;
      }
      if (want && robot_applied_ == want->sequence &&
          (cmd[0] != want->emotion || cmd[1] != want->intensity)) {
        std::lock_guard<std::mutex> st(state_mu_);
        last_sequence_ = std::max({last_sequence_, cmd[2], robot_applied_});
        desired_->sequence = NextSequenceLocked();
        status_.commanded_sequence = desired_->sequence;
        want = desired_;
      }
      if (want && (robot_applied_ != want->sequence || cmd[0] != want->emotion ||
                   cmd[1] != want->intensity || cmd[2] != want->sequence)) {
        s = WriteCommandLocked(*want, Clock::now() + std::chrono::milliseconds(
                                                         config_.ack_timeout_ms));
        if (s.ok()) {
          {
            std::lock_guard<std::mutex> st(state_mu_);
            ++status_.resends;
          }
          s = ReadRobotLocked();
        }
      }
    }
    connected = link_->IsConnected();
  }
  // While waiting to reconnect, keep the error that caused the wait.
  if (!s.ok() && !absl::StrContains(s.message(), "waiting to reconnect")) {
    RecordError(s, connected);
  }
  Publish();
  return s;
}

int RobotClient::Subscribe(std::function<void(const RobotStatus&)> fn) {
  std::lock_guard<std::mutex> l(subscribers_mu_);
  int id = next_subscriber_id_++;
  subscribers_.emplace(id, std::move(fn));
  return id;
}

void RobotClient::Unsubscribe(int id) {
  std::lock_guard<std::mutex> l(subscribers_mu_);
  subscribers_.erase(id);
}

void RobotClient::Publish() {
  RobotStatus snapshot = CachedStatus();
  std::lock_guard<std::mutex> l(subscribers_mu_);
  for (auto& [id, fn] : subscribers_) fn(snapshot);
}

}  // namespace kinemo::robot
