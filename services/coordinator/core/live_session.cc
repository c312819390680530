#include "services/coordinator/core/live_session.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "common/logging/log.h"
#include "common/metrics/metrics.h"

namespace kinemo::coordinator {

namespace inf = ::kinemo::inference::v1;
namespace pl = ::kinemo::planner::v1;
namespace pr = ::kinemo::prosody::v1;

namespace {

// Longest a frame batch waits for its face (docs/face.md): past it the batch
// goes with the face as far as the speech face reaches (the body never waits
// on a late prosody stream, e.g. one still starting its keyword spotter).
constexpr double kMaxFaceWaitS = 0.02;
// A batch whose last frame is further than this ahead of the speech face does
// not wait at all.
constexpr double kMaxFaceBehindS = 0.04;

// Motion lag at the coordinator: a chunk of audio received → the frames
// that reach its end queued for the client (the client's own figure adds
// the network both ways).
prometheus::Histogram& MotionLag() {
  static auto& h = metrics::Histogram(
      "kinemo_stream_animate_motion_lag_seconds",
      "StreamAnimate: audio chunk received by the coordinator -> frames up to its end sent to the client.",
      {0.01, 0.025, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.5, 1, 2, 5});
  return h;
}

void SetTimestamp(std::chrono::system_clock::duration since_epoch, google::protobuf::Timestamp* t) {
  t->set_seconds(std::chrono::duration_cast<std::chrono::seconds>(since_epoch).count());
  t->set_nanos(static_cast<int>(std::chrono::duration_cast<std::chrono::nanoseconds>(since_epoch).count() % 1000000000));
}

}  // namespace

Status NotConfigured(std::string_view service) {
  return absl::UnavailableError(
      kinemo::StrCat(service, ": not configured (CoordinatorOptions.services.", service, ".address)"));
}

// ---- ChunkArrivals -------------------------------------------------------------

void ChunkArrivals::Add(double audio_end_s) {
  if (size_ == kChunks) Pop();
  ring_[(head_ + size_) % kChunks] = {audio_end_s, std::chrono::steady_clock::now()};
  ++size_;
}

void ChunkArrivals::FramesUpTo(double frame_s) {
  const auto now = std::chrono::steady_clock::now();
  while (size_ > 0 && ring_[head_].audio_end_s <= frame_s + 1e-9) {
    MotionLag().Observe(std::chrono::duration<double>(now - ring_[head_].at).count());
    Pop();
  }
}

void ChunkArrivals::Pop() {
  head_ = (head_ + 1) % kChunks;
  --size_;
}

// ---- the session ---------------------------------------------------------------

StatusOr<std::unique_ptr<LiveSession>> LiveSession::Create(v1::StreamAnimateConfig config,
                                                           const v1::CoordinatorOptions& o, const Services& services,
                                                           std::uint64_t max_message_bytes, LiveOutput* out) {
  KINEMO_ASSIGN_OR_RETURN(v1::Method method,
                          ResolveMethod(config.method(), v1::METHOD_GESTURE_CONTROLLER, "config.method"));
  if (method != v1::METHOD_GESTURE_CONTROLLER) {
    return InvalidField("config.method",
                        "only METHOD_GESTURE_CONTROLLER runs live (GMG and BodySpeech need the whole utterance; use "
                        "Animate)");
  }
  const double max_audio_s = o.animate().max_audio_s() > 0 ? o.animate().max_audio_s() : 600;
  KINEMO_ASSIGN_OR_RETURN(AudioClock clock, AudioClock::Create(config.format(), max_audio_s, "config.format"));
  if (!services.prosody) return NotConfigured("prosody");
  if (!services.inference) return NotConfigured("inference");
  if (!services.planner) return NotConfigured("planner");
  std::unique_ptr<LiveSession> s(new LiveSession(std::move(config), clock, out));
  const v1::StreamAnimateConfig& c = s->config_;
  const auto& dm = o.animate().models();
  s->model_id_ = c.models().inference_model_id().empty() ? dm.inference_model_id() : c.models().inference_model_id();
  s->controller_id_ = c.models().controller_id().empty() ? dm.controller_id() : c.models().controller_id();
  if (s->model_id_.empty() || s->controller_id_.empty()) {
    return absl::FailedPreconditionError(
        absl::StrCat(s->model_id_.empty() ? "config.models.inference_model_id" : "config.models.controller_id",
                     ": not set, and no default in CoordinatorOptions.animate.models"));
  }
  if (!c.vmc().address().empty()) {
    // (A name in config.vmc.address is resolved here, once.)
    const auto& allowed = o.animate().vmc_allowed_hosts();
    KINEMO_ASSIGN_OR_RETURN(s->vmc_, vmc::OpenVmcTarget(c.vmc(), {allowed.begin(), allowed.end()}, "config.vmc"));
  }
  if (!c.session_id().empty()) {
    KINEMO_ASSIGN_OR_RETURN(s->cube_tones_, MakeCubeToneMap(o.animate().cube_tones(), "animate.cube_tones",
                                                            c.cube_tones(), "config.cube_tones"));
    if (o.animate().has_cube_emphasis_gain()) {
      KINEMO_RETURN_IF_ERROR(ValidateCubeEmphasisGain(o.animate().cube_emphasis_gain(), "animate.cube_emphasis_gain"));
      s->cube_emphasis_gain_ = o.animate().cube_emphasis_gain();
    }
  } else if (!c.cube_tones().empty()) {
    return InvalidField("config.cube_tones", "needs config.session_id");
  }
  s->max_message_bytes_ = max_message_bytes;
  s->request_id_ = c.request_id().empty()
                       ? absl::StrCat("stream-", std::chrono::system_clock::now().time_since_epoch().count())
                       : c.request_id();
  return s;
}

void LiveSession::Start() {
  pr::StreamAnalyzeRequest pc;
  *pc.mutable_config()->mutable_format() = config_.format();
  *pc.mutable_config()->mutable_params() = config_.prosody_params();
  // Live keyword spotting takes the keywords alone (the full recogniser
  // needs whole utterances).
  *pc.mutable_config()->mutable_recognizer()->mutable_keywords() = config_.keywords();
  pc.mutable_config()->set_request_id(request_id_);
  pc.mutable_config()->mutable_face()->set_enabled(true);
  pc.mutable_config()->mutable_face()->set_model_id(config_.face_model_id());
  face_.emplace(0.0);
  out_->ToProsody(std::move(pc));
  inf::StreamInferRequest ic;
  ic.mutable_config()->set_model_id(model_id_);
  ic.mutable_config()->set_request_id(request_id_);
  out_->ToInference(std::move(ic), /*owes=*/true);  // the model
  pl::ControlRequest cc;
  cc.mutable_config()->set_controller_id(controller_id_);
  cc.mutable_config()->set_rig_id(config_.models().rig_id());
  *cc.mutable_config()->mutable_style() = config_.style();
  cc.mutable_config()->set_emit_decisions(true);  // counted for the summary
  cc.mutable_config()->set_request_id(request_id_);
  out_->ToPlanner(std::move(cc), /*owes=*/true);  // the header
}

Status LiveSession::OnClientMessage(v1::StreamAnimateRequest& in) {
  if (in.has_chunk()) {
    if (config_.visemes() && audio_.size() + in.chunk().data().size() + (64 << 10) > max_message_bytes_) {
      return InvalidField("chunk", "with config.visemes the stream's audio goes to the recogniser in one message, at most ",
                          max_message_bytes_, " bytes (server.max_message_bytes); ", audio_.size(), " bytes so far");
    }
    KINEMO_RETURN_IF_ERROR(clock_.Add(in.chunk()));
    if (config_.visemes()) audio_.append(in.chunk().data());
    arrivals_.Add(clock_.audio_s());
    pr::StreamAnalyzeRequest q;
    *q.mutable_chunk() = std::move(*in.mutable_chunk());
    out_->ToProsody(std::move(q));
    // The audio clock: frames up to the audio received. A chunk that
    // completes no frame (20 ms chunks, 33 ms frames) moves nothing the
    // planner makes, so it is not sent: 40 % fewer planner messages.
    const std::int64_t frames =
        frame_time_s_ > 0 ? std::max<std::int64_t>(0, static_cast<std::int64_t>(std::ceil(clock_.audio_s() / frame_time_s_ - 1e-3)))
                          : -1;
    if (frames < 0 || frames > advanced_frames_) {
      advanced_frames_ = frames;
      pl::ControlRequest a;
      a.set_advance_to_s(clock_.audio_s());
      // Frames are owed once the audio passed the frame after the last one.
      const bool owes = frame_time_s_ > 0 && clock_.audio_s() >= last_frame_s_ + 2 * frame_time_s_;
      out_->ToPlanner(std::move(a), owes);
    }
    return FlushFaceFrames();  // overdue batches go
  }
  if (in.has_style()) {
    pl::ControlRequest q;
    *q.mutable_style() = std::move(*in.mutable_style());
    out_->ToPlanner(std::move(q), false);
    ++styles_sent_;
    return absl::OkStatus();
  }
  if (in.has_config()) return InvalidField("config", "sent twice");
  return InvalidField("message", "neither chunk nor style");
}

Status LiveSession::OnProsody(pr::StreamAnalyzeResponse& r) {
  auto steps = [&](std::vector<inf::ProsodyFeatures> v) {
    for (auto& f : v) {
      inf::StreamInferRequest q;
      *q.mutable_features() = std::move(f);
      out_->ToInference(std::move(q), false);
    }
  };
  if (r.has_syllable()) {
    auto v = GapSteps(covered_s_, r.syllable().start_s());
    v.push_back(SyllableStep(r.syllable()));
    covered_s_ = std::max(covered_s_, r.syllable().end_s());
    steps(std::move(v));
  } else if (r.has_pause()) {
    steps(GapSteps(covered_s_, r.pause().end_s()));
    covered_s_ = std::max(covered_s_, r.pause().end_s());
  } else if (r.has_accent()) {
    if (face_) face_->AddAccent(r.accent());
    if (config_.emit_prosody_events()) {
      v1::StreamAnimateResponse out;
      *out.mutable_accent() = std::move(*r.mutable_accent());
      return Emit(std::move(out));
    }
  } else if (r.has_word()) {
    if (!r.word().keyword()) return absl::OkStatus();
    pl::ControlRequest k;
    *k.mutable_keyword() = r.word();
    out_->ToPlanner(std::move(k), false);
    if (config_.emit_prosody_events()) {
      v1::StreamAnimateResponse out;
      *out.mutable_keyword() = std::move(*r.mutable_word());
      return Emit(std::move(out));
    }
  } else if (r.has_summary()) {
    prosody_summary_ = r.summary();
  } else if (r.has_info()) {
    face_known_ = true;
    if (!r.info().face_running()) face_.reset();
    return FlushFaceFrames();
  } else if (r.has_face()) {
    if (face_) face_->AddSpeech(r.face());
    return FlushFaceFrames();
  }
  return absl::OkStatus();
}

void LiveSession::OnInference(inf::StreamInferResponse& r) {
  if (!r.has_filtered()) return;
  pl::ControlRequest q;
  *q.mutable_belief() = ToBeliefStep(r.filtered());
  // Never past the audio received: beliefs change what plays next, the
  // audio clock alone moves media time.
  auto* b = q.mutable_belief();
  b->set_end_s(std::min(b->end_s(), clock_.audio_s()));
  b->set_start_s(std::min(b->start_s(), b->end_s()));
  ++beliefs_;
  out_->ToPlanner(std::move(q), false);
}

Status LiveSession::OnPlanner(pl::ControlResponse& r) {
  v1::StreamAnimateResponse out;
  if (r.has_header()) {
    frame_time_s_ = r.header().frame_time_s();
    if (face_) face_->SetSkeleton(r.header().skeleton());
    *out.mutable_header() = std::move(*r.mutable_header());
    return Emit(std::move(out));
  }
  if (r.has_frames()) {
    const int n = r.frames().frames_size();
    if (n == 0) return absl::OkStatus();
    frames_ += static_cast<std::uint64_t>(n);
    last_frame_s_ = r.frames().frames(n - 1).time_s();
    *out.mutable_frames() = std::move(*r.mutable_frames());
    held_frames_.push_back(std::move(out));
    held_since_.push_back(std::chrono::steady_clock::now());
    return FlushFaceFrames();
  }
  if (r.has_decision()) {
    ++decisions_;
    OnDecision(r.decision());
  }
  return absl::OkStatus();
}

Status LiveSession::OnProsodyEnd() {
  face_known_ = true;  // no more speech face: the frames still held go as they are
  if (face_) face_->FinishSpeech();
  KINEMO_RETURN_IF_ERROR(FlushFaceFrames());
  // The audio after the last syllable or pause, as unvoiced steps.
  for (auto& f : GapSteps(covered_s_, clock_.audio_s())) {
    inf::StreamInferRequest q;
    *q.mutable_features() = std::move(f);
    out_->ToInference(std::move(q), false);
  }
  return absl::OkStatus();
}

Status LiveSession::FlushFaceFrames() {
  while (!held_frames_.empty()) {
    v1::StreamAnimateResponse& out = held_frames_.front();
    const auto& frames = out.frames().frames();
    // A batch leaves once the speech face reaches its last frame, or after
    // kMaxFaceWaitS with the face as far as it is known.
    const bool overdue =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - held_since_.front()).count() >= kMaxFaceWaitS;
    if (face_) {
      // Wait only for a speech face that is about to arrive: one more than
      // kMaxFaceBehindS behind the frame (a prosody stream still starting)
      // is not waited for.
      const double t = frames[frames.size() - 1].time_s();
      const bool far_behind = t - face_->speech_until_s() > kMaxFaceBehindS;
      if (!overdue && !far_behind && (!face_known_ || !face_->Ready(t))) return absl::OkStatus();
      for (auto& f : *out.mutable_frames()->mutable_frames()) face_->Fill(&f);
    } else if (!face_known_ && !overdue) {
      return absl::OkStatus();
    }
    sent_frame_s_ = frames[frames.size() - 1].time_s();
    arrivals_.FramesUpTo(sent_frame_s_ + frame_time_s_);
    for (auto& t : ready_tones_) {
      v1::StreamAnimateResponse tc;
      *tc.mutable_tone_change() = std::move(t);
      KINEMO_RETURN_IF_ERROR(Emit(std::move(tc)));
    }
    ready_tones_.clear();
    v1::StreamAnimateResponse batch = std::move(out);
    held_frames_.pop_front();
    held_since_.pop_front();
    KINEMO_RETURN_IF_ERROR(Emit(std::move(batch)));
  }
  return absl::OkStatus();
}

