// kinemo animate FILE.wav -o OUT.bvh [--visemes OUT.json] — speech to body
// motion through the coordinator: Animate (the whole recording at once), or
// with --stream StreamAnimate (20 ms PCM chunks, at real-time pace with
// --realtime), printing the live timing as a user feels it
// (services/coordinator/client/live_client.h). Against a running stack
// (--coordinator, default localhost:50050), or, when none answers (or with
// --embedded), through a kinemo_allinone child started on an ephemeral port
// and stopped afterwards (embedded_stack.h).
//
// With --cube-video CUBE.avi (and --stream): a cube session plays the video
// through the cube tracker in real time, and the stream follows it
// (StreamAnimateConfig.session_id: the cube's top face picks the tone, its
// rotation the weight and the gesture emphasis); --json adds tone_changes
// [{t_s, tone, weight, gesture_emphasis, latency_ms, ...}] and the session's
// final emotion. The embedded stack's cube tracker may read the video's
// folder (its file_root).

#include <grpcpp/grpcpp.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>

#include "common/audio/decode.h"
#include "common/face/face_frame.h"
#include "common/face/face_json.h"
#include "common/face/face_proto.h"
#include "common/motion/bvh.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "nlohmann/json.hpp"
#include "services/cli/animate_vmc.h"
#include "services/cli/channel.h"
#include "services/cli/commands.h"
#include "services/cli/embedded_stack.h"
#include "services/cli/proto_json.h"
#include "services/cli/retarget_files.h"
#include "services/coordinator/client/cube_session.h"
#include "services/coordinator/client/live_client.h"

