// kinemo animate FILE.wav -o OUT.bvh [--visemes OUT.json] — speech to body
// motion through the coordinator: Animate (the whole recording at once), or
// with --stream StreamAnimate (20 ms PCM chunks, at real-time pace with
// --realtime), printing the live timing as a user feels it
// (services/coordinator/client/live_client.h). Against a running stack
// (--coordinator, default localhost:50050), or, when none answers (or with
// --embedded), through a kinemo_allinone child started on an ephemeral port
// and stopped afterwards (embedded_stack.h).

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>

#include "common/audio/decode.h"
#include "common/motion/bvh.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "nlohmann/json.hpp"
#include "services/cli/channel.h"
#include "services/cli/commands.h"
#include "services/cli/embedded_stack.h"
#include "services/cli/proto_json.h"
#include "services/cli/retarget_files.h"
#include "services/coordinator/client/live_client.h"

namespace kinemo::cli {

namespace {

namespace v1 = ::kinemo::coordinator::v1;
namespace fs = std::filesystem;

struct AnimateArgs {
  std::string input, output, visemes, coordinator, method, config;
  std::string model, controller, graph, summary, library;
  std::string rig, rig_map;  // --rig, --map (cmd_animate_rig.cc)
  std::string rig_id;        // --rig-id: a stored rig (the server retargets)
  std::vector<std::string> keywords;
  double timeout_s = 0;
  bool embedded = false, json = false, stream = false, realtime = false;
};

// The embedded stack is this process's own plaintext child; a stack named
// with --coordinator is reached with the TLS options (--ca/--cert/--key).
std::shared_ptr<grpc::Channel> CoordinatorChannel(const std::string& address, bool embedded) {
  return embedded ? LocalChannel(address) : ServerChannel(address);
}

v1::AnimateRequest AnimateRequestFor(const AnimateArgs& a) {
  std::ifstream in(a.input, std::ios::binary);
  if (!in) {
    std::cerr << "kinemo animate: file: cannot read " << a.input << "\n";
    throw CliExit{2};
  }
  std::stringstream ss;
  ss << in.rdbuf();
  v1::AnimateRequest req;
  req.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_FILE);
  req.mutable_audio()->set_data(ss.str());
  req.mutable_audio()->set_name(fs::path(a.input).filename().string());
  if (a.method.empty()) req.set_method(v1::METHOD_UNSPECIFIED);
  else if (a.method == "gc") req.set_method(v1::METHOD_GESTURE_CONTROLLER);
  else if (a.method == "gmg") req.set_method(v1::METHOD_GMG);
  else if (a.method == "bodyspeech") req.set_method(v1::METHOD_BODYSPEECH);
  else {
    std::cerr << "kinemo animate: --method: '" << a.method << "' is not gc, gmg or bodyspeech\n";
    throw CliExit{2};
  }
  req.mutable_models()->set_inference_model_id(a.model);
  req.mutable_models()->set_controller_id(a.controller);
  req.mutable_models()->set_gesture_graph_id(a.graph);
  req.mutable_models()->set_rig_id(a.rig_id);
  for (const auto& k : a.keywords) req.add_keywords(k);
  req.set_visemes(!a.visemes.empty());
  req.set_format(common::v1::MOTION_FORMAT_BVH);
  return req;
}

void RunAnimate(const AnimateArgs& a, const std::shared_ptr<grpc::Channel>& channel,
                const v1::AnimateRequest& req) {
  auto stub = v1::CoordinatorService::NewStub(channel);
  const double timeout_s =
      a.timeout_s > 0 ? a.timeout_s : 10.0 + 0.2 * (req.audio().data().size() / 32000.0);
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
  std::ofstream(a.output, std::ios::binary) << resp.motion().bvh();
  if (!a.visemes.empty()) std::ofstream(a.visemes) << ProtoJson(resp.visemes()) << "\n";
  v1::AnimateResponse summary;
  *summary.mutable_prosody() = resp.prosody();
  *summary.mutable_times() = resp.times();
  summary.set_method(resp.method());
  summary.set_request_id(resp.request_id());
  if (!a.summary.empty()) std::ofstream(a.summary) << ProtoJson(summary) << "\n";
  if (a.json) {
    std::printf("%s\n", ProtoJson(summary).c_str());
  } else {
    std::printf("%s: %.2f s of speech, %u syllables, %d accents -> %s (%s)%s%s in %.2f s\n",
                a.input.c_str(), resp.prosody().duration_s(), resp.prosody().syllables(),
                resp.prosody().accents_size(), a.output.c_str(),
                v1::Method_Name(resp.method()).c_str(), a.visemes.empty() ? "" : " + ",
                a.visemes.c_str(), resp.times().total_s());
  }
}

// StreamAnimate: the BVH from the streamed header and frames, the visemes
// sent at the end, and the live timing.
void RunStream(const AnimateArgs& a, const std::shared_ptr<grpc::Channel>& channel,
               const audio::DecodedAudio& audio) {
  coordinator::LiveStreamOptions o;
  o.realtime = a.realtime;
  o.timeout_s = a.timeout_s;
  o.config.set_method(v1::METHOD_GESTURE_CONTROLLER);
  o.config.mutable_models()->set_inference_model_id(a.model);
  o.config.mutable_models()->set_controller_id(a.controller);
  o.config.mutable_models()->set_rig_id(a.rig_id);
  for (const auto& k : a.keywords) o.config.add_keywords(k);
  o.config.set_visemes(!a.visemes.empty());
  o.config.set_request_id(kinemo::StrCat("animate-stream-", fs::path(a.input).filename().string()));
  auto r = coordinator::RunLiveStream(channel, audio.samples, audio.sample_rate_hz, o);
  if (!r.ok()) FailCommand("animate", r.status(), {absl::StatusCode::kInvalidArgument});
  auto clip = coordinator::ClipFromStream(r->header, r->frames);
  if (!clip.ok()) FailCommand("animate", Annotate(clip.status(), "the stream"), {});
  if (Status s = motion::WriteBvhFile(*clip, a.output); !s.ok()) FailCommand("animate", s, {});
  if (!a.visemes.empty() && r->visemes) std::ofstream(a.visemes) << ProtoJson(*r->visemes) << "\n";
  if (!a.summary.empty()) std::ofstream(a.summary) << ProtoJson(r->summary) << "\n";
  if (a.json) {
    const nlohmann::json j = {{"motion_lag_p50_ms", r->motion_lag_p50_ms},
                              {"motion_lag_p99_ms", r->motion_lag_p99_ms},
                              {"first_frame_ms", r->first_frame_ms},
                              {"max_frame_gap_ms", r->max_frame_gap_ms},
                              {"frames", r->frames.size()},
                              {"audio_s", r->audio_s},
                              {"realtime", a.realtime},
                              {"max_chunk_late_ms", r->max_chunk_late_ms},
                              {"beliefs", r->summary.beliefs()},
                              {"decisions", r->summary.decisions()}};
    std::printf("%s\n", j.dump().c_str());
  } else {
    std::printf("%s: %.2f s streamed%s -> %s (%zu frames)%s%s\n"
                "motion lag p50 %.1f ms  p99 %.1f ms   first frame %.1f ms   longest frame gap %.1f ms\n",
                a.input.c_str(), r->audio_s, a.realtime ? " at real-time pace" : "", a.output.c_str(),
                r->frames.size(), a.visemes.empty() ? "" : " + ", a.visemes.c_str(), r->motion_lag_p50_ms,
                r->motion_lag_p99_ms, r->first_frame_ms, r->max_frame_gap_ms);
  }
}

}  // namespace

