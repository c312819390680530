// kinemo animate FILE -o OUT.bvh [--visemes OUT.json] — speech to body
// motion through the coordinator. The recording is read and resampled to
// 16 kHz mono here; under 90 s it goes in one Animate call, longer ones (up
// to 2 h) through AnimateChunked (sent in 1 s chunks, read block by block;
// the BVH written as its pieces arrive); both answer the face (visemes, jaw,
// blinks, brows, expression; the BVH's jaw driven by it) and the viseme
// track; progress on stderr for recordings of a
// minute or more. With --stream: StreamAnimate (20 ms PCM chunks, at
// real-time pace with --realtime), printing the live timing as a user feels it
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

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>

#include "absl/strings/match.h"
#include "common/audio/decode.h"
#include "common/audio/recording_reader.h"
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
#include "services/coordinator/client/animate_chunked_client.h"
#include "services/coordinator/client/cube_session.h"
#include "services/coordinator/client/live_client.h"

namespace kinemo::cli {

namespace {
namespace cmd_animate {  // this file's own helpers (the unity build puts files together)

namespace v1 = ::kinemo::coordinator::v1;
namespace fs = std::filesystem;

struct AnimateArgs {
  std::string input, output, visemes, coordinator, method, config;
  std::string bvh_output;    // where the BVH goes: --out, or a temporary file with --rig
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

// The recordings animate reads: any length up to this (2 h, the stack's
// animate.max_chunked_audio_s default).
constexpr double kMaxRecordingS = 7200;

StatusOr<v1::Method> MethodOf(const std::string& method) {
  if (method.empty()) return v1::METHOD_UNSPECIFIED;
  if (method == "gc") return v1::METHOD_GESTURE_CONTROLLER;
  if (method == "gmg") return v1::METHOD_GMG;
  if (method == "bodyspeech") return v1::METHOD_BODYSPEECH;
  return InvalidField("--method", "'", method, "' is not a method: gc, gmg or bodyspeech (see kinemo animate --help)");
}

v1::AnimateRequest AnimateRequestFor(const AnimateArgs& a, v1::Method method) {
  v1::AnimateRequest req;
  req.mutable_audio()->set_name(fs::path(a.input).filename().string());
  req.set_method(method);
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

// Peak resident memory of a process (VmHWM), in MB; 0 if unknown.
double PeakRssMb(pid_t pid) {
  std::ifstream in(pid == 0 ? std::string("/proc/self/status") : kinemo::StrCat("/proc/", pid, "/status"));
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmHWM:", 0) == 0) return std::strtod(line.c_str() + 6, nullptr) / 1024.0;
  }
  return 0;
}

// "1:02:03" / "4:05" / "7.1 s".
std::string Clock(double s) {
  const long t = std::lround(s);
  char buf[32];
  if (s < 60) {
    std::snprintf(buf, sizeof buf, "%.1f s", s);
  } else if (t >= 3600) {
    std::snprintf(buf, sizeof buf, "%ld:%02ld:%02ld", t / 3600, t / 60 % 60, t % 60);
  } else {
    std::snprintf(buf, sizeof buf, "%ld:%02ld", t / 60, t % 60);
  }
  return buf;
}

// A status from the stack (or the recording) in the words of the command
// line: the file or option instead of the request's fields, without the
// services' names, with what to do. The raw status goes in --json output.
std::string CliWords(const Status& s, const AnimateArgs& a, const std::string& address, bool embedded,
                     double timeout_s) {
  std::string m(s.message());
  for (const char* service : {"prosody: ", "planner: ", "inference: ", "coordinator: "}) {
    if (m.rfind(service, 0) == 0) m = m.substr(std::strlen(service));
  }
  static const std::pair<const char*, const char*> kFields[] = {
      {"config.request.models.rig_id", "--rig-id"},
      {"config.request.models.gesture_graph_id", "--graph-id"},
      {"config.request.models.inference_model_id", "--model-id"},
      {"config.request.models.controller_id", "--controller-id"},
      {"config.request.method", "--method"},
      {"config.request.keywords", "--keyword"},
      {"models.rig_id", "--rig-id"},
      {"models.gesture_graph_id", "--graph-id"},
      {"models.inference_model_id", "--model-id"},
      {"models.controller_id", "--controller-id"},
      {"rig_id", "--rig-id"},
      {"graph_id", "--graph-id"},
      {"controller_id", "--controller-id"},
      {"model_id", "--model-id"},
      {"method", "--method"},
  };
  bool named = false;
  for (const auto& [field, option] : kFields) {
    const std::size_t n = std::strlen(field);
    if (m.size() > n && m.compare(0, n, field) == 0 && (m[n] == ':' || m[n] == '[')) {
      m = option + m.substr(n);
      named = true;
      break;
    }
  }
  if (!named) {
    // The recording's fields (config.request.audio..., chunk..., audio...)
    // are the file.
    for (const char* field : {"config.request.audio", "chunk", "audio", "config"}) {
      const std::size_t n = std::strlen(field);
      if (m.size() > n && m.compare(0, n, field) == 0 && (m[n] == ':' || m[n] == '.' || m[n] == '[')) {
        const auto colon = m.find(": ");
        m = a.input + ": " + (colon == std::string::npos ? m : m.substr(colon + 2));
        named = true;
        break;
      }
    }
  }
  // Option references the user cannot act on from here.
  for (const char* internal : {" (CoordinatorOptions.animate.models)", " in CoordinatorOptions.animate.models"}) {
    if (const auto at = m.find(internal); at != std::string::npos) m.erase(at, std::strlen(internal));
  }
  switch (s.code()) {
    case absl::StatusCode::kFailedPrecondition:
      if (m.find("no default") != std::string::npos) {
        m += " in the stack; name one (kinemo artifacts ls lists them), or use --library bundled";
      }
      break;
    case absl::StatusCode::kNotFound: {
      // An id the stack does not hold: what kind of thing, and how to list them.
      static const std::pair<const char*, std::pair<const char*, const char*>> kKinds[] = {
          {"--graph-id: ", {"gesture graph", "kinemo graph ls"}},
          {"--model-id: ", {"inference model", "kinemo model ls"}},
          {"--controller-id: ", {"controller", "kinemo controller ls"}},
          {"--rig-id: ", {"rig", "kinemo rig ls"}},
      };
      for (const auto& [option, kind] : kKinds) {
        if (m.rfind(option, 0) != 0) continue;
        std::string rest = m.substr(std::strlen(option));
        if (rest.rfind("no '", 0) == 0) rest = kinemo::StrCat("no ", kind.first, " ", rest.substr(3));
        m = kinemo::StrCat(option, rest, " in the stack (", kind.second, " lists them)");
      }
      break;
    }
    case absl::StatusCode::kUnavailable:
      if (m.find("not configured") != std::string::npos) {
        m = kinemo::StrCat("the stack at ", address, " cannot animate: ", m);
      } else if (!embedded) {
        m = kinemo::StrCat("cannot reach the stack at ", address, " (", m,
                           "); start it, or leave out --coordinator to run one embedded");
      }
      break;
    case absl::StatusCode::kUnimplemented:
      if (m.find("AnimateChunked") != std::string::npos || m.find("Method not found") != std::string::npos) {
        m = kinemo::StrCat("the stack at ", address,
                           " is older than this kinemo (it has no AnimateChunked): update it, or leave out "
                           "--coordinator to run one embedded");
      }
      break;
    case absl::StatusCode::kDeadlineExceeded:
      m = kinemo::StrCat("not done within ", std::lround(timeout_s), " s; give it more time with --timeout-s (", m, ")");
      break;
    default:
      break;
  }
  return m;
}

int ExitCodeOf(const Status& s) {
  switch (s.code()) {
    case absl::StatusCode::kInvalidArgument:
    case absl::StatusCode::kNotFound:
    case absl::StatusCode::kFailedPrecondition:
    case absl::StatusCode::kOutOfRange:
    case absl::StatusCode::kPermissionDenied:
      return 2;
    default:
      return 1;
  }
}

// Prints the error in the command line's words (and, with --json, a JSON
// line with the status as the stack sent it) and ends the command.
[[noreturn]] void FailAnimate(const Status& s, const AnimateArgs& a, const std::string& address, bool embedded,
                              double timeout_s) {
  const std::string words = CliWords(s, a, address, embedded, timeout_s);
  std::cerr << "kinemo animate: " << words << "\n";
  if (a.json) {
    const nlohmann::json j = {{"error", words},
                              {"code", absl::StatusCodeToString(s.code())},
                              {"detail", std::string(s.message())}};
    std::printf("%s\n", j.dump().c_str());
  }
  throw CliExit{ExitCodeOf(s)};
}

// A usage error (exit 2), in the same form.
[[noreturn]] void UsageError(const std::string& words, const AnimateArgs& a) {
  FailAnimate(absl::InvalidArgumentError(words), a, "", false, 0);
}

// Opens the recording (16 kHz mono, what the stack analyses): errors name
// the file and say what is wrong with it.
std::unique_ptr<audio::RecordingReader> OpenRecording(const std::string& path, const AnimateArgs& a) {
  audio::DecodeOptions options;
  options.limits.max_duration_s = kMaxRecordingS;
  options.limits.min_sample_rate_hz = 8000;
  options.limits.max_sample_rate_hz = 192000;
  auto reader = audio::RecordingReader::Open(path, coordinator::kChunkedAudioRateHz, options);
  if (!reader.ok()) FailAnimate(reader.status(), a, "", false, 0);
  return *std::move(reader);
}

// Recordings shorter than this go through Animate, one message each way
// (90 s at 16 kHz F32 mono is 5.8 MB; its BVH about 5 MB, under the 16 MiB
// message limit); longer ones through AnimateChunked, which has no message
// limit. Both answer the same face (docs/face.md: visemes, jaw, blinks,
// brows, expression, and the jaw in the BVH). Short recordings stay on
// Animate because AnimateChunked admits only animate.max_concurrent_chunked
// calls at once (2: sized for hours of audio held downstream), and a short
// file need not wait for, or be refused by, a slot that long ones hold
// (docs/coordinator.md, "Long recordings"). A stack whose messages are
// smaller, refusing the one message, gets the chunks instead.
constexpr double kWholeAnimateMaxS = 90;

// The BVH's frame count (its "Frames:" line), -1 when it has none.
std::int64_t BvhFrames(const std::string& bvh) {
  const auto at = bvh.find("\nFrames:");
  return at == std::string::npos ? -1 : std::strtoll(bvh.c_str() + at + 8, nullptr, 10);
}

// Animate (one message): the whole recording at 16 kHz mono F32LE; the BVH
// to `motion`, the viseme track to `visemes` (not null), the face to `face`.
StatusOr<coordinator::ChunkedAnimateResult> AnimateWhole(const std::shared_ptr<grpc::Channel>& channel,
                                                         audio::RecordingReader& reader, v1::AnimateRequest req,
                                                         double timeout_s, std::ostream& motion,
                                                         planner::v1::VisemeTrack* visemes,
                                                         common::v1::FaceTrack* face) {
  std::vector<float> pcm;
  while (true) {
    KINEMO_ASSIGN_OR_RETURN(const bool more, reader.Read(coordinator::kChunkedAudioRateHz, &pcm));
    if (!more) break;
  }
  auto* format = req.mutable_audio()->mutable_format();
  format->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
  format->set_sample_rate_hz(coordinator::kChunkedAudioRateHz);
  format->set_channels(1);
  req.mutable_audio()->set_data(std::string(reinterpret_cast<const char*>(pcm.data()), pcm.size() * sizeof(float)));
  auto stub = v1::CoordinatorService::NewStub(channel);
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(static_cast<int64_t>(timeout_s * 1000)));
  ctx.set_wait_for_ready(true);
  v1::AnimateResponse resp;
  const grpc::Status s = stub->Animate(&ctx, req, &resp);
  if (!s.ok()) return Status(static_cast<absl::StatusCode>(s.error_code()), s.error_message());
  if (!resp.motion().has_bvh()) return absl::InternalError("the stack answered no BVH");
  coordinator::ChunkedAnimateResult r;
  r.audio_s = static_cast<double>(pcm.size()) / coordinator::kChunkedAudioRateHz;
  r.frames = BvhFrames(resp.motion().bvh());
  r.motion_bytes = resp.motion().bvh().size();
  motion << resp.motion().bvh();
  *visemes = std::move(*resp.mutable_visemes());
  *face = std::move(*resp.mutable_face());
  r.face_frames = face->frames_size();
  resp.clear_motion();
  r.result = std::move(resp);
  return r;
}

// Offline: a recording shorter than kWholeAnimateMaxS goes through Animate
// (AnimateWhole); a longer one up in chunks (AnimateChunked), decoded and
// resampled here, the BVH coming back in pieces straight into its file. The
// BVH is written beside its file and renamed when complete. `face` receives
// the face for --rig (the viseme track's mouth on a stack without a face
// model). The face is kept only for --visemes and --rig (150 bytes a frame).
void RunAnimate(const AnimateArgs& a, const std::shared_ptr<grpc::Channel>& channel, audio::RecordingReader& reader,
                v1::Method method, const std::string& address, const EmbeddedStack* embedded,
                std::optional<face::FaceTrack>* face) {
  coordinator::ChunkedAnimateOptions o;
  o.request = AnimateRequestFor(a, method);
  const double audio_s = reader.info().duration_s;
  bool whole = audio_s > 0 && audio_s < kWholeAnimateMaxS;
  o.timeout_s = a.timeout_s > 0 ? a.timeout_s : coordinator::ChunkedTimeoutS(audio_s);
  const bool long_file = audio_s >= 60;
  const std::string name = fs::path(a.input).filename().string();
  int last_decile = -1;
  v1::AnimateStage last_stage = v1::ANIMATE_STAGE_UNSPECIFIED;
  std::uint64_t last_mb = 0;
  if (long_file && whole) {
    std::cerr << "kinemo animate: " << name << ": animating " << Clock(audio_s) << " of speech\n";
  }
  if (long_file) {
    o.on_progress = [&](const coordinator::ChunkedProgress& p) {
      if (p.stage == v1::ANIMATE_STAGE_UNSPECIFIED) {
        // (The resampled count may end a few samples short of the header's length.)
        const bool all = p.sent_s + 0.05 >= p.audio_s;
        const int decile = all ? 10 : static_cast<int>(10 * p.sent_s / std::max(1.0, p.audio_s));
        if (decile == last_decile) return;
        last_decile = decile;
        std::cerr << "kinemo animate: " << name << ": sent " << Clock(p.sent_s) << " of " << Clock(p.audio_s) << "\n";
        return;
      }
      if (p.stage != last_stage) {
        last_stage = p.stage;
        const char* what = p.stage == v1::ANIMATE_STAGE_PROSODY     ? "analysing the speech"
                           : p.stage == v1::ANIMATE_STAGE_INFERENCE ? "inferring the gesture style"
                           : p.stage == v1::ANIMATE_STAGE_PLANNER   ? "making the motion"
                                                                    : "making the visemes";
        std::cerr << "kinemo animate: " << name << ": " << what << "\n";
      }
      const std::uint64_t mb = p.motion_bytes >> 20;
      if (mb >= last_mb + 32) {
        last_mb = mb;
        std::cerr << "kinemo animate: writing " << a.output << ": " << mb << " MB\n";
      }
    };
  }
  const std::string partial = kinemo::StrCat(a.bvh_output, ".part", ::getpid());
  // --rig: the visemes give the character's mouth when there is no face.
  std::optional<planner::v1::VisemeTrack> visemes;
  if (!a.visemes.empty() || !a.rig.empty()) visemes.emplace();
  common::v1::FaceTrack face_track;
  StatusOr<coordinator::ChunkedAnimateResult> r;
  {
    std::ofstream out(partial, std::ios::binary | std::ios::trunc);
    if (!out) UsageError(kinemo::StrCat("-o: cannot write ", a.output, " (", std::strerror(errno), ")"), a);
    if (whole) {
      planner::v1::VisemeTrack track;
      r = AnimateWhole(channel, reader, o.request, o.timeout_s, out, &track, &face_track);
      if (visemes) *visemes = std::move(track);
      if (!r.ok() && (r.status().code() == absl::StatusCode::kResourceExhausted ||
                      absl::StrContains(r.status().message(), "AnimateChunked"))) {
        // Too large for one message on this stack: the chunks, from the file again.
        whole = false;
        std::unique_ptr<audio::RecordingReader> again = OpenRecording(a.input, a);
        face_track.Clear();
        r = coordinator::AnimateRecording(channel, *again, o, out, visemes ? &*visemes : nullptr,
                                          visemes ? &face_track : nullptr);
      }
    } else {
      r = coordinator::AnimateRecording(channel, reader, o, out, visemes ? &*visemes : nullptr,
                                        visemes ? &face_track : nullptr);
    }
    out.close();
    if (r.ok() && !out) r = absl::UnavailableError(kinemo::StrCat(a.output, ": could not be written"));
  }
  std::error_code ec;
  if (!r.ok()) {
    fs::remove(partial, ec);
    FailAnimate(r.status(), a, address, embedded != nullptr, o.timeout_s);
  }
  fs::rename(partial, a.bvh_output, ec);
  if (ec) {
    fs::remove(partial, ec);
    FailAnimate(absl::UnavailableError(kinemo::StrCat("-o: cannot write ", a.output)), a, address, false, 0);
  }
  // Every face channel (docs/face.md); without a face: the visemes alone.
  if (!a.visemes.empty()) {
    std::ofstream(a.visemes) << (face_track.frames_size() > 0 ? face::FaceTrackToJson(face::FromProto(face_track))
                                                              : ProtoJson(*visemes))
                             << "\n";
  }
  if (!a.rig.empty()) {
    *face = face_track.frames_size() > 0 ? std::optional<face::FaceTrack>(face::FromProto(face_track))
                                         : FaceOfVisemes(*visemes);
  }
  const v1::AnimateResponse& resp = r->result;
  v1::AnimateResponse summary;
  *summary.mutable_prosody() = resp.prosody();
  *summary.mutable_times() = resp.times();
  summary.set_method(resp.method());
  summary.set_request_id(resp.request_id());
  if (!a.summary.empty()) std::ofstream(a.summary) << ProtoJson(summary) << "\n";
  // Peak memory of what this command ran: itself and its embedded stack.
  double peak_mb = PeakRssMb(0);
  if (embedded != nullptr && embedded->pid() > 0) peak_mb += PeakRssMb(embedded->pid());
  if (a.json) {
    nlohmann::json j = nlohmann::json::parse(ProtoJson(summary), nullptr, false);
    if (j.is_discarded()) j = nlohmann::json::object();
    j["audio_s"] = r->audio_s;
    j["frames"] = r->frames;
    j["motion_bytes"] = r->motion_bytes;
    j["face_frames"] = r->face_frames;
    j["call"] = whole ? "Animate" : "AnimateChunked";
    j["peak_rss_mb"] = peak_mb;
    j["peak_rss_of"] = embedded != nullptr ? "kinemo and its embedded kinemo_allinone" : "kinemo (the stack is remote)";
    std::printf("%s\n", j.dump().c_str());
  } else {
    std::printf("%s: %s of speech, %u syllables, %d accents -> %s (%s, %lld frames)%s%s in %.1f s\n",
                a.input.c_str(), Clock(resp.prosody().duration_s()).c_str(), resp.prosody().syllables(),
                resp.prosody().accents_size(), a.output.c_str(), v1::Method_Name(resp.method()).c_str(),
                static_cast<long long>(r->frames), a.visemes.empty() ? "" : " + ", a.visemes.c_str(),
                resp.times().total_s());
  }
}

// StreamAnimate: the BVH from the streamed header and frames, the visemes
// sent at the end, and the live timing.
void RunStream(const AnimateArgs& a, const std::shared_ptr<grpc::Channel>& channel,
               const std::vector<float>& samples, int sample_rate_hz, const std::string& address, bool embedded,
               std::optional<face::FaceTrack>* face) {
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
    if (!opened.ok()) FailAnimate(opened.status(), a, address, embedded, 0);
    vmc = *std::move(opened);
    o.on_frame = [&vmc](const auto& header, const auto& frame, auto audio_sent) { vmc->OnFrame(header, frame, audio_sent); };
  }
  auto r = coordinator::RunLiveStream(channel, samples, sample_rate_hz, o);
  std::optional<v1::Session> final_session;
  if (!session.empty()) {
    if (auto s = coordinator::GetCubeSession(channel, session); s.ok()) final_session = *s;
    (void)coordinator::CloseCubeSession(channel, session);
  }
  if (!r.ok()) {
    const double audio_s = static_cast<double>(samples.size()) / sample_rate_hz;
    FailAnimate(r.status(), a, address, embedded, a.timeout_s > 0 ? a.timeout_s : 60 + 3 * audio_s);
  }
  if (vmc && !vmc->status().ok()) FailAnimate(vmc->status(), a, address, embedded, 0);
  auto clip = coordinator::ClipFromStream(r->header, r->frames);
  if (!clip.ok()) FailCommand("animate", Annotate(clip.status(), "the stream"), {});
  if (Status s = motion::WriteBvhFile(*clip, a.bvh_output); !s.ok()) FailCommand("animate", s, {});
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
      "Speech to body motion: kinemo animate FILE -o OUT.bvh [--method gc|gmg|bodyspeech] [--rig RIG.glb -o OUT.glb]");
  auto a = std::make_shared<AnimateArgs>();
  cmd->add_option("file", a->input,
                  kinemo::StrCat("the recording: ", audio::kRecordingFormatsText,
                                 ", any rate and channels, up to 2 hours"))
      ->required();
  cmd->add_option("-o,--out", a->output,
                  "file to write (required): OUT.bvh (the motion); with --rig, OUT.glb (the character moving), "
                  "OUT.bvh (on the rig's skeleton) or, for a VRM character, OUT.vrma (a VRM Animation)");
  AddDeprecatedOption(cmd, "--output", "--out", a->output);
  cmd->footer(
      "Methods (-m):\n"
      "  gc          Gesture Controller: a model trained on recorded speech and motion picks library segments (live too)\n"
      "  gmg         Gesture Motion Graph: one gesture phrase of the library per pitch accent, its apex on the accent\n"
      "  bodyspeech  BodySpeech (the default): as gmg, each gesture as large as its accent is strong\n"
      "bodyspeech is the default because it needs no trained model (only the motion library) and times a gesture to\n"
      "every pitch accent; a running stack (--coordinator) has its own default (animate.default_method).\n"
      "Recordings of any length up to 2 hours are decoded and resampled to 16 kHz mono here and sent in chunks;\n"
      "long ones show their progress on stderr.");
  cmd->add_option("--visemes", a->visemes, "viseme tracks to write (JSON; runs the recogniser)");
  cmd->add_option("--coordinator", a->coordinator,
                  "coordinator address (default localhost:50050; if none answers, an embedded "
                  "kinemo_allinone is started)");
  cmd->add_flag("--embedded", a->embedded, "always use an embedded kinemo_allinone");
  cmd->add_option("--allinone-config", a->config,
                  "options file of the embedded kinemo_allinone (default: the bundled gesture library, BodySpeech)");
  cmd->add_option("-m,--method", a->method,
                  "gc | gmg | bodyspeech: how the motion is made (below); default bodyspeech");
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
                  "deadline (0 = 60 s + 0.25 s per second of audio; with --stream 60 s + 3 s per second)");
  cmd->add_flag("--json", a->json,
                "print the summary as JSON: prosody, times, method, audio_s, frames, peak_rss_mb (with --stream: "
                "motion_lag_p50_ms, motion_lag_p99_ms, first_frame_ms, max_frame_gap_ms, frames, audio_s, "
                "max_chunk_late_ms); errors as {error, code, detail}");
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
                  "put the motion on this character (.glb/.gltf/.vrm; -o OUT.glb, OUT.bvh or, for a VRM, OUT.vrma): "
                  "kinemo retarget");
  cmd->add_option("--map", a->rig_map, "with --rig: JSON role map of the rig");
  cmd->add_option("--face-map", a->face_map,
                  "with --rig: JSON face map of the rig (which morph targets / VRM expressions the face drives)");
  cmd->add_option("--rig-id", a->rig_id,
                  "a rig stored in the stack (kinemo rig push): the server puts the motion (BVH, or the "
                  "streamed frames) on its skeleton")
      ->excludes("--rig");
  cmd->callback([a] {
    if (a->output.empty()) {
      UsageError("-o/--out is required: the file to write (OUT.bvh; OUT.glb with --rig)", *a);
    }
    a->bvh_output = a->output;
    auto method = MethodOf(a->method);
    if (!method.ok()) FailAnimate(method.status(), *a, "", false, 0);
    if (!a->library.empty()) {
      if (a->model.empty()) a->model = a->library;
      if (a->controller.empty()) a->controller = a->library;
      if (a->graph.empty()) a->graph = a->library;
    }
    if (a->realtime && !a->stream) {
      UsageError("--realtime: needs --stream", *a);
    }
    if (!a->cube_video.empty()) {
      if (!a->stream) {
        UsageError("--cube-video: needs --stream", *a);
      }
      if (!fs::is_regular_file(a->cube_video)) {
        UsageError(kinemo::StrCat("--cube-video: cannot read ", a->cube_video), *a);
      }
      if (a->cube_camera.empty()) a->cube_camera = a->cube_video + ".camera.yaml";
      if (a->cube_model.empty()) a->cube_model = BundledDataFile("cube/vleo.cube");
    }
    if (!a->vmc.address.empty()) {
      if (!a->stream) UsageError("--vmc: needs --stream", *a);
      if (Status s = AnimateVmc::Validate(a->vmc); !s.ok()) FailAnimate(s, *a, "", false, 0);
    }
    if (a->stream && !a->method.empty() && a->method != "gc") {
      UsageError("--method: only gc runs live (--stream)", *a);
    }
    std::optional<AnimateRig> rig;
    if (!a->rig.empty()) {
      auto prepared = PrepareAnimateRig(a->rig, a->rig_map, &a->bvh_output, a->face_map);
      if (!prepared.ok()) FailAnimate(prepared.status(), *a, "", false, 0);
      rig = *std::move(prepared);
    } else if (!a->rig_map.empty() || !a->face_map.empty()) {
      UsageError(a->rig_map.empty() ? "--face-map: needs --rig" : "--map: needs --rig", *a);
    } else {
      std::string ext = fs::path(a->output).extension().string();
      for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      if (ext == ".glb" || ext == ".vrma") {
        UsageError(kinemo::StrCat("-o: ", a->output, ": a ", ext, " is made for a character: name it with --rig RIG.glb|RIG.vrm"), *a);
      }
      if (ext != ".bvh") {
        UsageError(kinemo::StrCat("-o: ", a->output, ": animate writes BVH (OUT.bvh), or with --rig RIG.glb a character (OUT.glb)"), *a);
      }
    }
    // Open the recording before any stack starts: its errors come first.
    std::unique_ptr<audio::RecordingReader> reader = OpenRecording(a->input, *a);
    std::vector<float> pcm;
    if (a->stream) {
      // Live: the whole recording at 16 kHz, then paced out in 20 ms chunks.
      while (true) {
        auto more = reader->Read(coordinator::kChunkedAudioRateHz, &pcm);
        if (!more.ok()) FailAnimate(more.status(), *a, "", false, 0);
        if (!*more) break;
      }
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
      RunStream(*a, channel, pcm, coordinator::kChunkedAudioRateHz, address, use_embedded, &face);
    } else {
      RunAnimate(*a, channel, *reader, *method, address, use_embedded ? &embedded : nullptr, &face);
    }
    if (rig) {
      rig->face = std::move(face);
      if (Status s = RetargetAnimateResult(*rig, a->json); !s.ok()) FailAnimate(s, *a, address, use_embedded, 0);
    }
  });
}

}  // namespace kinemo::cli
