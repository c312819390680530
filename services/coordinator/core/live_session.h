// The session of one StreamAnimate stream, without the streams themselves
// (the adapter, stream_animate.cc, owns the gRPC calls and calls this under
// its mutex): what goes to prosody, inference and the planner for every
// client message and every answer, the frames' pacing by the audio clock,
// their face (docs/face.md), the session's Vleo tones (core/cube_tone.h),
// the VMC output (config.vmc), the visemes' requests and the summary.
//
// Every chunk advances media time to the end of the audio received (the
// planner's advance_to_s), so frames come at the pace of the audio, through
// pauses too; beliefs arrive later and change what plays next, never past
// the audio received. Frame batches wait for their face until the speech
// face reaches them (at most kMaxFaceWaitS, not at all when the speech face
// is far behind). A tone change goes to the client just before the frames
// of the first decision made in its tone (ControlDecision.style_changes).
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/status/status.h"
#include "common/vmc/vmc_proto.h"
#include "kinemo/coordinator/v1/coordinator.pb.h"
#include "kinemo/coordinator/v1/options.pb.h"
#include "kinemo/inference/v1/inference.pb.h"
#include "kinemo/planner/v1/planner.pb.h"
#include "kinemo/prosody/v1/prosody.pb.h"
#include "services/coordinator/core/animate_plan.h"
#include "services/coordinator/core/cube_tone.h"
#include "services/coordinator/core/face_animate.h"

namespace kinemo::coordinator {

// UNAVAILABLE "<service>: not configured (CoordinatorOptions.services.<service>.address)".
Status NotConfigured(std::string_view service);

// Where a live session's messages go: the adapter's three downstream streams
// and the client. `owes`: the peer owes an answer to it (the idle timeout).
class LiveOutput {
 public:
  virtual ~LiveOutput() = default;
  virtual void ToProsody(prosody::v1::StreamAnalyzeRequest request) = 0;
  virtual void ToInference(inference::v1::StreamInferRequest request, bool owes) = 0;
  virtual void ToPlanner(planner::v1::ControlRequest request, bool owes) = 0;
  virtual void ToClient(coordinator::v1::StreamAnimateResponse response) = 0;
};

// When each recent chunk arrived, by the audio time it ends at: a fixed ring
// (no allocation per chunk); past kChunks unanswered chunks the oldest are
// forgotten. Feeds kinemo_stream_animate_motion_lag_seconds.
class ChunkArrivals {
 public:
  void Add(double audio_end_s);
  // Frames up to `frame_s` leave now: observe the lag of every chunk they
  // complete.
  void FramesUpTo(double frame_s);

 private:
  static constexpr std::size_t kChunks = 256;
  struct Arrival {
    double audio_end_s = 0;
    std::chrono::steady_clock::time_point at;
  };
  void Pop();
  std::array<Arrival, kChunks> ring_{};
  std::size_t head_ = 0, size_ = 0;
};

class LiveSession {
 public:
  // Which services the adapter can reach (NotConfigured otherwise).
  struct Services {
    bool prosody = false, inference = false, planner = false;
  };
  // Checks the first message's config, naming its fields (config.method,
  // config.format, config.models.*, config.vmc, config.cube_tones with
  // animate.cube_tones and animate.cube_emphasis_gain), and opens config.vmc.
  static StatusOr<std::unique_ptr<LiveSession>> Create(coordinator::v1::StreamAnimateConfig config,
                                                       const coordinator::v1::CoordinatorOptions& options,
                                                       const Services& services, std::uint64_t max_message_bytes,
                                                       LiveOutput* out);
  LiveSession(const LiveSession&) = delete;
  LiveSession& operator=(const LiveSession&) = delete;

  const coordinator::v1::StreamAnimateConfig& config() const { return config_; }
  const std::string& request_id() const { return request_id_; }
  double audio_s() const { return clock_.audio_s(); }
  // The three streams' configs (the inference model and the planner's
  // header are owed).
  void Start();