void RegisterAnimateCommands(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "animate",
      "Speech to body motion: kinemo animate FILE.wav -o OUT.bvh [--visemes OUT.json] [--stream [--realtime]]");
  auto a = std::make_shared<AnimateArgs>();
  cmd->add_option("file", a->input, "recording (WAV, FLAC, ... any file libsndfile reads)")
      ->required();
  cmd->add_option("-o,--out", a->output, "BVH to write (required)");
  AddDeprecatedOption(cmd, "--output", "--out", a->output);
  cmd->add_option("--visemes", a->visemes, "viseme tracks to write (JSON; runs the recogniser)");
  cmd->add_option("--coordinator", a->coordinator,
                  "coordinator address (default localhost:50050; if none answers, an embedded "
                  "kinemo_allinone is started)");
  cmd->add_flag("--embedded", a->embedded, "always use an embedded kinemo_allinone");
  cmd->add_option("--allinone-config", a->config,
                  "options file of the embedded kinemo_allinone (default: the bundled gesture library, BodySpeech)");
  cmd->add_option("-m,--method", a->method,
                  "gc (Gesture Controller) | gmg | bodyspeech (default: the coordinator's; embedded: bodyspeech)");
  cmd->add_option("--library", a->library,
                  "a bundled set of models by name: the model, controller and gesture graph of that id "
                  "(bundled: the conversational default, BEAT2, SMPL-X skeleton; bandai: the emblems, "
                  "Bandai skeleton); --model-id/--controller-id/--graph-id override its parts");
  cmd->add_option("--model-id", a->model, "inference model id (gc)");
  cmd->add_option("--controller-id", a->controller, "controller id (gc)");
  cmd->add_option("--graph-id", a->graph, "gesture graph id (gmg, bodyspeech)");
  AddDeprecatedOption(cmd, "--model", "--model-id", a->model);
  AddDeprecatedOption(cmd, "--controller", "--controller-id", a->controller);
  AddDeprecatedOption(cmd, "--graph", "--graph-id", a->graph);
  cmd->add_option("--keyword", a->keywords, "keyword to spot for semantic gestures (gc)");
  cmd->add_option("--summary", a->summary,
                  "write the prosody summary and stage times (JSON; with --stream, the stream's summary)");
  cmd->add_option("--timeout-s", a->timeout_s,
                  "deadline (0 = 10 s + 0.2 s per second of audio; with --stream 60 s + 3 s per second)");
  cmd->add_flag("--json", a->json,
                "print the summary as JSON (with --stream: motion_lag_p50_ms, motion_lag_p99_ms, first_frame_ms, "
                "max_frame_gap_ms, frames, audio_s, max_chunk_late_ms)");
  cmd->add_flag("--stream", a->stream,
                "stream 20 ms PCM chunks through StreamAnimate (Gesture Controller) and print the live timing");
  cmd->add_flag("--realtime", a->realtime, "with --stream: send the chunks at real-time pace");
  cmd->add_option("--rig", a->rig,
                  "put the motion on this character (.glb/.gltf/.vrm; -o OUT.glb or OUT.bvh): kinemo retarget");
  cmd->add_option("--map", a->rig_map, "with --rig: JSON role map of the rig");
  cmd->add_option("--rig-id", a->rig_id,
                  "a rig stored in the stack (kinemo rig push): the server puts the motion (BVH, or the "
                  "streamed frames) on its skeleton")
      ->excludes("--rig");
  cmd->callback([a] {
    if (a->output.empty()) {
      std::cerr << "kinemo animate: --out is required\n";
      throw CliExit{2};
    }
    if (!a->library.empty()) {
      if (a->model.empty()) a->model = a->library;
      if (a->controller.empty()) a->controller = a->library;
      if (a->graph.empty()) a->graph = a->library;
    }
    if (a->realtime && !a->stream) {
      std::cerr << "kinemo animate: --realtime: needs --stream\n";
      throw CliExit{2};
    }
    if (a->stream && !a->method.empty() && a->method != "gc") {
      std::cerr << "kinemo animate: --method: only gc runs live (--stream)\n";
      throw CliExit{2};
    }
    std::optional<AnimateRig> rig;
    if (!a->rig.empty()) {
      auto prepared = PrepareAnimateRig(a->rig, a->rig_map, &a->output);
      if (!prepared.ok()) FailCommand("animate", prepared.status(), {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound});
      rig = *std::move(prepared);
    } else if (!a->rig_map.empty()) {
      std::cerr << "kinemo animate: --map: needs --rig\n";
      throw CliExit{2};
    }
    // Read the input before any stack starts.
    std::optional<v1::AnimateRequest> request;
    std::optional<audio::DecodedAudio> pcm;
    if (a->stream) {
      auto decoded = audio::DecodeAudioFile(a->input);
      if (!decoded.ok()) {
        FailCommand("animate", Annotate(decoded.status(), "file"),
                    {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound});
      }
      pcm = *std::move(decoded);
    } else {
      request = AnimateRequestFor(*a);
    }

    EmbeddedStack embedded;
    std::string address = a->coordinator;
    const bool use_embedded = a->embedded || (address.empty() && !Reachable("localhost:50050", 0.3));
    if (use_embedded) {
      address = embedded.Start("animate", a->config, 60.0);
      if (address.empty()) throw CliExit{1};
    } else if (address.empty()) {
      address = "localhost:50050";
    }
    const auto channel = CoordinatorChannel(address, use_embedded);
    if (a->stream) {
      RunStream(*a, channel, *pcm);
    } else {
      RunAnimate(*a, channel, *request);
    }
    if (rig) {
      if (Status s = RetargetAnimateResult(*rig, a->json); !s.ok()) FailCommand("animate", s, {});
    }
  });
}

}  // namespace kinemo::cli
