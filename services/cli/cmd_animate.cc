// kinemo animate FILE.wav -o OUT.bvh [--visemes OUT.json] — speech to body
// motion through the coordinator's Animate: against a running stack
// (--coordinator, default localhost:50050), or, when none answers (or with
// --embedded), through a kinemo_allinone child started on an ephemeral port
// and stopped afterwards.

#include <google/protobuf/util/json_util.h>
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <thread>

#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "common/testing/process.h"
#include "services/cli/channel.h"
#include "services/cli/commands.h"
#include "services/cli/proto_json.h"

namespace kinemo::cli {

namespace {

namespace v1 = ::kinemo::coordinator::v1;
namespace fs = std::filesystem;

// Where kinemo_allinone is: $KINEMO_ALLINONE, beside this binary, in the
// build tree's services/allinone, or on PATH.
std::string FindAllInOne() {
  if (const char* env = std::getenv("KINEMO_ALLINONE"); env != nullptr && *env) return env;
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    for (const fs::path& p : {self.parent_path() / "kinemo_allinone",
                              self.parent_path().parent_path() / "allinone" / "kinemo_allinone"}) {
      if (fs::exists(p, ec)) return p.string();
    }
  }
  if (const char* path = std::getenv("PATH")) {
    std::stringstream ss(path);
    std::string dir;
    while (std::getline(ss, dir, ':')) {
      const fs::path p = fs::path(dir) / "kinemo_allinone";
      if (fs::exists(p, ec)) return p.string();
    }
  }
  return "";
}

// The bundled gesture library (Bandai gesture clips): $KINEMO_GESTURE_LIBRARY,
// <prefix>/share/kinemo/gestures beside an installed binary, or the source
// tree's tests/data. Returns the library root and the folders in it, or "".
std::string FindGestureLibrary(std::vector<std::string>* folders) {
  const std::vector<std::string> kFolders = {"planner_gesture", "planner_controller"};
  std::error_code ec;
  std::vector<fs::path> roots;
  if (const char* env = std::getenv("KINEMO_GESTURE_LIBRARY"); env != nullptr && *env) roots.emplace_back(env);
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) roots.push_back(self.parent_path().parent_path() / "share" / "kinemo" / "gestures");
#ifdef KINEMO_CLI_TEST_DATA_DIR
  roots.emplace_back(KINEMO_CLI_TEST_DATA_DIR);
#endif
  for (const fs::path& root : roots) {
    folders->clear();
    for (const auto& f : kFolders) {
      if (fs::is_directory(root / f, ec)) folders->push_back(f);
    }
    if (!folders->empty()) return fs::absolute(root, ec).string();
  }
  return "";
}

// Options of the embedded kinemo_allinone when none are given: the bundled
// gesture library and a BodySpeech gesture graph over it ("bundled"), so that
// Animate works out of the box; the Gesture Controller needs a trained model
// and controller (--allinone-config).
std::string DefaultAllInOneConfig() {
  std::vector<std::string> folders;
  const std::string root = FindGestureLibrary(&folders);
  std::string config = "# written by kinemo animate\n";
  if (root.empty()) return config;
  config += "coordinator { animate { default_method: METHOD_BODYSPEECH models { gesture_graph_id: \"bundled\" } } }\n";
  config += "planner {\n  library_root: \"" + root + "\"\n  preload { library_id: \"bundled\"";
  for (const auto& f : folders) config += " paths: \"" + f + "\"";
  config += " }\n  preload_gesture_graphs { graph_id: \"bundled\" library_id: \"bundled\" params { stroke_phrases: true } }\n}\n";
  return config;
}

// A kinemo_allinone child on an ephemeral loopback port, ready (health
// SERVING) when Start returns; SIGTERM on scope exit.
class EmbeddedStack {
 public:
  // Returns the address, or "" after printing why it could not start.
  std::string Start(const std::string& config, double timeout_s) {
    const std::string binary = FindAllInOne();
    if (binary.empty()) {
      std::cerr << "kinemo animate: kinemo_allinone not found (set KINEMO_ALLINONE, or start a "
                   "stack and pass --coordinator)\n";
      return "";
    }
    std::string config_file = config;
    if (config_file.empty()) {
      config_file = dir_.File("allinone.textproto");
      std::ofstream(config_file) << DefaultAllInOneConfig();
    }
    auto started = testing::ServiceProcess::Start(
        {.binary = binary,
         .args = {"--config", config_file},
         .ready_timeout = std::chrono::milliseconds(static_cast<int64_t>(timeout_s * 1000))});
    if (!started.ok()) {
      std::cerr << "kinemo animate: " << started.status().message() << "\n";
      return "";
    }
    stack_ = *std::move(started);
    return stack_->address();
  }

 private:
  testing::TempDir dir_;
  std::unique_ptr<testing::ServiceProcess> stack_;
};

bool Reachable(const std::string& address, double timeout_s) {
  auto channel = ServerChannel(address);
  return channel->WaitForConnected(std::chrono::system_clock::now() +
                                   std::chrono::milliseconds(static_cast<int64_t>(timeout_s * 1000)));
}

}  // namespace