namespace kinemo::cli {

namespace {
namespace cmd_animate {  // this file's own helpers (the unity build puts files together)

namespace v1 = ::kinemo::coordinator::v1;
namespace fs = std::filesystem;

struct AnimateArgs {
  std::string input, output, visemes, coordinator, method, config;
  std::string model, controller, graph, summary, library;
  std::string rig, rig_map;  // --rig, --map (cmd_animate_rig.cc)
  std::string face_map;      // --face-map (with --rig)
  std::string rig_id;        // --rig-id: a stored rig (the server retargets)
  std::vector<std::string> keywords;
  std::string cube_video, cube_camera, cube_model, robot = "pleo";
  std::vector<std::string> cube_tones;  // ACTION=TONE
  double timeout_s = 0;
  bool embedded = false, json = false, stream = false, realtime = false;
  AnimateVmcArgs vmc;  // --vmc (animate_vmc.h)
};

// The embedded stack is this process's own plaintext child; a stack named
// with --coordinator is reached with the TLS options (--ca/--cert/--key).
// The deepest folder holding both files.
std::string CommonFolder(const fs::path& a, const fs::path& b) {
  const fs::path pa = a.parent_path(), pb = b.parent_path();
  fs::path out;
  auto ia = pa.begin(), ib = pb.begin();
  for (; ia != pa.end() && ib != pb.end() && *ia == *ib; ++ia, ++ib) out /= *ia;
  return out.string();
}

// A viseme track as a face track (common/face/face_json.h reads the viseme
// file's layout: OVR weights from the categories, no jaw, blinks or
// expression). nullopt, with a warning, when it cannot be read.
std::optional<face::FaceTrack> FaceOfVisemes(const planner::v1::VisemeTrack& visemes) {
  if (visemes.frames_size() == 0) return std::nullopt;
  std::string json;
  google::protobuf::util::JsonPrintOptions o;
  o.preserve_proto_field_names = true;
  o.always_print_primitive_fields = true;
  (void)google::protobuf::util::MessageToJsonString(visemes, &json, o);
  auto track = face::FaceTrackFromJson(json, "the animate result's visemes");
  if (!track.ok()) {
    std::cerr << "kinemo animate: warning: no face on the rig: " << track.status().message() << "\n";
    return std::nullopt;
  }
  return *std::move(track);
}

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
  // --rig: the visemes give the character's mouth (FaceOfVisemes).
  req.set_visemes(!a.visemes.empty() || !a.rig.empty());
  req.set_format(common::v1::MOTION_FORMAT_BVH);
  return req;
}

// `face` receives the response's face for --rig: today the viseme track
// (the mouth); the hook for the coordinator's FaceTrack (jaw, blinks, brows,
// expression too) once AnimateResponse carries one is here.
void RunAnimate(const AnimateArgs& a, const std::shared_ptr<grpc::Channel>& channel,
                const v1::AnimateRequest& req, std::optional<face::FaceTrack>* face) {
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
  // Every face channel (docs/face.md); a stack without a face model: the visemes alone.
  if (!a.visemes.empty()) {
    std::ofstream(a.visemes) << (resp.face().frames_size() > 0 ? face::FaceTrackToJson(face::FromProto(resp.face()))
                                                                : ProtoJson(resp.visemes()))
                             << "\n";
  }
  // --rig: the response's face track; a stack without a face model: its visemes.
  if (!a.rig.empty()) {
    *face = resp.face().frames_size() > 0 ? std::optional<face::FaceTrack>(face::FromProto(resp.face()))
                                          : FaceOfVisemes(resp.visemes());
  }
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
               const audio::DecodedAudio& audio, std::optional<face::FaceTrack>* face) {
  coordinator::LiveStreamOptions o;
  o.realtime = a.realtime;
  o.timeout_s = a.timeout_s;
  o.config.set_method(v1::METHOD_GESTURE_CONTROLLER);
  o.config.mutable_models()->set_inference_model_id(a.model);
  o.config.mutable_models()->set_controller_id(a.controller);
  o.config.mutable_models()->set_rig_id(a.rig_id);
  for (const auto& k : a.keywords) o.config.add_keywords(k);
  // With a face model the frames carry the face; the end-of-stream visemes
  // (the recogniser over the whole stream) are asked for only as a fallback.
  o.config.set_visemes(!a.visemes.empty());
  o.config.set_request_id(kinemo::StrCat("animate-stream-", fs::path(a.input).filename().string()));
  for (const auto& m : a.cube_tones) {
    const auto eq = m.find('=');
    if (eq == std::string::npos) {
      std::cerr << "kinemo animate: --cube-tone: '" << m << "' is not ACTION=TONE\n";
      throw CliExit{2};
    }
    (*o.config.mutable_cube_tones())[m.substr(0, eq)] = m.substr(eq + 1);
  }
  std::string session;
  if (!a.cube_video.empty()) {
    coordinator::CubeSessionOptions co;
    co.robot_id = a.robot;
    co.video = fs::absolute(a.cube_video).string();
    co.camera = fs::absolute(a.cube_camera).string();
    co.cube_model_file = a.cube_model;
    auto id = coordinator::OpenCubeSession(channel, co);
    if (!id.ok()) FailCommand("animate", Annotate(id.status(), "--cube-video"), {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound});
    session = *id;
    o.config.set_session_id(session);
  }
  std::unique_ptr<AnimateVmc> vmc;
  if (!a.vmc.address.empty()) {
    auto opened = AnimateVmc::Open(a.vmc);
    if (!opened.ok()) FailCommand("animate", opened.status(), {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound});
    vmc = *std::move(opened);
    o.on_frame = [&vmc](const auto& header, const auto& frame, auto audio_sent) { vmc->OnFrame(header, frame, audio_sent); };
  }
  auto r = coordinator::RunLiveStream(channel, audio.samples, audio.sample_rate_hz, o);
  std::optional<v1::Session> final_session;
  if (!session.empty()) {
    if (auto s = coordinator::GetCubeSession(channel, session); s.ok()) final_session = *s;
    (void)coordinator::CloseCubeSession(channel, session);
  }
  if (!r.ok()) FailCommand("animate", r.status(), {absl::StatusCode::kInvalidArgument});
  if (vmc && !vmc->status().ok()) FailCommand("animate", vmc->status(), {absl::StatusCode::kInvalidArgument});
  auto clip = coordinator::ClipFromStream(r->header, r->frames);
  if (!clip.ok()) FailCommand("animate", Annotate(clip.status(), "the stream"), {});
  if (Status s = motion::WriteBvhFile(*clip, a.output); !s.ok()) FailCommand("animate", s, {});
  // The face frames as received live (each with its motion frame); a stack
  // without a face model: the visemes sent at the end. With --rig they go
  // onto the character.
  if (r->face_frames > 0) {
    face::FaceTrack live;
    live.frame_time_s = r->header.frame_time_s();
    for (const auto& f : r->frames) {
      live.frames.push_back(face::FromProto(f.face()));
      live.frames.back().time_s = f.time_s();
    }
    if (!a.visemes.empty()) std::ofstream(a.visemes) << face::FaceTrackToJson(live) << "\n";
    if (!a.rig.empty()) *face = std::move(live);
  } else if (r->visemes) {
    if (!a.visemes.empty()) std::ofstream(a.visemes) << ProtoJson(*r->visemes) << "\n";
    if (!a.rig.empty()) *face = FaceOfVisemes(*r->visemes);
  }
  if (!a.summary.empty()) std::ofstream(a.summary) << ProtoJson(r->summary) << "\n";
  if (a.json) {
    const nlohmann::json j = {{"motion_lag_p50_ms", r->motion_lag_p50_ms},
                              {"motion_lag_p99_ms", r->motion_lag_p99_ms},
                              {"first_frame_ms", r->first_frame_ms},
                              {"max_frame_gap_ms", r->max_frame_gap_ms},
                              {"face_frames", r->face_frames},
                              {"face_lag_p95_ms", r->face_lag_p95_ms},
                              {"frames", r->frames.size()},
                              {"audio_s", r->audio_s},
                              {"realtime", a.realtime},
                              {"max_chunk_late_ms", r->max_chunk_late_ms},
                              {"beliefs", r->summary.beliefs()},
                              {"decisions", r->summary.decisions()}};
    nlohmann::json out = j;
    if (vmc) vmc->AddJson(&out);
    if (!session.empty()) {
      nlohmann::json tones = nlohmann::json::array();
      for (const auto& t : r->tone_changes) {
        tones.push_back({{"t_s", t.change.t_s()}, {"tone", t.change.tone()}, {"weight", t.change.weight()},
                         {"latency_ms", t.latency_ms}, {"action", common::v1::Action_Name(t.change.action())},
                         {"intensity", t.change.intensity()}, {"gesture_emphasis", t.change.gesture_emphasis()},
                         {"superseded", t.change.superseded()}});
      }
      out["tone_changes"] = tones;
      out["session_id"] = session;
      if (final_session) {
        out["emotion"] = common::v1::Emotion_Name(final_session->emotion());
        out["robot_emotion"] = common::v1::Emotion_Name(final_session->robot_emotion());
      }
    }
    std::printf("%s\n", out.dump().c_str());
  } else {
    std::printf("%s: %.2f s streamed%s -> %s (%zu frames)%s%s\n"
                "motion lag p50 %.1f ms  p99 %.1f ms   first frame %.1f ms   longest frame gap %.1f ms\n",
                a.input.c_str(), r->audio_s, a.realtime ? " at real-time pace" : "", a.output.c_str(),
                r->frames.size(), a.visemes.empty() ? "" : " + ", a.visemes.c_str(), r->motion_lag_p50_ms,
                r->motion_lag_p99_ms, r->first_frame_ms, r->max_frame_gap_ms);
    if (vmc) std::printf("%s\n", vmc->Summary().c_str());
    for (const auto& t : r->tone_changes) {
      std::printf("tone %-10s weight %.2f emphasis %+.2f from %s at %.2f s, %.0f ms after the cube%s\n",
                  t.change.tone().c_str(), t.change.weight(), t.change.gesture_emphasis(),
                  common::v1::Action_Name(t.change.action()).c_str(), t.change.t_s(),
                  t.latency_ms, t.change.superseded() ? " (superseded)" : "");
    }
    if (final_session) {
      std::printf("session %s ends %s\n", session.c_str(), common::v1::Emotion_Name(final_session->emotion()).c_str());
    }
  }
}

}  // namespace cmd_animate
}  // namespace