void LiveSession::OnSessionEvent(const v1::SessionEvent& e) {
  if (e.has_snapshot()) {
    SendStyle(e.snapshot().action(), e.snapshot().intensity());
    if (!pending_tones_.empty()) pending_tones_.back().change.set_initial(true);
  } else if (e.has_action_changed()) {
    SendStyle(e.action_changed().action(), e.action_changed().intensity());
  }
}

void LiveSession::SendStyle(common::v1::Action action, double intensity) {
  CubeStyle cs = StyleForAction(cube_tones_, action, intensity, cube_emphasis_gain_);
  if (cs.tone == last_tone_ && std::abs(cs.weight - last_weight_) < 1e-9 &&
      std::abs(cs.emphasis - last_emphasis_) < 1e-9)
    return;  // no change
  last_tone_ = cs.tone;
  last_weight_ = cs.weight;
  last_emphasis_ = cs.emphasis;
  PendingTone p;
  p.change.set_tone(cs.tone);
  p.change.set_weight(cs.weight);
  p.change.set_gesture_emphasis(cs.emphasis);
  *p.change.mutable_style() = cs.style;
  p.change.set_action(action);
  p.change.set_intensity(intensity);
  SetTimestamp(std::chrono::system_clock::now().time_since_epoch(), p.change.mutable_seen_time());
  pl::ControlRequest q;
  *q.mutable_style() = std::move(cs.style);
  out_->ToPlanner(std::move(q), false);
  p.style_changes = ++styles_sent_;
  pending_tones_.push_back(std::move(p));
}