void RegisterAnimateCommands(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "animate", "Speech to body motion: kinemo animate FILE.wav -o OUT.bvh [--visemes OUT.json]");
  struct Args {
    std::string input, output, visemes, coordinator, method, config;
    std::string model, controller, graph, summary;
    std::vector<std::string> keywords;
    double timeout_s = 0;
    bool embedded = false, json = false;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("file", a->input, "recording (WAV, FLAC, ... any file libsndfile reads)")
      ->required();
  cmd->add_option("-o,--output", a->output, "BVH to write")->required();
  cmd->add_option("--visemes", a->visemes, "viseme tracks to write (JSON; runs the recogniser)");
  cmd->add_option("--coordinator", a->coordinator,
                  "coordinator address (default localhost:50050; if none answers, an embedded "
                  "kinemo_allinone is started)");
  cmd->add_flag("--embedded", a->embedded, "always use an embedded kinemo_allinone");
  cmd->add_option("--allinone-config", a->config,
                  "options file of the embedded kinemo_allinone (default: the bundled gesture library, BodySpeech)");
  cmd->add_option("-m,--method", a->method,
                  "gc (Gesture Controller) | gmg | bodyspeech (default: the coordinator's; embedded: bodyspeech)");
  cmd->add_option("--model", a->model, "inference model id (gc)");
  cmd->add_option("--controller", a->controller, "controller id (gc)");
  cmd->add_option("--graph", a->graph, "gesture graph id (gmg, bodyspeech)");
  cmd->add_option("--keyword", a->keywords, "keyword to spot for semantic gestures (gc)");
  cmd->add_option("--summary", a->summary, "write the prosody summary and stage times (JSON)");
  cmd->add_option("--timeout-s", a->timeout_s, "deadline (0 = 10 s + 0.2 s per second of audio)");
  cmd->add_flag("--json", a->json, "print the summary as JSON");
  cmd->callback([a] {
    std::ifstream in(a->input, std::ios::binary);
    if (!in) {
      std::cerr << "kinemo animate: file: cannot read " << a->input << "\n";
      throw CliExit{2};
    }
    std::stringstream ss;
    ss << in.rdbuf();
    v1::AnimateRequest req;
    req.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_FILE);
    req.mutable_audio()->set_data(ss.str());
    req.mutable_audio()->set_name(fs::path(a->input).filename().string());
    if (a->method.empty()) req.set_method(v1::METHOD_UNSPECIFIED);
    else if (a->method == "gc") req.set_method(v1::METHOD_GESTURE_CONTROLLER);
    else if (a->method == "gmg") req.set_method(v1::METHOD_GMG);
    else if (a->method == "bodyspeech") req.set_method(v1::METHOD_BODYSPEECH);
    else {
      std::cerr << "kinemo animate: --method: '" << a->method << "' is not gc, gmg or bodyspeech\n";
      throw CliExit{2};
    }
    req.mutable_models()->set_inference_model_id(a->model);
    req.mutable_models()->set_controller_id(a->controller);
    req.mutable_models()->set_gesture_graph_id(a->graph);
    for (const auto& k : a->keywords) req.add_keywords(k);
    req.set_visemes(!a->visemes.empty());
    req.set_format(common::v1::MOTION_FORMAT_BVH);

    EmbeddedStack embedded;
    std::string address = a->coordinator;
    const bool use_embedded = a->embedded || (address.empty() && !Reachable("localhost:50050", 0.3));
    if (use_embedded) {
      address = embedded.Start(a->config, 60.0);
      if (address.empty()) throw CliExit{1};
    } else if (address.empty()) {
      address = "localhost:50050";
    }
    // The embedded stack is this process's own plaintext child; a stack
    // named with --coordinator is reached with the TLS options.
    auto stub = v1::CoordinatorService::NewStub(use_embedded ? LocalChannel(address)
                                                                    : ServerChannel(address));
    const double timeout_s =
        a->timeout_s > 0 ? a->timeout_s : 10.0 + 0.2 * (req.audio().data().size() / 32000.0);
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() +
                     std::chrono::milliseconds(static_cast<int64_t>(timeout_s * 1000)));
    ctx.set_wait_for_ready(true);
    v1::AnimateResponse resp;
    grpc::Status s = stub->Animate(&ctx, req, &resp);
    if (!s.ok()) {
      std::cerr << "kinemo animate: " << s.error_message() << " (code "
                << static_cast<int>(s.error_code()) << ")\n";
      throw CliExit{s.error_code() == grpc::StatusCode::INVALID_ARGUMENT ? 2 : 1};
    }
    if (!resp.motion().has_bvh()) {
      std::cerr << "kinemo animate: the coordinator returned no BVH\n";
      throw CliExit{1};
    }
    std::ofstream(a->output, std::ios::binary) << resp.motion().bvh();
    if (!a->visemes.empty()) std::ofstream(a->visemes) << ProtoJson(resp.visemes()) << "\n";
    v1::AnimateResponse summary;
    *summary.mutable_prosody() = resp.prosody();
    *summary.mutable_times() = resp.times();
    summary.set_method(resp.method());
    summary.set_request_id(resp.request_id());
    if (!a->summary.empty()) std::ofstream(a->summary) << ProtoJson(summary) << "\n";
    if (a->json) {
      std::printf("%s\n", ProtoJson(summary).c_str());
    } else {
      std::printf("%s: %.2f s of speech, %u syllables, %d accents -> %s (%s)%s%s in %.2f s\n",
                  a->input.c_str(), resp.prosody().duration_s(), resp.prosody().syllables(),
                  resp.prosody().accents_size(), a->output.c_str(),
                  v1::Method_Name(resp.method()).c_str(), a->visemes.empty() ? "" : " + ",
                  a->visemes.c_str(), resp.times().total_s());
    }
  });
}

}  // namespace kinemo::cli
