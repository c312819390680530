// pleo_sim: a simulated Pleo controller speaking Modbus (TCP or RTU).
//
//   pleo_sim --tcp 127.0.0.1:0 --port-file /tmp/p    # ephemeral port, written to /tmp/p
//   pleo_sim --rtu /dev/pts/5 --baud 115200
//
// Register map: docs/robot_bridge_registers.md.
#include <signal.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <string>

#include "CLI/CLI.hpp"
#include "services/pleo_sim/server.h"

namespace {

kinemo::pleo_sim::PleoSimServer* g_server = nullptr;

void OnSignal(int) {
  if (g_server != nullptr) g_server->Stop();
}

bool WriteFileAtomically(const std::string& path, const std::string& text) {
  std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    if (!out) return false;
    out << text;
    if (!out.flush()) return false;
  }
  return std::rename(tmp.c_str(), path.c_str()) == 0;
}

}  // namespace

int main(int argc, char** argv) {
  using kinemo::pleo_sim::ServerOptions;
  ServerOptions o;
  std::string tcp, rtu, parity = "N", port_file, fault = "none";
  CLI::App app{"pleo_sim: a simulated Pleo robot controller (Modbus TCP / RTU server)"};
  auto* tcp_opt = app.add_option("--tcp", tcp, "listen on HOST:PORT (PORT 0 = ephemeral)");
  auto* rtu_opt = app.add_option("--rtu", rtu, "serve on this serial device");
  tcp_opt->excludes(rtu_opt);
  app.add_option("--baud", o.baud, "RTU baud rate")->capture_default_str();
  app.add_option("--parity", parity, "RTU parity N, E or O")->capture_default_str();
  app.add_option("--unit", o.unit_id, "Modbus unit id (1..247)")->capture_default_str();
  app.add_option("--port-file", port_file, "write the bound TCP port here once listening");
  app.add_option("--switch-ms", o.firmware.switch_ms, "animation switch time")->capture_default_str();
  app.add_option("--watchdog-ms", o.firmware.watchdog_ms, "initial watchdog (0 = off)")
      ->capture_default_str();
  app.add_option("--battery-permille", o.firmware.battery_permille, "initial battery 0..1000")
      ->capture_default_str();
  app.add_option("--drain-permille-per-min", o.firmware.drain_permille_per_min,
                 "battery drain at intensity 0 (doubles at 1000)")
      ->capture_default_str();
  app.add_option("--autonomous-period-ms", o.firmware.autonomous_period_ms,
                 "mood change period when autonomous")
      ->capture_default_str();
  app.add_option("--seed", o.firmware.seed, "random seed")->capture_default_str();
  app.add_option("--fault", fault, "initial fault: none|delay|drop|busy|corrupt|silent|noise")
      ->capture_default_str();
  app.add_option("--fault-delay-ms", o.fault_delay_ms, "delay for --fault delay")
      ->capture_default_str();
  app.add_option("--fault-count", o.fault_count, "requests affected (0 = until cleared)")
      ->capture_default_str();
  app.add_flag("-v,--verbose", o.verbose, "log connections and faults to stderr");
  CLI11_PARSE(app, argc, argv);

  if (tcp.empty() == rtu.empty()) {
    std::fprintf(stderr, "pleo_sim: give exactly one of --tcp HOST:PORT or --rtu DEVICE\n");
    return 2;
  }
  auto f = kinemo::robot::SimFaultFromName(fault);
  if (!f) {
    std::fprintf(stderr, "pleo_sim: --fault: unknown fault '%s'\n", fault.c_str());
    return 2;
  }
  o.fault = *f;
  if (parity.size() != 1 || std::string("NEO").find(parity[0]) == std::string::npos) {
    std::fprintf(stderr, "pleo_sim: --parity: '%s' is not N, E or O\n", parity.c_str());
    return 2;
  }
  o.parity = parity[0];
  if (!tcp.empty()) {
    size_t colon = tcp.rfind(':');
    if (colon == std::string::npos) {
      std::fprintf(stderr, "pleo_sim: --tcp: '%s' must be HOST:PORT\n", tcp.c_str());
      return 2;
    }
    o.tcp = true;
    o.host = tcp.substr(0, colon);
    if (o.host.size() > 2 && o.host.front() == '[') o.host = o.host.substr(1, o.host.size() - 2);
    try {
      o.port = std::stoi(tcp.substr(colon + 1));
    } catch (...) {
      o.port = -1;
    }
    if (o.port < 0 || o.port > 65535) {
      std::fprintf(stderr, "pleo_sim: --tcp: bad port in '%s'\n", tcp.c_str());
      return 2;
    }
  } else {
    o.tcp = false;
    o.device = rtu;
  }

  signal(SIGPIPE, SIG_IGN);
  kinemo::pleo_sim::PleoSimServer server(o);
  kinemo::Status s = server.Open();
  if (!s.ok()) {
    std::fprintf(stderr, "pleo_sim: %s\n", std::string(s.message()).c_str());
    return 1;
  }
  g_server = &server;
  struct sigaction sa {};
  sa.sa_handler = OnSignal;
  sigaction(SIGTERM, &sa, nullptr);
  sigaction(SIGINT, &sa, nullptr);
  if (o.tcp) {
    std::printf("pleo_sim: listening tcp %s:%d unit %d\n", o.host.c_str(), server.port(), o.unit_id);
    if (!port_file.empty() && !WriteFileAtomically(port_file, std::to_string(server.port()) + "\n")) {
      std::fprintf(stderr, "pleo_sim: --port-file: cannot write '%s'\n", port_file.c_str());
      return 1;
    }
  } else {
    std::printf("pleo_sim: serving rtu %s %d baud unit %d\n", o.device.c_str(), o.baud, o.unit_id);
  }
  std::fflush(stdout);
  s = server.Run();
  g_server = nullptr;
  if (!s.ok()) {
    std::fprintf(stderr, "pleo_sim: %s\n", std::string(s.message()).c_str());
    return 1;
  }
  return 0;
}
