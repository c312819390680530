// PleoFirmware: what the robot's controller does with the register map
// (docs/robot_bridge_registers.md). Plain state machine over a libmodbus
// mapping; the server feeds it requests and the clock.
#pragma once

#include <modbus/modbus.h>

#include <chrono>
#include <cstdint>
#include <random>

#include "services/robot_bridge/core/register_map.h"

namespace kinemo::pleo_sim {

// The big-endian 16-bit word at p (a Modbus register or address in a request).
inline uint16_t ModbusWord(const uint8_t* p) { return static_cast<uint16_t>((p[0] << 8) | p[1]); }

struct FirmwareOptions {
  int switch_ms = 300;             // time to change loop animation
  int watchdog_ms = 2000;          // initial WATCHDOG_MS (0 = off)
  int battery_permille = 1000;     // initial charge
  double drain_permille_per_min = 5.0;  // at intensity 0; x2 at intensity 1000
  int autonomous_period_ms = 2500; // how often autonomous behaviour changes emotion
  uint32_t seed = 1;
  uint16_t firmware_version = 0x0100;
};

class PleoFirmware {
 public:
  using Clock = std::chrono::steady_clock;

  PleoFirmware(const FirmwareOptions& options, Clock::time_point now);
  ~PleoFirmware();
  PleoFirmware(const PleoFirmware&) = delete;
  PleoFirmware& operator=(const PleoFirmware&) = delete;

  modbus_mapping_t* mapping() { return mapping_; }

  // Checks a request before libmodbus answers it from the mapping. Returns 0
  // when it may be answered, else the Modbus exception code to send
  // (addresses outside the map → 02, values out of range → 03).
  // `req` is the frame, `header_length` from modbus_get_header_length.
  int Check(const uint8_t* req, int length, int header_length) const;
  // The holding registers [address, address+count) were written.
  void OnHoldingWritten(int address, int count, Clock::time_point now);
  // A write was refused (sets the "command refused" fault flag).
  void OnRefused();
  // Advances animations, battery, watchdog, autonomous behaviour.
  void Tick(Clock::time_point now);

  // Fault control (registers 100..102).
  robot::SimFault fault_mode() const;
  int fault_delay_ms() const;
  // Consumes one use of the current fault (SIM_FAULT_COUNT counts down).
  void ConsumeFault();

  robot::RobotState state() const { return state_; }
  robot::Emotion shown() const { return shown_; }

 private:
  void BeginSwitch(uint16_t emotion, uint16_t intensity, Clock::time_point now);
  void Publish(Clock::time_point now);

  FirmwareOptions options_;
  modbus_mapping_t* mapping_ = nullptr;
  std::minstd_rand rng_;
  Clock::time_point boot_;
  Clock::time_point last_tick_;
  Clock::time_point last_heartbeat_;
  Clock::time_point switch_done_;
  Clock::time_point next_wander_;
  bool host_seen_ = false;
  robot::RobotState state_ = robot::RobotState::kAutonomous;
  robot::Emotion shown_ = robot::Emotion::kNeutral;
  uint16_t shown_intensity_ = 500;
  robot::Emotion target_ = robot::Emotion::kNeutral;
  uint16_t target_intensity_ = 500;
  uint16_t applied_sequence_ = 0;
  uint16_t applied_emotion_ = 0;
  uint16_t applied_intensity_ = 500;
  double battery_permille_ = 1000;
  uint16_t flags_ = 0;
};

}  // namespace kinemo::pleo_sim
