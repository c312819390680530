// Gesture Controller RPCs of the planner: BuildController (progress stream),
// Synthesize (offline DP), Control (online policy, bidi stream); and the
// "controllers" artifacts (controllers/<id>/<version>/controller.kctrl,
// depending on the library version they were built on).
#include <atomic>
#include <chrono>
#include <cmath>
#include <deque>
#include <filesystem>
#include <mutex>
#include <span>
#include <thread>

#include <google/protobuf/util/json_util.h>

#include "common/grpc/cancel_token.h"
#include "common/grpc/request_check.h"
#include "common/grpc/status_mapping.h"
#include "common/grpc/worker_write_reactor.h"
#include "common/logging/log.h"
#include "common/motion/bvh.h"
#include "services/planner/controller/controller_proto.h"
#include "services/planner/rpc/planner_service.h"

namespace kinemo::planner {
namespace {

using controller::Controller;

constexpr int kBuildStages = 4;  // segments, delta, value_iteration, culling
constexpr std::string_view kControllerFile = "controller.kctrl";

using StoredController = PlannerServiceImpl::StoredController;

// Commits a draft holding controller.kctrl, built on `library`, as the next
// version of its id, and serves it.
StatusOr<store::ArtifactMeta> CommitController(PlannerServiceImpl* svc, store::Draft draft,
                                               std::shared_ptr<StoredController> stored, const Library& library,
                                               std::string description, bool overwrite, std::string_view field) {
  const std::string id = draft.id();
  store::ArtifactMeta meta;
  meta.description = std::move(description);
  meta.depends_on.push_back({std::string(store::kLibraries), library.id, static_cast<std::uint32_t>(library.version)});
  v1::ControllerInfo summary = stored->info;
  summary.clear_version();
  meta.summary_json = SummaryJson(summary);
  return svc->CommitArtifact(std::move(draft), std::move(meta), overwrite, field, [&](int version) {
    stored->info.set_version(static_cast<uint32_t>(version));
    svc->controllers().Set(id, stored, version);
  });
}

void SetCreatedTime(std::int64_t unix_ms, v1::ControllerInfo* info) {
  info->mutable_created_time()->set_seconds(unix_ms / 1000);
  info->mutable_created_time()->set_nanos(static_cast<int>(unix_ms % 1000) * 1000000);
}

std::int64_t NowUnixMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

int StageIndex(std::string_view s) {
  if (s == "segments") return 0;
  if (s == "delta") return 1;
  if (s == "value_iteration") return 2;
  return 3;
}

StatusOr<std::vector<double>> StyleOf(const Controller& c, const v1::StyleVector& s) {
  std::vector<std::pair<std::string, double>> w;
  for (const auto& [tone, weight] : s.tone_weights()) w.emplace_back(tone, weight);
  std::sort(w.begin(), w.end());
  const double e = s.gesture_emphasis();
  if (e != 0 && std::isfinite(e) && std::abs(e) <= 1 && !c.HasEmphasis()) {
    log::Warn("gesture_emphasis_ignored",
              {{"reason", std::string("the controller was built without emphasis tables; rebuild it to use "
                                      "style.gesture_emphasis")},
               {"gesture_emphasis", e}});
  }
  return controller::StyleFromWeights(c, w, e);
}

void PlayToProto(const Controller& c, const controller::SegmentPlayOut& p, v1::SegmentPlay* out) {
  const auto& seg = c.segments().segments[static_cast<size_t>(p.segment)];
  out->set_segment_index(static_cast<uint32_t>(p.segment));
  out->set_clip(c.library().clips[static_cast<size_t>(seg.clip)].name);
  out->set_clip_first_frame(static_cast<uint32_t>(seg.first_frame + p.first));
  out->set_clip_last_frame(static_cast<uint32_t>(seg.first_frame + p.last));
  out->set_start_s(p.start_s);
  out->set_end_s(p.end_s);
  out->set_interrupted(p.interrupted);
  out->set_keyword(p.keyword);
}

Status BeliefFromProto(const v1::BeliefStep& b, controller::BeliefSpan* out) {
  out->start_s = b.start_s();
  out->end_s = b.end_s();
  out->probabilities.assign(b.probabilities().begin(), b.probabilities().end());
  double sum = 0;
  for (double v : out->probabilities) sum += v;
  if (std::isfinite(sum) && sum > 0 && std::abs(sum - 1) <= 1e-6)
    for (double& v : out->probabilities) v /= sum;
  return absl::OkStatus();
}

// ---------------------------------------------------------------------------
class BuildReactor final : public WorkerWriteReactor<v1::BuildControllerResponse> {
 public:
  BuildReactor(PlannerServiceImpl* svc, const v1::BuildControllerRequest* request) : svc_(svc), request_(*request) {
    const int limit = svc_->options().max_concurrent_builds() != 0 ? static_cast<int>(svc_->options().max_concurrent_builds()) : 1;
    if (!TakeSlot(&svc_->controller_builds, limit, "max_concurrent_builds", "builds")) return;
    StartWorker([this] { return Run(); });
  }