  // ---- the client ----
  // A message after the config: a chunk of audio or a style.
  Status OnClientMessage(coordinator::v1::StreamAnimateRequest& request);

  // ---- the downstream streams ----
  Status OnProsody(prosody::v1::StreamAnalyzeResponse& response);
  void OnInference(inference::v1::StreamInferResponse& response);
  Status OnPlanner(planner::v1::ControlResponse& response);
  // Prosody's stream ended: the frames still held go as they are, the audio
  // after the last syllable or pause goes to inference as unvoiced steps.
  Status OnProsodyEnd();
  // Frame batches held past kMaxFaceWaitS go now.
  Status FlushFaceFrames();

  // ---- the session's Vleo (config.session_id) ----
  // The current action (snapshot) or a change: a style message to the planner.
  void OnSessionEvent(const coordinator::v1::SessionEvent& event);

  // ---- the end ----
  // With config.visemes: the recogniser's request over the stream's audio.
  prosody::v1::AnalyzeRequest TakeVisemesAnalysis();
  // planner.Visemes' request for the recogniser's track.
  planner::v1::VisemesRequest VisemesRequestFor(const prosody::v1::ProsodyTrack& track) const;
  // After the last frames: the visemes (with config.visemes), the summary.
  Status End(planner::v1::VisemeTrack* visemes);

 private:
  LiveSession(coordinator::v1::StreamAnimateConfig config, AudioClock clock, LiveOutput* out)
      : config_(std::move(config)), clock_(clock), out_(out) {}
  void SendStyle(common::v1::Action action, double intensity);
  void OnDecision(const planner::v1::ControlDecision& d);
  Status Emit(coordinator::v1::StreamAnimateResponse r);

  coordinator::v1::StreamAnimateConfig config_;
  AudioClock clock_;
  LiveOutput* const out_;
  std::string request_id_, model_id_, controller_id_;
  std::uint64_t max_message_bytes_ = 0;
  double covered_s_ = 0;  // end of the last inference step sent
  double frame_time_s_ = 0, last_frame_s_ = 0;
  // Frames the planner makes up to the last advance_to_s sent (its emit
  // rule: times k·frame_time_s < advance − 0.001 frame); -1 before its header.
  std::int64_t advanced_frames_ = -1;
  ChunkArrivals arrivals_;  // for the motion lag metric
  std::uint64_t frames_ = 0, beliefs_ = 0, decisions_ = 0;
  prosody::v1::StreamSummary prosody_summary_;

  // The face: asked of prosody with every stream; until prosody's
  // StreamInfo says whether it runs, and then until the speech face reaches
  // their time, frame batches wait in held_frames_.
  std::optional<LiveFace> face_;
  bool face_known_ = false;  // prosody's StreamInfo arrived
  std::deque<coordinator::v1::StreamAnimateResponse> held_frames_;
  std::deque<std::chrono::steady_clock::time_point> held_since_;  // when each held batch came
  double sent_frame_s_ = -1;  // time of the last frame sent to the client

  // The session's Vleo (config.session_id).
  struct PendingTone {
    std::uint64_t style_changes = 0;  // the planner's count once it applied this one
    coordinator::v1::ToneChange change;
  };
  CubeToneMap cube_tones_;
  double cube_emphasis_gain_ = kDefaultCubeEmphasisGain;  // animate.cube_emphasis_gain
  std::uint64_t styles_sent_ = 0;          // style messages sent to the planner
  std::deque<PendingTone> pending_tones_;  // sent, no decision in them yet
  std::vector<coordinator::v1::ToneChange> ready_tones_;  // go out before the next frames
  std::string last_tone_;
  double last_weight_ = -1;
  double last_emphasis_ = 0;

  // config.vmc: the frames also go out as VMC packets (Emit).
  std::unique_ptr<vmc::ProtoVmcStream> vmc_;
  std::string audio_;  // the stream's PCM, with config.visemes
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

}  // namespace kinemo::coordinator
