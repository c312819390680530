// The robot bridge benchmark behind `kinemo robot bench`: starts pleo_sim on
// loopback TCP and on one end of a socat pty pair (RTU), hosts the real
// RobotBridgeService on a loopback gRPC port, and times SetEmotion round
// trips through gRPC → bridge → Modbus → pleo_sim and back (acknowledged).
#pragma once

#include <string>

#include "common/status/status.h"

namespace kinemo::robot_bridge {

struct BenchOptions {
  std::string pleo_sim;     // path of the pleo_sim binary ("" = look beside this program)
  int tcp_commands = 1000;  // timed SetEmotion calls over TCP
  int rtu_commands = 300;   // timed SetEmotion calls over RTU
  int warmup = 20;          // untimed calls first, per transport
  bool rtu = true;          // run the RTU part (needs socat)
  int rtu_baud = 115200;
};

struct BenchResult {
  double tcp_p50_ms = 0, tcp_p99_ms = 0, tcp_max_ms = 0;
  double rtu_p50_ms = 0, rtu_p99_ms = 0, rtu_max_ms = 0;
  double commands_per_s = 0;  // sequential SetEmotion calls per second over TCP
  int tcp_commands = 0, rtu_commands = 0;
  std::string rtu_skipped;    // why the RTU part did not run, if it did not
};

StatusOr<BenchResult> RunRobotBench(const BenchOptions& options);

// pleo_sim next to the running program (build tree or install), or "".
std::string FindPleoSim(const std::string& argv0);

}  // namespace kinemo::robot_bridge