 private:
  Status Run() {
    if (!IsValidId(request_.controller_id())) return InvalidField("controller_id", "must match [a-z0-9_-]{1,64}");
    KINEMO_RETURN_IF_ERROR(
        svc_->CheckNewVersion(store::kControllers, request_.controller_id(), request_.overwrite(), "controller_id"));
    KINEMO_ASSIGN_OR_RETURN(auto library, svc_->libraries().Get(request_.library_id(), "library_id"));
    KINEMO_ASSIGN_OR_RETURN(controller::StateModel model, controller::FromProto(request_.state_model()));
    KINEMO_RETURN_IF_ERROR(CheckFitsInt(request_.params(), "params"));
    const controller::ControllerParams params =
        controller::FromProto(request_.params(), svc_->options().controller_defaults());
    KINEMO_RETURN_IF_ERROR(controller::ValidateControllerParams(params));
    const auto start = std::chrono::steady_clock::now();
    auto last = start - std::chrono::seconds(1);
    std::string last_stage;
    controller::BuildReport report;
    auto built = Controller::Build(
        library, model, params,
        [&](std::string_view stage, double fraction) {
          const auto now = std::chrono::steady_clock::now();
          if (stage != last_stage || now - last > std::chrono::milliseconds(200) || fraction >= 1) {
            last = now;
            last_stage = std::string(stage);
            Send(stage, fraction, std::chrono::duration<double>(now - start).count());
          }
          return !cancelled();
        },
        &report);
    if (cancelled()) return absl::CancelledError("build cancelled; nothing was stored");
    if (!built.ok()) return built.status();
    auto stored = std::make_shared<StoredController>();
    stored->controller = *built;
    controller::ToProto(**built, &stored->info);
    stored->info.set_controller_id(request_.controller_id());
    stored->info.set_inference_model_id(request_.inference_model_id());
    SetCreatedTime(NowUnixMs(), &stored->info);
    // The file records the stored library's manifest as its source, so that
    // `kinemo controller synthesize` can read it from the store too.
    KINEMO_ASSIGN_OR_RETURN(store::Draft draft, svc_->store().Begin(store::kControllers, request_.controller_id()));
    KINEMO_ASSIGN_OR_RETURN(std::string path, draft.PathFor(kControllerFile));
    const store::ArtifactRef library_ref{std::string(store::kLibraries), library->id,
                                         static_cast<std::uint32_t>(library->version)};
    KINEMO_RETURN_IF_ERROR((*built)->Save(path, {svc_->store().FilePath(library_ref, "manifest.json")}));
    KINEMO_RETURN_IF_ERROR(CommitController(svc_, std::move(draft), stored, *library,
                                            kinemo::StrCat("BuildController: inference model '",
                                                           request_.inference_model_id(), "'"),
                                            request_.overwrite(), "controller_id")
                               .status());
    const v1::ControllerInfo info = stored->info;
    v1::BuildControllerResponse msg;
    auto* p = msg.mutable_progress();
    p->set_stage("culling");
    p->set_stage_index(kBuildStages - 1);
    p->set_stage_count(kBuildStages);
    p->set_stage_fraction(1);
    p->set_fraction(1);
    p->set_elapsed_s(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    *msg.mutable_controller() = info;
    Enqueue(std::move(msg));
    return absl::OkStatus();
  }

  void Send(std::string_view stage, double fraction, double elapsed_s) {
    v1::BuildControllerResponse r;
    auto* p = r.mutable_progress();
    const int idx = StageIndex(stage);
    p->set_stage(std::string(stage));
    p->set_stage_index(static_cast<uint32_t>(idx));
    p->set_stage_count(kBuildStages);
    p->set_stage_fraction(fraction);
    p->set_fraction((idx + fraction) / kBuildStages);
    p->set_elapsed_s(elapsed_s);
    Enqueue(std::move(r));
  }
  PlannerServiceImpl* svc_;
  const v1::BuildControllerRequest request_;
};

// ---------------------------------------------------------------------------
// Control: reads one message, produces what it makes ready (frames up to the
// media time, decisions), writes those one by one, then reads the next.
//
// Media time is the audio clock: `advance_to_s` (the client's audio received)
// and on-time beliefs move it; frames are emitted up to it whatever the
// beliefs. A belief for a step that ended behind media time (prosody and
// inference lag the audio) does not hold frames back: it replaces α and is
// propagated by T_f over the frames already emitted since the step's end
// (α_{t+1} = T α_t without observations, Gesture Controllers §7.2), so it
// changes the decisions still to come. The segment being played continues;
// decisions happen at end points as always.
//
// Bounds: one message moves media time by at most kMaxAdvanceS, and never
// beyond start_time_s + max_output_s, so each message's work is bounded; the
// emit loop also stops when the call is cancelled.
constexpr double kMaxAdvanceS = 10.0;
constexpr double kMaxStartS = 1e6;

class ControlReactor final : public grpc::ServerBidiReactor<v1::ControlRequest, v1::ControlResponse> {
 public:
  explicit ControlReactor(PlannerServiceImpl* svc)
      : svc_(svc), max_output_s_(svc->options().max_output_s() > 0 ? svc->options().max_output_s() : 600) {
    const int limit = svc_->options().max_concurrent_streams() != 0 ? static_cast<int>(svc_->options().max_concurrent_streams()) : 1024;
    if (!slot_.Take(&svc_->control_streams, limit)) {
      Finish(ToGrpcStatus(absl::ResourceExhaustedError(kinemo::StrCat("max_concurrent_streams: ", limit, " streams are open"))));
      return;
    }
    StartRead(&request_);
  }
  void OnReadDone(bool ok) override {
    if (!ok) {
      End(grpc::Status::OK);
      return;
    }
    const Status st = Handle();
    if (!st.ok()) {
      End(ToGrpcStatus(st));
      return;
    }
    WriteNextOrRead();
  }
  void OnWriteDone(bool ok) override {
    if (!ok) {
      End(grpc::Status::CANCELLED);
      return;
    }
    out_.pop_front();
    WriteNextOrRead();
  }
  void OnCancel() override { cancelled_.store(true, std::memory_order_relaxed); }
  void OnDone() override { delete this; }

