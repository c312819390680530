// Fuzzes the robot client's decoding of what a robot answers
// (services/robot_bridge/core/robot_client.cc): a ModbusLink whose every
// answer — success or the error a flaky line gives, and the register values —
// comes from the input drives RobotClient through the operations the bridge
// performs (status reads, heartbeat ticks with reconciliation, emotion
// commands with read-back and acknowledgement). The status it reports must
// stay inside the register map's ranges. The first bytes are also parsed as
// a robot endpoint (ParseEndpoint), whose printed form must parse back.
#include <fuzzer/FuzzedDataProvider.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "services/robot_bridge/core/robot_client.h"
#include "tests/fuzz/fuzz_check.h"

namespace {

using kinemo::Status;
using kinemo::robot::ModbusLink;

class FuzzedLink final : public ModbusLink {
 public:
  explicit FuzzedLink(FuzzedDataProvider* in) : in_(in) {}

  Status Connect() override {
    if (connected_) return absl::OkStatus();
    Status s = Outcome();
    connected_ = s.ok();
    return s;
  }
  void Close() override { connected_ = false; }
  bool IsConnected() const override { return connected_; }
  Status ReadHoldingRegisters(int, std::span<uint16_t> out) override { return Read(out); }
  Status ReadInputRegisters(int, std::span<uint16_t> out) override { return Read(out); }
  Status WriteRegister(int, uint16_t) override { return Outcome(); }
  Status WriteRegisters(int, std::span<const uint16_t>) override { return Outcome(); }
  Status WriteAndReadRegisters(int, std::span<const uint16_t> values, int,
                               std::span<uint16_t> out) override {
    KINEMO_RETURN_IF_ERROR(Outcome());
    // Mostly the device echoes what was written (as a healthy robot does).
    if (in_->ConsumeBool()) {
      for (size_t i = 0; i < out.size() && i < values.size(); ++i) out[i] = values[i];
      return absl::OkStatus();
    }
    for (auto& v : out) v = in_->ConsumeIntegral<uint16_t>();
    return absl::OkStatus();
  }
  Status ReadDiscreteInputs(int, std::span<uint8_t> out) override {
    KINEMO_RETURN_IF_ERROR(Outcome());
    for (auto& v : out) v = in_->ConsumeBool() ? 1 : 0;
    return absl::OkStatus();
  }
  std::string Describe() const override { return "fuzz://robot unit 1"; }

 private:
  // What the line gives: success, or one of the errors a ModbusLink returns.
  // A device that has nothing more to say is gone.
  Status Outcome() {
    if (in_->remaining_bytes() == 0) {
      connected_ = false;
      return absl::UnavailableError("fuzz: connection lost");
    }
    switch (in_->ConsumeIntegralInRange<int>(0, 15)) {
      case 1:
        connected_ = false;
        return absl::UnavailableError("fuzz: timeout");
      case 2:
        return absl::UnavailableError("fuzz: device busy");
      case 3:
        return absl::InvalidArgumentError("fuzz: illegal data value");
      case 4:
        return absl::FailedPreconditionError("fuzz: illegal function");
      default:
        return absl::OkStatus();
    }
  }
  Status Read(std::span<uint16_t> out) {
    KINEMO_RETURN_IF_ERROR(Outcome());
    for (auto& v : out) v = in_->ConsumeIntegral<uint16_t>();
    return absl::OkStatus();
  }

  FuzzedDataProvider* in_;
  bool connected_ = false;
};

void CheckStatus(const kinemo::robot::RobotStatus& st, int touch_count) {
  using kinemo::robot::Emotion;
  using kinemo::robot::RobotState;
  KINEMO_FUZZ_CHECK(static_cast<uint16_t>(st.shown_emotion) < kinemo::robot::kEmotionCount,
                    "shown_emotion");
  KINEMO_FUZZ_CHECK(static_cast<uint16_t>(st.target_emotion) < kinemo::robot::kEmotionCount,
                    "target_emotion");
  KINEMO_FUZZ_CHECK(static_cast<uint16_t>(st.state) <= static_cast<uint16_t>(RobotState::kSleeping),
                    "state");
  KINEMO_FUZZ_CHECK((st.touch_mask >> touch_count) == 0, "touch bit beyond the robot's sensors");
}

void CheckEndpoint(const std::string& text) {
  auto ep = kinemo::robot::ParseEndpoint(text);
  if (!ep.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(ep.status(), absl::StatusCode::kInvalidArgument);
    return;
  }
  auto again = kinemo::robot::ParseEndpoint(ep->ToString());
  KINEMO_FUZZ_CHECK(again.ok(), again.status().ToString());
  KINEMO_FUZZ_CHECK(again->ToString() == ep->ToString(),
                    "printed endpoint parses to another: " + ep->ToString());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  FuzzedDataProvider in(data, size);
  CheckEndpoint(in.ConsumeRandomLengthString(64));

  kinemo::robot::RobotConfig config;
  config.name = "pleo";
  config.retry.max_attempts = in.ConsumeIntegralInRange(1, 3);
  config.retry.initial_backoff_ms = 0;
  config.retry.max_backoff_ms = 0;
  config.ack_timeout_ms = 1;
  config.heartbeat_interval_ms = 10;
  config.status_poll_interval_ms = 10;
  config.watchdog_ms = in.ConsumeBool() ? 0 : 100;
  config.reconnect_backoff_initial_ms = 1;
  config.reconnect_backoff_max_ms = 1;
  config.verify_readback = in.ConsumeBool();
  config.map.touch_count = in.ConsumeIntegralInRange(0, 8);
  if (in.ConsumeBool()) config.map.watchdog = -1;
  KINEMO_FUZZ_CHECK(kinemo::robot::ValidateRobotConfig(config).ok(), "the harness's config");
  const int touch_count = config.map.touch_count;
  kinemo::robot::RobotClient client(std::move(config), std::make_unique<FuzzedLink>(&in));

  // At most 32 operations per input; never the heartbeat thread.
  for (int op = 0; op < 32 && in.remaining_bytes() > 0; ++op) {
    switch (in.ConsumeIntegralInRange(0, 2)) {
      case 0: {
        auto st = client.ReadStatus();
        if (st.ok()) CheckStatus(*st, touch_count);
        break;
      }
      case 1:
        (void)client.HeartbeatOnce();
        break;
      case 2: {
        const int emotion = in.ConsumeIntegralInRange(-1, 3);
        const int intensity = in.ConsumeIntegralInRange(-1, 1001);
        kinemo::robot::CommandOptions options;
        options.timeout_ms = 2;
        auto r = client.SetEmotion(emotion, intensity, options);
        if (emotion < 0 || emotion > 2 || intensity < 0 || intensity > 1000) {
          KINEMO_FUZZ_CHECK(!r.ok() && r.status().code() == absl::StatusCode::kInvalidArgument,
                            "an out-of-range command was not refused");
        }
        break;
      }
    }
    CheckStatus(client.CachedStatus(), touch_count);
  }
  return 0;
}
