// FaultInjectingLink: wraps a real ModbusLink and makes chosen operations fail
// the way a flaky line does. Used by tests; the wrapped link is real.
#pragma once

#include <atomic>
#include <memory>
#include <mutex>
#include <string>

#include "services/robot_bridge/core/modbus_link.h"

namespace kinemo::robot {

class FaultInjectingLink final : public ModbusLink {
 public:
  explicit FaultInjectingLink(std::unique_ptr<ModbusLink> inner) : inner_(std::move(inner)) {}

  // The next `n` operations fail with UNAVAILABLE without reaching the device.
  void FailNext(int n) { fail_next_ = n; }
  // The next `n` writes reach the device, but their answer is "lost": the
  // caller sees UNAVAILABLE (the case sequence numbers exist for).
  void LoseNextWriteAnswers(int n) { lose_write_answers_ = n; }
  // The next operation closes the real connection first (a dropped socket).
  void DropConnectionOnNext() { drop_next_ = true; }
  // WriteAndReadRegisters answers like a device without FC 23.
  void RefuseWriteAndRead(bool refuse) { refuse_fc23_ = refuse; }
  // Connect() fails while set.
  void RefuseConnect(bool refuse) { refuse_connect_ = refuse; }

  int operations() const { return operations_; }
  int writes() const { return writes_; }
  int connects() const { return connects_; }

  Status Connect() override {
    ++connects_;
    if (refuse_connect_) return absl::UnavailableError(Describe() + ": injected: connect refused");
    return inner_->Connect();
  }
  void Close() override { inner_->Close(); }
  bool IsConnected() const override { return inner_->IsConnected(); }

  Status ReadHoldingRegisters(int address, std::span<uint16_t> out) override {
    KINEMO_RETURN_IF_ERROR(Before());
    return inner_->ReadHoldingRegisters(address, out);
  }
  Status ReadInputRegisters(int address, std::span<uint16_t> out) override {
    KINEMO_RETURN_IF_ERROR(Before());
    return inner_->ReadInputRegisters(address, out);
  }
  Status WriteRegister(int address, uint16_t value) override {
    KINEMO_RETURN_IF_ERROR(Before());
    ++writes_;
    Status s = inner_->WriteRegister(address, value);
    return AfterWrite(s);
  }
  Status WriteRegisters(int address, std::span<const uint16_t> values) override {
    KINEMO_RETURN_IF_ERROR(Before());
    ++writes_;
    Status s = inner_->WriteRegisters(address, values);
    return AfterWrite(s);
  }
  Status WriteAndReadRegisters(int write_address, std::span<const uint16_t> values,
                               int read_address, std::span<uint16_t> out) override {
    KINEMO_RETURN_IF_ERROR(Before());
    if (refuse_fc23_) {
      return absl::FailedPreconditionError(Describe() + ": injected: Illegal function");
    }
    ++writes_;
    Status s = inner_->WriteAndReadRegisters(write_address, values, read_address, out);
    return AfterWrite(s);
  }
  Status ReadDiscreteInputs(int address, std::span<uint8_t> out) override {
    KINEMO_RETURN_IF_ERROR(Before());
    return inner_->ReadDiscreteInputs(address, out);
  }
  std::string Describe() const override { return inner_->Describe(); }

 private:
  Status Before() {
    ++operations_;
    if (drop_next_.exchange(false)) inner_->Close();
    if (fail_next_ > 0) {
      --fail_next_;
      return absl::UnavailableError(Describe() + ": injected: no response");
    }
    return absl::OkStatus();
  }
  Status AfterWrite(const Status& s) {
    if (s.ok() && lose_write_answers_ > 0) {
      --lose_write_answers_;
      return absl::UnavailableError(Describe() + ": injected: answer to the write was lost");
    }
    return s;
  }

  std::unique_ptr<ModbusLink> inner_;
  std::atomic<int> fail_next_{0};
  std::atomic<int> lose_write_answers_{0};
  std::atomic<bool> drop_next_{false};
  std::atomic<bool> refuse_connect_{false};
  std::atomic<bool> refuse_fc23_{false};
  std::atomic<int> operations_{0};
  std::atomic<int> writes_{0};
  std::atomic<int> connects_{0};
};

}  // namespace kinemo::robot