 private:
  // The slot is free before the client hears the end.
  void End(const grpc::Status& status) {
    slot_.Release();
    Finish(status);
  }
  void WriteNextOrRead() {
    if (!out_.empty()) {
      StartWrite(&out_.front());
    } else {
      StartRead(&request_);
    }
  }

  Status Handle() {
    if (!configured_) {
      if (!request_.has_config()) return InvalidField("config", "must be the first message");
      const auto& cfg = request_.config();
      KINEMO_ASSIGN_OR_RETURN(auto stored, svc_->controllers().Get(cfg.controller_id(), "controller_id"));
      stored_ = stored;
      const Controller& c = *stored_->controller;
      KINEMO_ASSIGN_OR_RETURN(on_rig_, svc_->MotionOnRig(cfg.rig_id(), c.library(), c.frame_time_s(), "config.rig_id"));
      policy_ = std::make_unique<controller::Policy>(c);
      KINEMO_ASSIGN_OR_RETURN(std::vector<double> style, StyleOf(c, cfg.style()));
      KINEMO_RETURN_IF_ERROR(policy_->SetStyle(style));
      if (!(cfg.start_time_s() >= 0 && cfg.start_time_s() <= kMaxStartS))
        return InvalidField("config.start_time_s", "must be in [0, ", kMaxStartS, "] s");
      start_s_ = media_s_ = cfg.start_time_s();
      emit_decisions_ = cfg.emit_decisions();
      assembler_ = std::make_unique<controller::FrameAssembler>(c.segments(), controller::DefaultBlendFrames(c.frame_time_s()));
      frame_.resize(static_cast<size_t>(c.library().skeleton.num_channels()));
      if (on_rig_) rig_frame_.resize(static_cast<size_t>(on_rig_->num_channels()));
      configured_ = true;
      v1::ControlResponse r;
      if (on_rig_) {
        SkeletonToProto(on_rig_->skeleton(), on_rig_->meters_per_unit(), on_rig_->regions(), on_rig_->name(),
                        r.mutable_header()->mutable_skeleton());
      } else {
        const Library& lib = c.library();
        SkeletonToProto(lib.skeleton, lib.meters_per_unit, lib.regions, motion::SkeletonFamilyName(lib.regions.family),
                        r.mutable_header()->mutable_skeleton());
      }
      r.mutable_header()->set_frame_time_s(c.frame_time_s());
      out_.push_back(std::move(r));
      return absl::OkStatus();
    }
    const Controller& c = *stored_->controller;
    switch (request_.message_case()) {
      case v1::ControlRequest::kConfig:
        return InvalidField("config", "sent twice");
      case v1::ControlRequest::kBelief: {
        const auto& b = request_.belief();
        if (have_belief_ && b.step() <= last_step_) return InvalidField("belief.step", "must increase (got ", b.step(), ")");
        if (!std::isfinite(b.start_s()) || b.start_s() < 0) return InvalidField("belief.start_s", "must be finite and >= 0");
        if (!std::isfinite(b.end_s()) || b.end_s() < b.start_s()) return InvalidField("belief.end_s", "must be >= start_s");
        KINEMO_RETURN_IF_ERROR(CheckMediaTime(b.end_s(), "belief.end_s"));
        const size_t n = static_cast<size_t>(b.probabilities_size());
        if (n != static_cast<size_t>(c.num_states()))
          return InvalidField("belief.probabilities", "has ", n, " values, the controller has ", c.num_states(), " states");
        double sum = 0;
        for (double v : b.probabilities()) sum += v;
        if (std::isfinite(sum) && std::abs(sum - 1) > 1e-6) return InvalidField("belief.probabilities", "sum to ", sum, ", not 1");
        const std::span<const double> p(b.probabilities().data(), n);
        if (b.end_s() <= media_s_) {
          // Late: frames up to media time are out; α for the next frame.
          KINEMO_RETURN_IF_ERROR(Annotate(policy_->SetBelief(p), "belief"));
          const std::int64_t since_end = frames_ - FramesBefore(b.end_s());
          const std::int64_t bound = std::lround(kMaxAdvanceS / c.frame_time_s());
          for (std::int64_t k = 1; k < std::min(since_end, bound); ++k) policy_->Advance();
          fresh_belief_ = since_end <= 0;
        } else {
          // Frames before this step's start use the previous belief.
          Emit(b.start_s());
          KINEMO_RETURN_IF_ERROR(Annotate(policy_->SetBelief(p), "belief"));
          fresh_belief_ = true;
          Emit(b.end_s());
        }
        have_belief_ = true;
        last_step_ = b.step();
        return absl::OkStatus();
      }
      case v1::ControlRequest::kKeyword: {
        const int k = c.KeywordIndex(request_.keyword().word());
        if (k >= 0) KINEMO_RETURN_IF_ERROR(policy_->SetKeyword(k));
        return absl::OkStatus();
      }
      case v1::ControlRequest::kStyle: {
        KINEMO_ASSIGN_OR_RETURN(std::vector<double> style, StyleOf(c, request_.style()));
        KINEMO_RETURN_IF_ERROR(policy_->SetStyle(style));
        ++style_changes_;
        restyle_ = true;
        return absl::OkStatus();
      }
      case v1::ControlRequest::kAdvanceToS:
        KINEMO_RETURN_IF_ERROR(CheckMediaTime(request_.advance_to_s(), "advance_to_s"));
        Emit(request_.advance_to_s());
        return absl::OkStatus();
      default:
        return InvalidField("message", "empty request");
    }
  }