void RegisterAnimateCommands(CLI::App& app) {
  using namespace cmd_animate;
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
  cmd->add_option("--cube-video", a->cube_video,
                  "with --stream: a cube video (e.g. `kinemo cube render`) drives the tone: the top face picks it "
                  "(idle -> neutral, kisses -> happy, shouting -> angry), the rotation its weight");
  cmd->add_option("--cube-camera", a->cube_camera, "with --cube-video: its camera file (default VIDEO.camera.yaml)");
  cmd->add_option("--cube-model", a->cube_model,
                  "with --cube-video: the cube (text proto; default the bundled tests/data/cube/vleo.cube, "
                  "else the tracker's default cube)");
  cmd->add_option("--cube-tone", a->cube_tones, "with --cube-video: ACTION=TONE (repeatable), e.g. idle=subdued");
  cmd->add_option("--robot", a->robot, "with --cube-video: the session's robot id")->capture_default_str();
  AddAnimateVmcOptions(cmd, &a->vmc);
  cmd->add_option("--rig", a->rig,
                  "put the motion on this character (.glb/.gltf/.vrm; -o OUT.glb or OUT.bvh): kinemo retarget");
  cmd->add_option("--map", a->rig_map, "with --rig: JSON role map of the rig");
  cmd->add_option("--face-map", a->face_map,
                  "with --rig: JSON face map of the rig (which morph targets / VRM expressions the face drives)");
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
    if (!a->cube_video.empty()) {
      if (!a->stream) {
        std::cerr << "kinemo animate: --cube-video: needs --stream\n";
        throw CliExit{2};
      }
      if (!fs::is_regular_file(a->cube_video)) {
        std::cerr << "kinemo animate: --cube-video: cannot read " << a->cube_video << "\n";
        throw CliExit{2};
      }
      if (a->cube_camera.empty()) a->cube_camera = a->cube_video + ".camera.yaml";
      if (a->cube_model.empty()) a->cube_model = BundledDataFile("cube/vleo.cube");
    }
    if (!a->vmc.address.empty()) {
      if (!a->stream) {
        std::cerr << "kinemo animate: --vmc: needs --stream\n";
        throw CliExit{2};
      }
      if (Status s = AnimateVmc::Validate(a->vmc); !s.ok()) FailCommand("animate", s, {absl::StatusCode::kInvalidArgument});
    }
    if (a->stream && !a->method.empty() && a->method != "gc") {
      std::cerr << "kinemo animate: --method: only gc runs live (--stream)\n";
      throw CliExit{2};
    }
    std::optional<AnimateRig> rig;
    if (!a->rig.empty()) {
      auto prepared = PrepareAnimateRig(a->rig, a->rig_map, &a->output, a->face_map);
      if (!prepared.ok()) FailCommand("animate", prepared.status(), {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound});
      rig = *std::move(prepared);
    } else if (!a->rig_map.empty() || !a->face_map.empty()) {
      std::cerr << "kinemo animate: " << (a->rig_map.empty() ? "--face-map" : "--map") << ": needs --rig\n";
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
      std::string config = a->config;
      if (config.empty() && !a->cube_video.empty()) {
        // The default options, and a cube tracker that may read the video and its camera.
        config = (fs::temp_directory_path() / kinemo::StrCat("kinemo-animate-", ::getpid(), ".textproto")).string();
        std::ofstream(config) << DefaultAllInOneConfig("animate") << "cube_tracker { file_root: \""
                              << CommonFolder(fs::absolute(a->cube_video), fs::absolute(a->cube_camera)) << "\" }\n";
      }
      address = embedded.Start("animate", config, 60.0);
      if (config != a->config) fs::remove(config);
      if (address.empty()) throw CliExit{1};
    } else if (address.empty()) {
      address = "localhost:50050";
    }
    const auto channel = CoordinatorChannel(address, use_embedded);
    std::optional<face::FaceTrack> face;
    if (a->stream) {
      RunStream(*a, channel, *pcm, &face);
    } else {
      RunAnimate(*a, channel, *request, &face);
    }
    if (rig) {
      rig->face = std::move(face);
      if (Status s = RetargetAnimateResult(*rig, a->json); !s.ok()) FailCommand("animate", s, {});
    }
  });
}

}  // namespace kinemo::cli
