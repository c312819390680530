#include "services/pleo_sim/firmware.h"

#include <algorithm>
#include <cstdio>

namespace kinemo::pleo_sim {

namespace reg = robot::reg;
using robot::Emotion;
using robot::RobotState;

namespace {

constexpr int kHoldingSize = reg::kSimBase + reg::kSimCount;  // 0..104

bool InBlock(int addr, int count, int base, int size) {
  return count >= 1 && addr >= base && addr + count <= base + size;
}

bool HoldingAddressOk(int addr, int count) {
  return InBlock(addr, count, 0, reg::kHoldingCount) ||
         InBlock(addr, count, reg::kSimBase, reg::kSimCount);
}

bool HoldingValueOk(int addr, uint16_t v) {
  switch (addr) {
    case reg::kCmdEmotion: return v < robot::kEmotionCount;
    case reg::kCmdIntensity: return v <= robot::kIntensityMaxPermille;
    case reg::kCmdSequence: return true;
    case reg::kHeartbeat: return true;
    case reg::kWatchdogMs:
      return v == 0 || (v >= robot::kWatchdogMinMs && v <= robot::kWatchdogMaxMs);
    case reg::kSimFaultMode: return v < robot::kSimFaultCount;
    case reg::kSimFaultDelayMs: return v <= 10000;
    case reg::kSimFaultCount: return true;
    case reg::kSimTouch: return v <= 0xFF;
    case reg::kSimBatteryPermille: return v <= robot::kBatteryMaxPermille;
    default: return false;
  }
}

}  // namespace

PleoFirmware::PleoFirmware(const FirmwareOptions& options, Clock::time_point now)
    : options_(options), rng_(options.seed) {
  mapping_ = modbus_mapping_new_start_address(0, 0, reg::kTouchBase, reg::kTouchCount, 0,
                                              kHoldingSize, 0, reg::kInputCount);
  boot_ = last_tick_ = last_heartbeat_ = switch_done_ = now;
  next_wander_ = now + std::chrono::milliseconds(options_.autonomous_period_ms);
  battery_permille_ = std::clamp(options_.battery_permille, 0, 1000);
  mapping_->tab_registers[reg::kCmdIntensity] = 500;
  mapping_->tab_registers[reg::kWatchdogMs] = static_cast<uint16_t>(options_.watchdog_ms);
  if (battery_permille_ <= 0) state_ = RobotState::kSleeping;
  Publish(now);
}

PleoFirmware::~PleoFirmware() { modbus_mapping_free(mapping_); }

int PleoFirmware::Check(const uint8_t* req, int length, int h) const {
  if (length < h + 1) return MODBUS_EXCEPTION_ILLEGAL_FUNCTION;
  const uint8_t fc = req[h];
  const uint8_t* p = req + h + 1;
  auto need = [&](int bytes) { return length >= h + 1 + bytes; };
  switch (fc) {
    case MODBUS_FC_READ_COILS:
    case MODBUS_FC_WRITE_SINGLE_COIL:
    case MODBUS_FC_WRITE_MULTIPLE_COILS:
      return MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;  // Pleo has no coils
    case MODBUS_FC_READ_DISCRETE_INPUTS:
      if (!need(4)) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
      return InBlock(ModbusWord(p), ModbusWord(p + 2), reg::kTouchBase, reg::kTouchCount)
                 ? 0
                 : MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
    case MODBUS_FC_READ_INPUT_REGISTERS:
      if (!need(4)) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
      return InBlock(ModbusWord(p), ModbusWord(p + 2), 0, reg::kInputCount)
                 ? 0
                 : MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
    case MODBUS_FC_READ_HOLDING_REGISTERS:
      if (!need(4)) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
      return HoldingAddressOk(ModbusWord(p), ModbusWord(p + 2)) ? 0 : MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
    case MODBUS_FC_WRITE_SINGLE_REGISTER: {
      if (!need(4)) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
      int addr = ModbusWord(p);
      if (!HoldingAddressOk(addr, 1)) return MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
      return HoldingValueOk(addr, ModbusWord(p + 2)) ? 0 : MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
    }
    case MODBUS_FC_WRITE_MULTIPLE_REGISTERS:
    case MODBUS_FC_WRITE_AND_READ_REGISTERS: {
      int waddr, wcount;
      const uint8_t* values;
      if (fc == MODBUS_FC_WRITE_MULTIPLE_REGISTERS) {
        if (!need(5)) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
        waddr = ModbusWord(p);
        wcount = ModbusWord(p + 2);
        values = p + 5;
      } else {
        if (!need(9)) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
        if (!HoldingAddressOk(ModbusWord(p), ModbusWord(p + 2))) return MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
        waddr = ModbusWord(p + 4);
        wcount = ModbusWord(p + 6);
        values = p + 9;
      }
      if (!HoldingAddressOk(waddr, wcount)) return MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
      if (values + 2 * wcount > req + length) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
      for (int i = 0; i < wcount; ++i) {
        if (!HoldingValueOk(waddr + i, ModbusWord(values + 2 * i))) {
          return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
        }
      }
      return 0;
    }
    case MODBUS_FC_REPORT_SLAVE_ID:
      return 0;
    default:
      return MODBUS_EXCEPTION_ILLEGAL_FUNCTION;
  }
}

void PleoFirmware::OnRefused() { flags_ |= robot::kFaultCommandRefused; }

void PleoFirmware::BeginSwitch(uint16_t emotion, uint16_t intensity, Clock::time_point now) {
  target_ = static_cast<Emotion>(emotion);
  target_intensity_ = intensity;
  if (target_ == shown_ && state_ != RobotState::kSwitching) {
    shown_intensity_ = intensity;  // same loop animation, only its intensity changes
    state_ = RobotState::kFollowing;
    return;
  }
  state_ = RobotState::kSwitching;
  switch_done_ = now + std::chrono::milliseconds(options_.switch_ms);
}

void PleoFirmware::OnHoldingWritten(int address, int count, Clock::time_point now) {
  Tick(now);
  uint16_t* h = mapping_->tab_registers;
  auto touches = [&](int r) { return r >= address && r < address + count; };
  if (address < reg::kHoldingCount) {
    // Any write to the command/heartbeat block feeds the watchdog.
    host_seen_ = true;
    last_heartbeat_ = now;
    flags_ &= static_cast<uint16_t>(~robot::kFaultWatchdogExpired);
    if (state_ == RobotState::kAutonomous) {
      state_ = RobotState::kFollowing;
      BeginSwitch(applied_emotion_, applied_intensity_, now);
    }
  }
  if (touches(reg::kCmdSequence)) {
    uint16_t seq = h[reg::kCmdSequence];
    if (seq != 0 && seq != applied_sequence_) {
      applied_sequence_ = seq;
      applied_emotion_ = h[reg::kCmdEmotion];
      applied_intensity_ = h[reg::kCmdIntensity];
      flags_ &= static_cast<uint16_t>(~robot::kFaultCommandRefused);
      if (state_ != RobotState::kSleeping) BeginSwitch(applied_emotion_, applied_intensity_, now);
    }
  }
  if (touches(reg::kSimBatteryPermille)) {
    battery_permille_ = h[reg::kSimBatteryPermille];
    if (battery_permille_ > 0 && state_ == RobotState::kSleeping) {
      state_ = RobotState::kFollowing;
      BeginSwitch(applied_emotion_, applied_intensity_, now);
    }
  }
  if (touches(reg::kSimTouch)) {
    for (int i = 0; i < reg::kTouchCount; ++i) {
      mapping_->tab_input_bits[i] = (h[reg::kSimTouch] >> i) & 1u;
    }
  }
  Publish(now);
}

void PleoFirmware::Tick(Clock::time_point now) {
  const double dt_min = std::chrono::duration<double>(now - last_tick_).count() / 60.0;
  last_tick_ = now;
  if (state_ != RobotState::kSleeping) {
    battery_permille_ -= options_.drain_permille_per_min * dt_min * (1.0 + shown_intensity_ / 1000.0);
    if (battery_permille_ <= 0) {
      battery_permille_ = 0;
      state_ = RobotState::kSleeping;
    }
  }
  if (state_ == RobotState::kSwitching && now >= switch_done_) {
    shown_ = target_;
    shown_intensity_ = target_intensity_;
    state_ = RobotState::kFollowing;
  }
  const int watchdog_ms = mapping_->tab_registers[reg::kWatchdogMs];
  if (host_seen_ && watchdog_ms > 0 &&
      (state_ == RobotState::kFollowing || state_ == RobotState::kSwitching) &&
      now - last_heartbeat_ > std::chrono::milliseconds(watchdog_ms)) {
    state_ = RobotState::kAutonomous;
    flags_ |= robot::kFaultWatchdogExpired;
    next_wander_ = now;
  }
  if (state_ == RobotState::kAutonomous && now >= next_wander_) {
    // Pleo's own behaviour: wander between moods.
    uint16_t next = static_cast<uint16_t>(
        (static_cast<uint16_t>(shown_) + 1 + rng_() % (robot::kEmotionCount - 1)) %
        robot::kEmotionCount);
    shown_ = target_ = static_cast<Emotion>(next);
    shown_intensity_ = target_intensity_ = static_cast<uint16_t>(200 + rng_() % 601);
    next_wander_ = now + std::chrono::milliseconds(options_.autonomous_period_ms);
  }
  Publish(now);
}

void PleoFirmware::Publish(Clock::time_point now) {
  uint16_t* in = mapping_->tab_input_registers;
  const auto battery = static_cast<uint16_t>(battery_permille_ + 0.5);
  uint16_t flags = flags_ & static_cast<uint16_t>(robot::kFaultWatchdogExpired |
                                                   robot::kFaultCommandRefused);
  if (battery < robot::kBatteryLowPermille) flags |= robot::kFaultBatteryLow;
  if (battery == 0) flags |= robot::kFaultBatteryEmpty;
  const auto uptime =
      static_cast<uint32_t>(std::chrono::duration_cast<std::chrono::seconds>(now - boot_).count());
  in[reg::kShownEmotion] = static_cast<uint16_t>(shown_);
  in[reg::kShownIntensity] = shown_intensity_;
  in[reg::kAppliedSequence] = applied_sequence_;
  in[reg::kState] = static_cast<uint16_t>(state_);
  in[reg::kBatteryPermille] = battery;
  in[reg::kFaultFlags] = flags;
  in[reg::kFirmwareVersion] = options_.firmware_version;
  in[reg::kUptimeHi] = static_cast<uint16_t>(uptime >> 16);
  in[reg::kUptimeLo] = static_cast<uint16_t>(uptime & 0xFFFF);
  in[reg::kTargetEmotion] = static_cast<uint16_t>(target_);
  in[reg::kDeviceId] = robot::kDeviceIdValue;
  mapping_->tab_registers[reg::kSimBatteryPermille] = battery;
}

robot::SimFault PleoFirmware::fault_mode() const {
  return static_cast<robot::SimFault>(mapping_->tab_registers[reg::kSimFaultMode]);
}

int PleoFirmware::fault_delay_ms() const { return mapping_->tab_registers[reg::kSimFaultDelayMs]; }

void PleoFirmware::ConsumeFault() {
  uint16_t* h = mapping_->tab_registers;
  if (h[reg::kSimFaultCount] == 0) return;  // until cleared
  if (--h[reg::kSimFaultCount] == 0) h[reg::kSimFaultMode] = 0;
}

}  // namespace kinemo::pleo_sim