  // A time a message may move media time to: finite, at most kMaxAdvanceS
  // past media time, and within max_output_s of the stream's start.
  Status CheckMediaTime(double t, const char* field) const {
    if (!std::isfinite(t)) return InvalidField(field, "must be finite");
    if (t > start_s_ + max_output_s_)
      return InvalidField(field, t, " s is past the stream's end at ", start_s_ + max_output_s_, " s (max_output_s)");
    if (t - media_s_ > kMaxAdvanceS)
      return InvalidField(field, "moves media time from ", media_s_, " s to ", t, " s; at most ", kMaxAdvanceS,
                          " s per message");
    return absl::OkStatus();
  }

  // Frames whose time is before t_s (the emit loop's rule).
  std::int64_t FramesBefore(double t_s) const {
    const double dt = stored_->controller->frame_time_s();
    return std::max<std::int64_t>(0, static_cast<std::int64_t>(std::ceil((t_s - start_s_) / dt - 1e-3)));
  }

  // Frames with time < until_s.
  void Emit(double until_s) {
    const Controller& c = *stored_->controller;
    const auto& L = c.segments();
    const double dt = c.frame_time_s();
    kinemo::common::v1::MotionFrameBatch* batch = nullptr;
    while (start_s_ + static_cast<double>(frames_) * dt < until_s - 1e-3 * dt) {  // BVH frame times are rounded
      if (cancelled_.load(std::memory_order_relaxed)) return;
      const double t = start_s_ + static_cast<double>(frames_) * dt;
      if (!fresh_belief_ && frames_ > 0) policy_->Advance();
      fresh_belief_ = false;
      bool decided = false;
      controller::Decision d;
      const auto t0 = std::chrono::steady_clock::now();
      if (segment_ < 0) {
        d = policy_->Start();
        decided = true;
      } else if (frame_in_ == L.end_points[static_cast<size_t>(end_point_)].frame) {
        d = policy_->Decide(end_point_);
        decided = true;
      } else if (restyle_) {
        // A style change since the last decision takes effect at this frame,
        // not at the coming end point: the policy decides now with that end
        // point's values (the table's nearest). Continuing keeps playing this
        // segment (the new tone chose it); anything else leaves it here,
        // blended like any interruption.
        d = policy_->Decide(end_point_);
        if (d.continuation) {
          d.segment = segment_;
          d.start = frame_in_ + 1;
          d.end_point = end_point_;
        } else {
          d.interrupted = true;
        }
        decided = true;
      } else {
        ++frame_in_;
      }
      if (decided) restyle_ = false;
      if (decided) {
        const double us = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count();
        segment_ = d.segment;
        frame_in_ = d.start;
        end_point_ = d.end_point;
        if (emit_decisions_) {
          if (batch != nullptr) batch = nullptr;
          v1::ControlResponse r;
          auto* dec = r.mutable_decision();
          dec->set_time_s(t);
          controller::SegmentPlayOut p;
          p.segment = d.segment;
          p.first = d.start;
          p.last = L.end_points[static_cast<size_t>(d.end_point)].frame;
          p.start_s = t;
          p.end_s = t + (p.last - p.first + 1) * dt;
          p.interrupted = d.interrupted;
          if (d.keyword >= 0) p.keyword = c.keywords()[static_cast<size_t>(d.keyword)];
          PlayToProto(c, p, dec->mutable_next());
          dec->set_expected_cost(d.expected_cost);
          dec->set_decide_us(us);
          dec->set_style_changes(style_changes_);
          out_.push_back(std::move(r));
        }
      }
      assembler_->Next(segment_, frame_in_, frame_);
      if (batch == nullptr) {
        out_.emplace_back();
        batch = out_.back().mutable_frames();
      }
      auto* f = batch->add_frames();
      f->set_time_s(t);
      if (on_rig_) {
        // Retargeting cannot fail on a frame of the library's size.
        (void)on_rig_->Frame(frame_, rig_frame_);
        f->mutable_values()->Assign(rig_frame_.begin(), rig_frame_.end());
      } else {
        f->mutable_values()->Assign(frame_.begin(), frame_.end());
      }
      ++frames_;
    }
    media_s_ = std::max(media_s_, until_s);
  }