void LiveSession::OnDecision(const pl::ControlDecision& d) {
  if (pending_tones_.empty() || d.style_changes() < pending_tones_.front().style_changes) return;
  const auto now = std::chrono::system_clock::now().time_since_epoch();
  while (!pending_tones_.empty() && d.style_changes() >= pending_tones_.front().style_changes) {
    v1::ToneChange c = std::move(pending_tones_.front().change);
    pending_tones_.pop_front();
    c.set_t_s(d.time_s());
    SetTimestamp(now, c.mutable_synthesized_time());
    c.set_superseded(!pending_tones_.empty() && d.style_changes() >= pending_tones_.front().style_changes);
    if (face_ && !c.superseded()) face_->SetTone(c.t_s(), c.tone(), c.tone() == "neutral" ? 0.0 : c.weight());
    ready_tones_.push_back(std::move(c));
  }
}

pr::AnalyzeRequest LiveSession::TakeVisemesAnalysis() {
  pr::AnalyzeRequest r;
  *r.mutable_audio()->mutable_format() = config_.format();
  r.mutable_audio()->set_data(std::move(audio_));
  audio_.clear();
  *r.mutable_params() = config_.prosody_params();
  r.mutable_recognizer()->set_enabled(true);
  r.set_request_id(request_id_);
  return r;
}

