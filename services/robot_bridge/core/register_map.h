// The Pleo Modbus register map (v1). docs/robot_bridge_registers.md is the
// prose version; this header is the single source of the numbers and is shared
// by the bridge and by pleo_sim.
#pragma once

#include <cstdint>
#include <optional>
#include <string_view>

namespace kinemo::robot {

// Emotions the robot can show (thesis §5.3.2: neutral, happy, angry).
enum class Emotion : uint16_t { kNeutral = 0, kHappy = 1, kAngry = 2 };
inline constexpr uint16_t kEmotionCount = 3;

// What the firmware is doing (input register STATE).
enum class RobotState : uint16_t {
  kFollowing = 0,   // showing the commanded emotion
  kSwitching = 1,   // an animation change is in progress
  kAutonomous = 2,  // watchdog expired: Pleo's own behaviour
  kSleeping = 3,    // battery empty
};

namespace reg {

// Holding registers (FC 03 / 06 / 16).
inline constexpr int kCmdEmotion = 0;
inline constexpr int kCmdIntensity = 1;
inline constexpr int kCmdSequence = 2;
inline constexpr int kHeartbeat = 3;
inline constexpr int kWatchdogMs = 4;
inline constexpr int kHoldingCount = 5;  // 0..4

// Simulator-only fault control block (pleo_sim).
inline constexpr int kSimFaultMode = 100;
inline constexpr int kSimFaultDelayMs = 101;
inline constexpr int kSimFaultCount = 102;
inline constexpr int kSimTouch = 103;
inline constexpr int kSimBatteryPermille = 104;
inline constexpr int kSimBase = 100;
inline constexpr int kSimCount = 5;  // 100..104

// Input registers (FC 04).
inline constexpr int kShownEmotion = 0;
inline constexpr int kShownIntensity = 1;
inline constexpr int kAppliedSequence = 2;
inline constexpr int kState = 3;
inline constexpr int kBatteryPermille = 4;
inline constexpr int kFaultFlags = 5;
inline constexpr int kFirmwareVersion = 6;
inline constexpr int kUptimeHi = 7;
inline constexpr int kUptimeLo = 8;
inline constexpr int kTargetEmotion = 9;
inline constexpr int kDeviceId = 10;
inline constexpr int kInputCount = 11;  // 0..10

// Discrete inputs (FC 02): touch sensors.
inline constexpr int kTouchBase = 0;
inline constexpr int kTouchCount = 8;

}  // namespace reg

// Ranges.
inline constexpr uint16_t kIntensityMaxPermille = 1000;
inline constexpr uint16_t kWatchdogMinMs = 100;
inline constexpr uint16_t kWatchdogMaxMs = 60000;
inline constexpr uint16_t kBatteryMaxPermille = 1000;
inline constexpr uint16_t kBatteryLowPermille = 150;
inline constexpr uint16_t kDeviceIdValue = 0x504C;  // "PL"

// FAULT_FLAGS bits.
inline constexpr uint16_t kFaultBatteryLow = 1u << 0;
inline constexpr uint16_t kFaultWatchdogExpired = 1u << 1;
inline constexpr uint16_t kFaultCommandRefused = 1u << 2;
inline constexpr uint16_t kFaultBatteryEmpty = 1u << 3;

// SIM_FAULT_MODE values.
enum class SimFault : uint16_t {
  kNone = 0,
  kDelay = 1,    // answer after SIM_FAULT_DELAY_MS
  kDrop = 2,     // close the connection (TCP) / stay silent (RTU)
  kBusy = 3,     // exception 06 SERVER DEVICE BUSY
  kCorrupt = 4,  // corrupted frame (bad CRC / bad transaction id)
  kSilent = 5,   // no answer at all
  kNoise = 6,    // random bytes on the line before the answer
};
inline constexpr uint16_t kSimFaultCount = 7;

// Touch sensor names, in discrete input order.
inline constexpr std::string_view kTouchNames[reg::kTouchCount] = {
    "head", "chin", "back", "left_shoulder", "right_shoulder", "left_leg", "right_leg", "tail"};

std::string_view EmotionName(Emotion e);
std::optional<Emotion> EmotionFromName(std::string_view name);
std::string_view RobotStateName(RobotState s);
std::string_view SimFaultName(SimFault f);
std::optional<SimFault> SimFaultFromName(std::string_view name);

}  // namespace kinemo::robot
