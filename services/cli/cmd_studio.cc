// kinemo studio [--open] [--port P] [--port-file F]: the web studio
// (services/studio) in front of an embedded stack: a kinemo_allinone child
// with the bundled gesture library, model and controller, and a simulated
// Pleo (pleo_sim) behind its robot bridge, all on loopback; prints the URL
// and runs until Ctrl-C (or SIGTERM), then stops its children.
// Pages may attach a cube video to their session: the embedded cube
// tracker reads the studio's cube_dir (a folder of the run's temporary one).
// --coordinator uses a running stack instead (no embedded stack, no pleo_sim),
// reached with the CLI's TLS files (--ca/--cert/--key) when given.
// The studio asks for a token (StudioAuth): on loopback a new one is made at
// every start and the printed URL carries it (?token=, which becomes an
// HttpOnly cookie); any other --host needs --token-file (exit 2 without).
// --https-cert/--https-key serve the page over HTTPS and WSS (e.g. the
// studio.pem/.key of deploy/certs.sh).
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <string>
#include <thread>

#include "absl/strings/escaping.h"
#include "common/process/process.h"
#include "services/studio/core/token.h"
#include "services/cli/channel.h"
#include "services/cli/commands.h"
#include "services/cli/embedded_stack.h"

namespace kinemo::cli {
namespace {
namespace cmd_studio {  // this file's own helpers (the unity build puts files together)

struct StudioArgs {
  std::string host = "127.0.0.1";
  int port = 8080;
  std::string port_file;
  std::string coordinator;
  std::string config;
  std::string token_file;
  std::string https_cert, https_key;
  bool open = false;
  bool no_robot = false;
  double timeout_s = 60;
};

// Waits for a child's port file; "" (after printing why) if the child exits
// or the time runs out.
std::string WaitForPortFile(process::ChildProcess& child, const std::string& what, const std::string& path,
                            double timeout_s) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < deadline) {
    std::ifstream in(path);
    std::string port;
    if (in >> port && !port.empty()) return port;
    if (!child.Running()) {
      std::cerr << "kinemo studio: " << what << " exited (" << child.exit_code() << "):\n" << child.ReadLog();
      return "";
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  std::cerr << "kinemo studio: " << what << " did not start within " << timeout_s << " s:\n" << child.ReadLog();
  return "";
}

std::unique_ptr<process::ChildProcess> SpawnOrFail(const std::vector<std::string>& argv, const std::string& log) {
  auto child = process::ChildProcess::Spawn(argv, log);
  if (!child.ok()) FailCommand("studio", child.status(), {});
  return *std::move(child);
}

void Run(const StudioArgs& a) {
  if (a.token_file.empty() && !studio::IsLoopbackHost(a.host)) {
    std::cerr << "kinemo studio: --token-file: needed with --host " << a.host
              << " (not loopback): a file holding the token (16 or more of A-Z a-z 0-9 - _ . ~) that the "
                 "page and clients present; or listen on 127.0.0.1\n";
    throw CliExit{2};
  }
  const std::string studio = FindKinemoBinary("studio", "studio");
  if (studio.empty()) {
    std::cerr << "kinemo studio: the studio binary was not found beside kinemo, in the build tree or on PATH\n";
    throw CliExit{1};
  }
  process::TempDir dir;
  std::unique_ptr<process::ChildProcess> pleo_sim;
  EmbeddedStack embedded;
  std::string coordinator = a.coordinator;
  std::string cube_dir;  // the cube videos pages attach, read by the embedded cube tracker
  if (coordinator.empty()) {
    std::string config = a.config;
    if (config.empty()) {
      config = dir.File("allinone.textproto");
      cube_dir = dir.File("cube");
      std::filesystem::create_directories(cube_dir);
      std::string text = DefaultAllInOneConfig("studio") + "cube_tracker { file_root: \"" +
                         absl::CEscape(cube_dir) + "\" }\n";
      const std::string sim = a.no_robot ? "" : FindKinemoBinary("pleo_sim", "pleo_sim");
      if (!sim.empty()) {
        // A simulated Pleo for the Vleo-Pleo panel, behind the all-in-one's robot bridge.
        pleo_sim = SpawnOrFail({sim, "--tcp", "127.0.0.1:0", "--port-file", dir.File("pleo_sim.port")},
                               dir.File("pleo_sim.log"));
        const std::string port = WaitForPortFile(*pleo_sim, "pleo_sim", dir.File("pleo_sim.port"), a.timeout_s);
        if (port.empty()) throw CliExit{1};
        text += "robot_bridge { robots { robot_id: \"pleo\" tcp { host: \"127.0.0.1\" port: " + port +
                " } unit_id: 1 } }\n";
      }
      std::ofstream(config) << text;
    }
    coordinator = embedded.Start("studio", config, a.timeout_s);
    if (coordinator.empty()) throw CliExit{1};
  }
  std::string token_url_suffix;
  {
    // A running stack (--coordinator) is reached with the CLI's own TLS
    // files (--ca/--cert/--key or $KINEMO_TLS_*); the embedded one is plaintext on loopback.
    std::ofstream out(dir.File("studio.textproto"));
    out << "coordinator { address: \"" << coordinator << "\"";
    if (!a.coordinator.empty()) {
      const ClientTlsFiles tls = CliTlsFiles();
      const auto quoted = [](const std::string& path) {
        return "\"" + absl::CEscape(std::filesystem::absolute(path).string()) + "\"";
      };
      if (!tls.ca_file.empty()) out << " ca_file: " << quoted(tls.ca_file);
      if (!tls.cert_file.empty()) out << " cert_file: " << quoted(tls.cert_file);
      if (!tls.key_file.empty()) out << " key_file: " << quoted(tls.key_file);
    }
    out << " }\n";
    // The token: the user's file, or a new one on loopback (readable by
    // this user only), which the printed URL carries.
    std::string token_file = a.token_file.empty() ? "" : std::filesystem::absolute(a.token_file).string();
    if (token_file.empty()) {
      token_file = dir.File("studio.token");
      const std::string token = studio::NewToken();
      std::ofstream(token_file) << token << "\n";
      std::filesystem::permissions(token_file,
                                   std::filesystem::perms::owner_read | std::filesystem::perms::owner_write);
      token_url_suffix = "?token=" + token;
    }
    out << "auth { token_file: \"" << absl::CEscape(token_file) << "\" }\n";
    if (!cube_dir.empty()) out << "cube_dir: \"" << absl::CEscape(cube_dir) << "\"\n";
    if (!a.https_cert.empty()) {
      out << "server { tls { cert_file: \"" << absl::CEscape(std::filesystem::absolute(a.https_cert).string())
          << "\" key_file: \"" << absl::CEscape(std::filesystem::absolute(a.https_key).string()) << "\" } }\n";
    }
  }
  const std::string port_file = a.port_file.empty() ? dir.File("studio.port") : a.port_file;
  auto child = SpawnOrFail({studio, "--config", dir.File("studio.textproto"), "--host", a.host, "--port",
                            std::to_string(a.port), "--port-file", port_file},
                           dir.File("studio.log"));
  const std::string port = WaitForPortFile(*child, "the studio", port_file, a.timeout_s);
  if (port.empty()) throw CliExit{1};
  const std::string host = a.host.find(':') != std::string::npos ? "[" + a.host + "]" : a.host;
  const std::string url = (a.https_cert.empty() ? "http://" : "https://") + host + ":" + port + "/" + token_url_suffix;
  std::cout << "kinemo studio: " << url << " (coordinator " << coordinator
            << (pleo_sim ? ", a simulated Pleo as robot \"pleo\"" : "") << "); Ctrl-C stops it" << std::endl;
  if (a.open) {
    auto opener = process::ChildProcess::Spawn({"/usr/bin/xdg-open", url}, dir.File("open.log"));
    if (!opener.ok()) std::cerr << "kinemo studio: --open: " << opener.status().message() << "\n";
  }
  // Until Ctrl-C / SIGTERM, or until the studio exits by itself.
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  const timespec second{1, 0};
  while (sigtimedwait(&set, nullptr, &second) < 0) {
    if (!child->Running()) {
      std::cerr << "kinemo studio: the studio exited (" << child->exit_code() << "):\n" << child->ReadLog();
      throw CliExit{1};
    }
  }
  std::cout << "kinemo studio: stopping" << std::endl;
  (void)child->Stop(SIGTERM, std::chrono::seconds(10));
  if (pleo_sim) (void)pleo_sim->Stop(SIGTERM, std::chrono::seconds(5));
}

}  // namespace cmd_studio
}  // namespace

void RegisterStudioCommands(CLI::App& app) {
  using namespace cmd_studio;
  auto* cmd = app.add_subcommand(
      "studio",
      "The web studio: kinemo studio [--open] [--port P] [--port-file F] [--token-file F] [--https-cert F "
      "--https-key F] (embedded stack, prints the URL with its token)");
  auto a = std::make_shared<StudioArgs>();
  cmd->add_option("--host", a->host, "address the studio listens on (default 127.0.0.1: this machine only)");
  cmd->add_option("--port", a->port, "the studio's port (default 8080; 0 = any free port)")->check(CLI::Range(0, 65535));
  cmd->add_option("--port-file", a->port_file, "write the studio's port here once it listens");
  cmd->add_flag("--open", a->open, "open the page in the desktop's browser (xdg-open)");
  cmd->add_option("--coordinator", a->coordinator,
                  "use this coordinator (a running stack) instead of an embedded kinemo_allinone");
  cmd->add_option("--allinone-config", a->config,
                  "options file of the embedded kinemo_allinone (default: the bundled gesture library and "
                  "models, a simulated Pleo)");
  cmd->add_option("--token-file", a->token_file,
                  "a file holding the token the page and clients present (needed with a --host other than "
                  "loopback; default: a new token at every start, in the printed URL)");
  auto* cert = cmd->add_option("--https-cert", a->https_cert,
                                "serve the page over HTTPS/WSS with this certificate (PEM; e.g. deploy/certs.sh's "
                                "studio.pem)")
                   ->check(CLI::ExistingFile);
  auto* key = cmd->add_option("--https-key", a->https_key, "the key of --https-cert (PEM)")->check(CLI::ExistingFile);
  cert->needs(key);
  key->needs(cert);
  cmd->add_flag("--no-robot", a->no_robot, "no simulated Pleo in the embedded stack");
  cmd->add_option("--timeout-s", a->timeout_s, "how long each part may take to start (default 60)")
      ->check(CLI::Range(1.0, 600.0));
  cmd->callback([a] { Run(*a); });
}

}  // namespace kinemo::cli