pl::VisemesRequest LiveSession::VisemesRequestFor(const pr::ProsodyTrack& track) const {
  pl::VisemesRequest r;
  *r.mutable_phones() = track.phones();
  *r.mutable_accents() = track.accents();
  r.set_duration_s(track.duration_s());
  *r.mutable_params() = config_.viseme_params();
  return r;
}

Status LiveSession::End(pl::VisemeTrack* visemes) {
  if (visemes != nullptr) {
    v1::StreamAnimateResponse v;
    *v.mutable_visemes() = std::move(*visemes);
    KINEMO_RETURN_IF_ERROR(Emit(std::move(v)));
  }
  v1::StreamAnimateResponse r;
  auto* s = r.mutable_summary();
  s->set_audio_s(clock_.audio_s());
  s->set_chunks(clock_.chunks());
  s->set_frames(frames_);
  s->set_syllables(prosody_summary_.syllables());
  s->set_pauses(prosody_summary_.pauses());
  s->set_accents(prosody_summary_.accents());
  s->set_beliefs(beliefs_);
  s->set_decisions(decisions_);
  if (vmc_ != nullptr) {
    const vmc::VmcStats& vs = vmc_->stream().stats();
    s->set_vmc_frames(vs.frames);
    s->set_vmc_packets(vs.packets);
    s->set_vmc_bones(vs.bones);
    s->set_vmc_blendshapes(vs.blendshapes);
  }
  KINEMO_RETURN_IF_ERROR(Emit(std::move(r)));
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  log::Info("stream_animated", {{"request_id", request_id_},
                                {"audio_s", clock_.audio_s()},
                                {"frames", frames_},
                                {"beliefs", beliefs_},
                                {"decisions", decisions_},
                                {"wall_s", wall_s}});
  return absl::OkStatus();
}

Status LiveSession::Emit(v1::StreamAnimateResponse r) {
  if (vmc_ != nullptr && (r.has_header() || r.has_frames())) {
    // The frames go out to the VMC receiver as they go to the client.
    Status sent = r.has_header() ? vmc_->OnHeader(r.header()) : absl::OkStatus();
    for (int i = 0; sent.ok() && r.has_frames() && i < r.frames().frames_size(); ++i) {
      sent = vmc_->OnFrame(r.frames().frames(i)).status();
    }
    if (!sent.ok()) return Annotate(sent, "config.vmc");
  }
  r.set_last_chunk_sequence(clock_.last_sequence());
  // Media time the frames sent so far reach (the audio clock).
  r.set_audio_time_s(sent_frame_s_ < 0 ? 0.0 : std::min(clock_.audio_s(), sent_frame_s_ + frame_time_s_));
  out_->ToClient(std::move(r));
  return absl::OkStatus();
}

}  // namespace kinemo::coordinator