  PlannerServiceImpl* svc_;
  const double max_output_s_;
  std::atomic<bool> cancelled_{false};
  CallSlot slot_;  // max_concurrent_streams
  bool configured_ = false, emit_decisions_ = false;
  bool have_belief_ = false, fresh_belief_ = false;
  std::uint64_t last_step_ = 0;
  std::uint64_t style_changes_ = 0;  // style messages applied
  bool restyle_ = false;             // a style message since the last decision
  v1::ControlRequest request_;
  std::deque<v1::ControlResponse> out_;
  std::shared_ptr<const PlannerServiceImpl::StoredController> stored_;
  std::unique_ptr<controller::Policy> policy_;
  std::unique_ptr<controller::FrameAssembler> assembler_;
  std::vector<double> frame_;
  std::unique_ptr<rig::RigMotion> on_rig_;  // config.rig_id: frames on the user's rig
  std::vector<double> rig_frame_;
  double start_s_ = 0, media_s_ = 0;
  std::int64_t frames_ = 0;
  int segment_ = -1, frame_in_ = 0, end_point_ = 0;
};

}  // namespace

grpc::ServerWriteReactor<v1::BuildControllerResponse>* PlannerServiceImpl::BuildController(
    grpc::CallbackServerContext* /*ctx*/, const v1::BuildControllerRequest* request) {
  return new BuildReactor(this, request);
}

StatusOr<PlannerServiceImpl::ControllerSynthesis> PlannerServiceImpl::RunSynthesize(
    const v1::SynthesizeRequest& request, double max_output_s, const CancelToken* cancel) {
  ControllerSynthesis out;
  KINEMO_ASSIGN_OR_RETURN(out.stored, controllers().Get(request.controller_id(), "controller_id"));
  const Controller& c = *out.stored->controller;
  std::vector<controller::BeliefSpan> beliefs(static_cast<size_t>(request.beliefs_size()));
  for (int i = 0; i < request.beliefs_size(); ++i)
    KINEMO_RETURN_IF_ERROR(BeliefFromProto(request.beliefs(i), &beliefs[static_cast<size_t>(i)]));
  controller::SynthesisOptions o;
  if (!std::isfinite(request.duration_s()) || request.duration_s() < 0) return InvalidField("duration_s", "must be >= 0");
  o.duration_s = request.duration_s();
  o.max_duration_s = max_output_s;
  o.cancel = cancel;
  KINEMO_ASSIGN_OR_RETURN(o.style, StyleOf(c, request.style()));
  for (const auto& w : request.keywords()) o.keywords.push_back({w.word(), w.start_s(), w.end_s()});
  KINEMO_ASSIGN_OR_RETURN(std::unique_ptr<rig::RigMotion> on_rig,
                          MotionOnRig(request.rig_id(), c.library(), c.frame_time_s(), "rig_id"));
  KINEMO_ASSIGN_OR_RETURN(out.result, controller::Synthesize(c, beliefs, o));
  if (on_rig) {
    KINEMO_ASSIGN_OR_RETURN(out.motion.clip, on_rig->Clip(out.result.clip));
    out.motion.meters_per_unit = on_rig->meters_per_unit();
    out.motion.regions = on_rig->regions();
    out.motion.skeleton_name = on_rig->name();
  } else {
    out.motion.clip = std::move(out.result.clip);
    out.motion.meters_per_unit = c.library().meters_per_unit;
    out.motion.regions = c.library().regions;
    out.motion.skeleton_name = std::string(motion::SkeletonFamilyName(c.library().regions.family));
  }
  out.result.clip = motion::Clip();
  out.motion.clip_name = request.controller_id();
  return out;
}

namespace {

// Everything of Synthesize's response but the motion.
void FillSynthesizeResponse(const PlannerServiceImpl::ControllerSynthesis& out, const v1::SynthesizeRequest& request,
                            v1::SynthesizeResponse* response) {
  for (const auto& p : out.result.plays) PlayToProto(*out.stored->controller, p, response->add_segments());
  response->set_max_transition_angular_speed_dps(out.result.max_transition_dps);
  response->set_compute_s(out.result.compute_s);
  response->set_request_id(request.request_id());
}

}  // namespace

grpc::ServerUnaryReactor* PlannerServiceImpl::Synthesize(grpc::CallbackServerContext* ctx,
                                                         const v1::SynthesizeRequest* request,
                                                         v1::SynthesizeResponse* response) {
  const std::unique_ptr<CancelToken> cancel = CallCancelToken(*ctx);
  auto out = RunSynthesize(*request, options().max_output_s() > 0 ? options().max_output_s() : 600, cancel.get());
  if (!out.ok()) return FinishUnary(ctx, out.status());
  const MotionOut& m = out->motion;
  const Status written = MotionToProto(m.clip, m.meters_per_unit, m.regions, m.skeleton_name, m.clip_name,
                                       request->format(), m.bvh, response->mutable_motion());
  if (!written.ok()) return FinishUnary(ctx, written);
  FillSynthesizeResponse(*out, *request, response);
  return FinishUnary(ctx, absl::OkStatus());
}

// The synthesis on a worker thread, then the motion in pieces as the client
// reads them, then the rest of the response.
grpc::ServerWriteReactor<v1::SynthesizeChunkedResponse>* PlannerServiceImpl::SynthesizeChunked(
    grpc::CallbackServerContext* ctx, const v1::SynthesizeRequest* request) {
  using Response = v1::SynthesizeChunkedResponse;
  return NewChunkedCall<Response>(this, [this, ctx, request = *request](const auto& send) -> Status {
    const std::unique_ptr<CancelToken> cancel = CallCancelToken(*ctx);
    KINEMO_ASSIGN_OR_RETURN(ControllerSynthesis out, RunSynthesize(request, MaxChunkedOutputS(options()), cancel.get()));
    Response last;
    FillSynthesizeResponse(out, request, last.mutable_result());
    KINEMO_RETURN_IF_ERROR(SendMotionPieces<Response>(std::move(out.motion), request.format(), send));
    send(std::move(last));
    return absl::OkStatus();
  });
}

grpc::ServerBidiReactor<v1::ControlRequest, v1::ControlResponse>* PlannerServiceImpl::Control(
    grpc::CallbackServerContext* /*ctx*/) {
  return new ControlReactor(this);
}

// ---- "controllers" artifacts ---------------------------------------------------

PlannerServiceImpl::ArtifactKind PlannerServiceImpl::ControllerKind() {
  ArtifactKind k;
  k.kind = std::string(store::kControllers);
  k.served_version = [this](const std::string& id) { return controllers_.Version(id); };
  k.unserve = [this](const std::string& id) { controllers_.Remove(id); };
  k.serve = [this](const store::ArtifactMeta& meta) -> Status {
    KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<const Library> library, DependencyLibrary(meta));
    KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<const Controller> c,
                            Controller::Load(store_->FilePath(meta.ref(), kControllerFile), library));
    auto stored = std::make_shared<StoredController>();
    stored->controller = c;
    controller::ToProto(*c, &stored->info);
    v1::ControllerInfo recorded;
    if (google::protobuf::util::JsonStringToMessage(meta.summary_json, &recorded).ok()) {
      stored->info.set_inference_model_id(recorded.inference_model_id());
    }
    stored->info.set_controller_id(meta.id);
    stored->info.set_version(meta.version);
    SetCreatedTime(meta.created_unix_ms, &stored->info);
    controllers_.Set(meta.id, std::move(stored), static_cast<int>(meta.version));
    return absl::OkStatus();
  };
  // A controller file built elsewhere (kinemo controller build --out), pushed
  // with the stored library it was built on.
  k.push = [this](store::Draft draft,
                  const common::v1::PushArtifactHeader& header) -> StatusOr<common::v1::PushArtifactResponse> {
    const std::string name = header.files(0).name();
    if (header.files_size() != 1 || name.size() < 6 || name.substr(name.size() - 6) != ".kctrl") {
      return InvalidField("header.files", "a controller is one .kctrl file (kinemo controller build --out)");
    }
    KINEMO_ASSIGN_OR_RETURN(int dep, LibraryDependency(header));
    if (dep < 0) {
      return InvalidField("header.depends_on", "name the stored library the controller was built on (kind libraries)");
    }
    const std::string& id = header.ref().id();
    KINEMO_RETURN_IF_ERROR(CheckNewVersion(store::kControllers, id, header.overwrite(), "header.ref.id"));
    const std::string field = kinemo::StrCat("header.depends_on[", dep, "]");
    KINEMO_ASSIGN_OR_RETURN(
        std::shared_ptr<const Library> library,
        StoredLibrary(header.depends_on(dep).id(), header.depends_on(dep).version(), field));
    const std::string path = kinemo::StrCat(draft.dir(), "/", name);
    auto c = Controller::Load(path, library);
    if (!c.ok()) {
      return PushError(c.status(), draft, absl::IsFailedPrecondition(c.status()) ? field : "header.files[0]");
    }
    if (name != kControllerFile) {
      std::error_code ec;
      std::filesystem::rename(path, kinemo::StrCat(draft.dir(), "/", kControllerFile), ec);
      if (ec) return absl::InternalError(kinemo::StrCat("store: cannot rename ", name, ": ", ec.message()));
    }
    auto stored = std::make_shared<StoredController>();
    stored->controller = *c;
    controller::ToProto(**c, &stored->info);
    stored->info.set_controller_id(id);
    SetCreatedTime(NowUnixMs(), &stored->info);
    KINEMO_ASSIGN_OR_RETURN(store::ArtifactMeta meta,
                            CommitController(this, std::move(draft), stored, *library, header.description(),
                                             header.overwrite(), "header.ref.id"));
    common::v1::PushArtifactResponse response;
    *response.mutable_artifact() = kinemo::ToProto(meta);
    return response;
  };
  return k;
}

}  // namespace kinemo::planner
