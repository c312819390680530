// ModbusLink: the bridge's view of one Modbus connection to one robot.
//
// The bridge core talks only to this interface; LibmodbusLink implements it
// with libmodbus (TCP and RTU), FaultInjectingLink wraps a real link so tests
// can inject failures. Implementations are not thread-safe: the caller
// (RobotClient) serialises access.
//
// Error codes returned by every operation:
//   UNAVAILABLE          no connection, timeout, connection lost, corrupted
//                        frame, or a transient exception (device busy,
//                        device failure) — worth retrying;
//   INVALID_ARGUMENT     the device refused a value (exception 03);
//   FAILED_PRECONDITION  the device refused the address or function
//                        (exceptions 01, 02): the register map is wrong.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "common/status/status.h"

namespace kinemo::robot {

// Where a robot is reached.
struct Endpoint {
  enum class Kind { kTcp, kRtu };
  Kind kind = Kind::kTcp;
  // TCP
  std::string host = "127.0.0.1";
  int port = 502;
  // RTU
  std::string device;
  int baud = 115200;
  char parity = 'N';  // 'N', 'E' or 'O'
  int data_bits = 8;
  int stop_bits = 1;

  // "tcp://HOST:PORT" or "rtu://DEVICE?baud=115200&parity=N" (DEVICE is a
  // path, e.g. rtu:///dev/ttyUSB0).
  std::string ToString() const;
};

// Parses the forms produced by Endpoint::ToString.
StatusOr<Endpoint> ParseEndpoint(std::string_view text);

struct LinkOptions {
  Endpoint endpoint;
  int unit_id = 1;                 // Modbus slave address 1..247
  int connect_timeout_ms = 1000;   // TCP connect
  int response_timeout_ms = 200;   // whole response
  int byte_timeout_ms = 50;        // gap between bytes of one frame (RTU)
};

Status ValidateLinkOptions(const LinkOptions& options);

class ModbusLink {
 public:
  virtual ~ModbusLink() = default;

  // Opens the connection if it is not open. Cheap when already connected.
  virtual Status Connect() = 0;
  // Closes the connection (next operation needs Connect()).
  virtual void Close() = 0;
  virtual bool IsConnected() const = 0;

  virtual Status ReadHoldingRegisters(int address, std::span<uint16_t> out) = 0;
  virtual Status ReadInputRegisters(int address, std::span<uint16_t> out) = 0;
  virtual Status WriteRegister(int address, uint16_t value) = 0;
  virtual Status WriteRegisters(int address, std::span<const uint16_t> values) = 0;
  // FC 23: writes `values` at `write_address`, then reads `out` from
  // `read_address`, in one transaction. FAILED_PRECONDITION if the device
  // does not implement it.
  virtual Status WriteAndReadRegisters(int write_address, std::span<const uint16_t> values,
                                       int read_address, std::span<uint16_t> out) = 0;
  // One byte per bit, 0 or 1.
  virtual Status ReadDiscreteInputs(int address, std::span<uint8_t> out) = 0;

  // "tcp://127.0.0.1:1502 unit 1" — for messages.
  virtual std::string Describe() const = 0;
};

// A libmodbus link. Never fails to construct; errors surface on Connect().
std::unique_ptr<ModbusLink> NewLibmodbusLink(const LinkOptions& options);

}  // namespace kinemo::robot
