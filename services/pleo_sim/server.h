// PleoSimServer: serves PleoFirmware over Modbus TCP (many clients, one
// select loop) or Modbus RTU (a serial device, e.g. one end of a socat pty
// pair), with the fault injection of registers 100..102.
#pragma once

#include <modbus/modbus.h>

#include <atomic>
#include <memory>
#include <string>
#include <vector>

#include "common/status/status.h"
#include "services/pleo_sim/firmware.h"

namespace kinemo::pleo_sim {

struct ServerOptions {
  // Exactly one of tcp / rtu.
  bool tcp = true;
  std::string host = "127.0.0.1";
  int port = 0;  // 0 = ephemeral, see PleoSimServer::port()
  std::string device;
  int baud = 115200;
  char parity = 'N';
  int unit_id = 1;
  FirmwareOptions firmware;
  // Initial fault (same as writing registers 100..102).
  robot::SimFault fault = robot::SimFault::kNone;
  int fault_delay_ms = 0;
  int fault_count = 0;
  bool verbose = false;
};

class PleoSimServer {
 public:
  explicit PleoSimServer(ServerOptions options);
  ~PleoSimServer();
  PleoSimServer(const PleoSimServer&) = delete;
  PleoSimServer& operator=(const PleoSimServer&) = delete;

  // Binds the TCP port / opens the serial device.
  Status Open();
  // The bound TCP port (after Open).
  int port() const { return port_; }
  // Serves until Stop(). Returns an error if the device fails for good.
  Status Run();
  // Thread- and async-signal-safe.
  void Stop();

 private:
  enum class Outcome { kAnswered, kClose };
  Outcome Handle(int fd, const uint8_t* req, int length);
  void SendCorrupted(int fd, const uint8_t* req, int length);
  Status RunTcp();
  Status RunRtu();
  int TickTimeoutMs() const { return 10; }
  void Log(const char* fmt, ...) const;

  ServerOptions options_;
  std::unique_ptr<PleoFirmware> firmware_;
  modbus_t* ctx_ = nullptr;
  int listen_fd_ = -1;
  int wake_[2] = {-1, -1};
  int port_ = 0;
  std::vector<int> clients_;
  uint32_t noise_state_ = 12345;
};

}  // namespace kinemo::pleo_sim
