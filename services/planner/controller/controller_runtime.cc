// Runtime of the Gesture Controller: the online policy (Gesture Controllers
// §7.2 "Online Animation as a Markov Decision Process": the decision
// argmin_{a',f'} Σ_i α_t(i) V_d(a', f', a, f, s_i) over the culled table,
// α_{t+1} = α_t T without observations) and the frame assembly that turns its
// plays into a continuous, blended, foot-planted frame stream (§7.1's
// animation sequence A as frames). The offline build is in
// controller_build.cc, offline synthesis in controller_synthesis.cc.
#include "services/planner/controller/controller.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>

#include <Eigen/Geometry>

#include "common/motion/body_regions.h"
#include "common/motion/kinematics.h"
#include "common/motion/resample.h"
#include "services/planner/controller/controller_internal.h"
#include "services/planner/library/feet.h"

namespace kinemo::planner::controller {

using internal::kInf;

// ---------------------------------------------------------------------------
// Policy

Policy::Policy(const Controller& controller, double min_play_s, double max_run_s, double recent_s)
    : c_(controller),
      alpha_(controller.state_model().initial),
      tmp_(controller.num_states()),
      style_(Eigen::VectorXd::Zero(controller.num_tones())),
      min_play_frames_(std::max(0, static_cast<int>(std::lround(min_play_s / controller.frame_time_s())))),
      max_run_frames_(std::max(0, static_cast<int>(std::lround(max_run_s / controller.frame_time_s())))),
      recent_frames_(std::max(0, static_cast<int>(std::lround(recent_s / controller.frame_time_s())))),
      last_shown_(static_cast<size_t>(controller.segments().num_segments()), std::numeric_limits<std::int64_t>::min() / 2) {
  const int neutral = c_.ToneIndex(c_.params().neutral_tone);
  style_(neutral >= 0 ? neutral : 0) = 1;
}

Status Policy::SetBelief(std::span<const double> p) {
  if (static_cast<int>(p.size()) != c_.num_states())
    return InvalidField("probabilities", "has ", p.size(), " values, the controller has ", c_.num_states(), " states");
  double sum = 0;
  for (double v : p) {
    if (!std::isfinite(v) || v < 0) return InvalidField("probabilities", "must be finite and non-negative");
    sum += v;
  }
  if (!(sum > 0)) return InvalidField("probabilities", "sum to 0");
  for (size_t i = 0; i < p.size(); ++i) alpha_(static_cast<Eigen::Index>(i)) = p[i] / sum;
  return absl::OkStatus();
}

void Policy::Advance() {
  tmp_.noalias() = c_.frame_transition().transpose() * alpha_;
  alpha_.swap(tmp_);
}

Status Policy::SetStyle(std::span<const double> weights) {
  if (static_cast<int>(weights.size()) != c_.num_tones())
    return InvalidField("style", "has ", weights.size(), " weights, the controller has ", c_.num_tones(), " tones");
  double sum = 0;
  for (double v : weights) {
    if (!std::isfinite(v) || v < 0) return InvalidField("style", "weights must be finite and non-negative");
    sum += v;
  }
  if (!(sum > 0)) return InvalidField("style", "weights sum to 0");
  for (size_t i = 0; i < weights.size(); ++i) style_(static_cast<Eigen::Index>(i)) = weights[i] / sum;
  return absl::OkStatus();
}

Status Policy::SetKeyword(int keyword) {
  if (keyword < -1 || keyword >= static_cast<int>(c_.keywords().size()))
    return InvalidField("keyword", keyword, " is out of range");
  keyword_ = keyword;
  return absl::OkStatus();
}

Decision Policy::Start() {
  const int w = keyword_ + 1;
  const int S = c_.num_states(), M = c_.num_tones();
  Decision best;
  best.expected_cost = kInf;
  for (int b = 0; b < c_.segments().num_segments(); ++b) {
    if (w > 0 && c_.Matches(b, w)) continue;
    double v = 0;
    for (int m = 0; m < M; ++m) {
      if (style_(m) == 0) continue;
      const double* u = c_.U(m, w).data() + static_cast<Eigen::Index>(b) * S;
      double dot = 0;
      for (int i = 0; i < S; ++i) dot += alpha_(i) * u[i];
      v += style_(m) * dot;
    }
    if (v < best.expected_cost) {
      best.expected_cost = v;
      best.segment = b;
    }
  }
  best.end_point = c_.segments().segments[static_cast<size_t>(best.segment)].first_end;
  play_segment_ = best.segment;
  play_start_ = best.start;
  run_base_ = 0;
  BeginBlock(best);
  return best;
}

void Policy::BeginBlock(const Decision& d) {
  block_segment_ = d.segment;
  block_start_ = d.start;
}

Decision Policy::Decide(int e) {
  const SegmentLibrary& L = c_.segments();
  const EndPoint& ep = L.end_points[static_cast<size_t>(e)];
  const auto& sa = L.segments[static_cast<size_t>(ep.segment)];
  const int w = keyword_ + 1;
  const int S = c_.num_states(), M = c_.num_tones();
  // The clock: the block played since the last decision has been shown.
  if (ep.segment == block_segment_) clock_ += std::max(0, ep.frame + 1 - block_start_);
  last_shown_[static_cast<size_t>(ep.segment)] = clock_;
  auto dot_row = [&](auto&& row_of) {
    double v = 0;
    for (int m = 0; m < M; ++m) {
      if (style_(m) == 0) continue;
      const double* r = row_of(m);
      double d = 0;
      for (int i = 0; i < S; ++i) d += alpha_(i) * r[i];
      v += style_(m) * d;
    }
    return v;
  };
  Decision best;
  best.expected_cost = kInf;
  // The run since the last choice (the chosen play and the successors it
  // continued into) up to this end point: whether it is young (it goes on:
  // kDefaultMinPlaySeconds) or must end here (kDefaultMaxRunSeconds).
  const bool playing = ep.segment == play_segment_;
  const int run = playing ? run_base_ + ep.frame + 1 - play_start_ : 0;
  const bool young = w == 0 && playing && run < min_play_frames_;
  const bool run_over = w == 0 && max_run_frames_ > 0 && run >= max_run_frames_ && !young;
  auto finish = [&](const Decision& d) {
    if (d.keyword >= 0) keyword_ = -1;
    if (!d.continuation) {
      // Entering the true successor at its first frame from the last frame
      // continues the run; anything else starts a new one.
      const bool chained = ep.last && d.segment == sa.next && d.start == 0 && playing;
      run_base_ = chained ? run : 0;
      play_segment_ = d.segment;
      play_start_ = d.start;
    }
    BeginBlock(d);
    return d;
  };
  if (!ep.last && !run_over) {
    best.expected_cost = dot_row([&](int m) { return c_.Vc(m, w).data() + static_cast<Eigen::Index>(e) * S; });
    best.segment = ep.segment;
    best.start = ep.frame + 1;
    best.end_point = e + 1;
    best.continuation = true;
    if (w > 0 && c_.Matches(ep.segment, w)) best.keyword = keyword_;
    // A young run continues (no pending keyword): see kDefaultMinPlaySeconds.
    if (young) return finish(best);
  }
  const float* srow = L.transition.data() + static_cast<size_t>(e) * L.num_segments();
  auto entry_value = [&](int b) {
    return srow[b] + dot_row([&](int m) { return c_.U(m, w).data() + static_cast<Eigen::Index>(b) * S; });
  };
  // Entries ruled out: past the run's end, the continuation's successor and
  // the segment itself; with the memory, every segment shown in the last
  // recent_s (a pending keyword decides as before).
  const bool remember = w == 0 && recent_frames_ > 0;
  auto possible = [&](int b) { return !(run_over && (b == ep.segment || (ep.last && b == sa.next))); };
  auto allowed = [&](int b) {
    return possible(b) && !(remember && clock_ - last_shown_[static_cast<size_t>(b)] < recent_frames_);
  };
  auto consider = [&](int b) {
    const double v = entry_value(b);
    if (v < best.expected_cost) {
      best = Decision{};
      best.expected_cost = v;
      best.segment = b;
      best.end_point = L.segments[static_cast<size_t>(b)].first_end;
      best.interrupted = !ep.last;
    }
  };
  // Culling dropped the entries that another action at e dominates: when one
  // of the kept entries is ruled out, the best allowed entry may be among the
  // dropped ones, so every segment is scanned (one scan of the segments).
  bool scan_all = run_over;
  if (!scan_all)
    for (int b : c_.Kept(w, e))
      if (!allowed(b)) {
        scan_all = true;
        break;
      }
  if (scan_all) {
    for (int b = 0; b < L.num_segments(); ++b)
      if (allowed(b)) consider(b);
    if (best.expected_cost == kInf && remember) {
      // Every entry was shown recently (a small library): the memory yields.
      for (int b = 0; b < L.num_segments(); ++b)
        if (possible(b)) consider(b);
    }
  } else {
    for (int b : c_.Kept(w, e)) consider(b);
  }
  if (w > 0) {
    const auto entries = c_.SemanticEntries(w, e);
    const int base = c_.SemanticBase(w, e);
    for (size_t q = 0; q < entries.size(); ++q) {
      const double v = dot_row([&](int m) { return c_.SemanticValues(m, w, base + static_cast<int>(q)).data(); });
      if (v < best.expected_cost) {
        const auto& s = entries[q];
        best = Decision{};
        best.expected_cost = v;
        best.segment = s.segment;
        best.start = s.start;
        best.end_point = L.segments[static_cast<size_t>(s.segment)].first_end + s.h;
        best.interrupted = !ep.last;
        best.keyword = keyword_;
      }
    }
  }
  if (best.expected_cost == kInf) {
    // Every entry but the successor was culled here: the run goes on.
    const int b = ep.last ? sa.next : ep.segment;
    if (b >= 0) {
      best.segment = b;
      best.start = ep.last ? 0 : ep.frame + 1;
      best.end_point = ep.last ? L.segments[static_cast<size_t>(b)].first_end : e + 1;
      best.continuation = !ep.last;
      best.expected_cost = 0;
    }
  }
  return finish(best);
}

// ---------------------------------------------------------------------------
// Frame assembly

FrameAssembler::FrameAssembler(const SegmentLibrary& segments, int blend_frames, const motion::FootPlantParams& feet,
                               int start_frames)
    : s_(segments),
      skel_(segments.library->skeleton),
      blend_frames_(std::max(0, blend_frames)),
      start_frames_(start_frames >= 0 ? start_frames
                                      : static_cast<int>(std::lround(0.5 * (segments.library->frame_rate_hz > 0
                                                                                 ? segments.library->frame_rate_hz
                                                                                 : 30.0)))),
      inertializer_(segments.library->skeleton),
      stance_(*segments.library) {
  const size_t n = static_cast<size_t>(skel_.num_channels());
  prev_.resize(n);
  a_.resize(n);
  t1_.resize(n);
  t2_.resize(n);
  t3_.resize(n);
  rest_.resize(n);
  prev_rot_.resize(static_cast<size_t>(skel_.num_joints()));
  cur_rot_.resize(prev_rot_.size());
  if (StatusOr<motion::KeyJoints> key = motion::FindKeyJoints(skel_, segments.library->regions); key.ok()) {
    const int ends[] = {key->head, key->left_hand, key->right_hand, key->left_foot, key->right_foot};
    gap_joints_ = motion::JointsWithAncestors(skel_, ends);
  } else {
    for (int j = 0; j < skel_.num_joints(); ++j) gap_joints_.push_back(j);
  }
  if (feet.enabled) {
    const Library& lib = *segments.library;
    const double dt = lib.frame_rate_hz > 0 ? 1.0 / lib.frame_rate_hz : 1.0 / 30;
    auto planter = [&]() -> StatusOr<std::unique_ptr<motion::FootPlanter>> {
      KINEMO_ASSIGN_OR_RETURN(motion::FootPlantParams p, LibraryFootPlantParams(lib, s_.ground_height_m, feet));
      return motion::FootPlanter::Create(skel_, lib.regions, dt, p);
    }();
    if (planter.ok()) {
      planter_ = *std::move(planter);
    } else {
      feet_status_ = Annotate(planter.status(), "feet");
    }
  }
}

FrameAssembler::~FrameAssembler() = default;

namespace {

void CopyFrame(const motion::Clip& clip, int f, const Eigen::Vector3d& offset, const motion::Joint& root,
               std::span<double> out) {
  const auto src = clip.frame(std::clamp(f, 0, clip.num_frames() - 1));
  std::copy(src.begin(), src.end(), out.begin());
  for (int k : {0, 2})
    if (root.position_column[static_cast<size_t>(k)] >= 0) out[static_cast<size_t>(root.position_column[static_cast<size_t>(k)])] += offset(k);
}

}  // namespace

int FrameAssembler::TransitionFrames(std::span<const double> to) const {
  // Long enough that the difference's decay (peak rate 1.875/T of the
  // largest joint angle between the two poses) stays under 0.4 x the
  // library's 99th-percentile joint speed; at most 4x the nominal length.
  const double dt = 1.0 / s_.library->frame_rate_hz;
  double gap_deg = 0;
  for (int j : gap_joints_) gap_deg = std::max(gap_deg, motion::JointAngularSpeedDps(skel_.joint(j), prev_, to, 1.0));
  const double limit_dps = std::max(30.0, 0.4 * s_.angular_speed_p99_dps);
  const int need = static_cast<int>(std::ceil(1.875 * gap_deg / (limit_dps * dt)));
  return std::clamp(need, std::max(1, blend_frames_), 4 * std::max(1, blend_frames_));
}

void FrameAssembler::StartTransition(const motion::Clip& clip, int g, int frames) {
  const motion::Joint& root = skel_.joint(0);
  CopyFrame(clip, g - 1, offset_, root, t1_);
  CopyFrame(clip, g - 2, offset_, root, t2_);
  CopyFrame(clip, g - 3, offset_, root, t3_);
  // A transition lengthened for far-apart poses (up to 4x) carries the
  // motion shown over at most twice the nominal length: carried over all of
  // a 2.4 s decay, a BEAT2 leg's swing kicked its foot 1.5 m up (GC online
  // with a 12-state model and shorter limits); no output of the default
  // models changes (their transitions stay under twice the nominal).
  inertializer_.Start(t1_, t2_, t3_, frames, true, 2 * blend_frames_);
}

void FrameAssembler::RestAt(int clip, int frame) {
  const motion::Joint& root = skel_.joint(0);
  const auto& clips = s_.library->clips;
  const Eigen::Vector2d here = stance_.At(clip, std::clamp(frame, 0, clips[static_cast<size_t>(clip)].clip.num_frames() - 1)) +
                               Eigen::Vector2d(offset_(0), offset_(2));
  const Eigen::Vector2d rest = stance_.At(s_.rest.clip, s_.rest.frame);
  const Eigen::Vector3d shift(here.x() - rest.x(), 0, here.y() - rest.y());
  CopyFrame(clips[static_cast<size_t>(s_.rest.clip)].clip, s_.rest.frame, shift, root, rest_);
}

void FrameAssembler::Next(int segment, int f, std::span<double> out) {
  const auto& seg = s_.segments[static_cast<size_t>(segment)];
  const auto& clips = s_.library->clips;
  const motion::Joint& root = skel_.joint(0);
  const int c = seg.clip, g = std::min(seg.first_frame + f, clips[static_cast<size_t>(c)].clip.num_frames() - 1);
  const motion::Clip& clip = clips[static_cast<size_t>(c)].clip;
  bool jumped = false;
  if (frames_out_ > 0 && (resting_ || !(c == cur_clip_ && g == cur_frame_ + 1))) {
    jumped = true;
    ++transitions_;
    // The new segment stands where the old one would have stood next.
    const motion::Clip& old = clips[static_cast<size_t>(cur_clip_)].clip;
    // (An eased first segment was shown behind the plan: from where it was.)
    const int shown = easing_ ? ease_shown_ : cur_frame_;
    const Eigen::Vector2d next_stance =
        stance_.At(cur_clip_, std::min(shown + 1, old.num_frames() - 1)) + Eigen::Vector2d(offset_(0), offset_(2));
    const Eigen::Vector2d new_stance = stance_.At(c, g);
    offset_ = Eigen::Vector3d(next_stance.x() - new_stance.x(), 0, next_stance.y() - new_stance.y());
    resting_ = false;
    easing_ = false;
  }
  CopyFrame(clip, g, offset_, root, a_);
  if (frames_out_ == 0 && start_frames_ > 0) {
    // Begin at rest: the rest pose, standing where the first segment stands,
    // as the frames "shown" before the first one; the first segment eases in
    // from standstill (its frame g held as its past: no velocity to carry).
    RestAt(c, g);
    for (int k = 0; k < 3; ++k) inertializer_.Apply(rest_, t1_);
    std::copy(rest_.begin(), rest_.end(), prev_.begin());
    easing_ = true;
    ease_first_ = g;
    inertializer_.Start(a_, a_, a_, std::max(start_frames_, TransitionFrames(a_)), true, 2 * blend_frames_);
  } else if (easing_) {
    // Playback time since the start: ∫ smoothstep(k / S) dk, then k − S / 2.
    const double S = start_frames_, x = std::min(1.0, frames_out_ / S);
    const double played = frames_out_ < S ? S * (x * x * x - 0.5 * x * x * x * x) : frames_out_ - 0.5 * S;
    const double u = std::min<double>(ease_first_ + played, clip.num_frames() - 1);
    const int i = static_cast<int>(std::floor(u));
    const int i1 = std::min(i + 1, clip.num_frames() - 1);
    motion::InterpolateFrame(skel_, clip.frame(i), clip.frame(i1), u - i, clip.frame(i), a_);
    ease_shown_ = static_cast<int>(std::lround(u));
    for (int k : {0, 2}) {
      if (root.position_column[static_cast<size_t>(k)] >= 0) a_[static_cast<size_t>(root.position_column[static_cast<size_t>(k)])] += offset_(k);
    }
  }
  if (jumped && blend_frames_ > 0) StartTransition(clip, g, TransitionFrames(a_));
  const bool transition = jumped || inertializer_.active();
  inertializer_.Apply(a_, out);
  cur_clip_ = c;
  cur_frame_ = g;
  Finish(transition, out);
}

void FrameAssembler::NextRest(int frames, std::span<double> out) {
  if (frames_out_ == 0) {
    // Nothing shown yet: the rest pose where the first segment would stand.
    offset_.setZero();
    RestAt(s_.segments.empty() ? s_.rest.clip : s_.segments[0].clip, 0);
    std::copy(rest_.begin(), rest_.end(), out.begin());
    resting_ = true;
    cur_clip_ = s_.rest.clip;
    cur_frame_ = s_.rest.frame;
    Finish(false, out);
    return;
  }
  bool jumped = false;
  if (!resting_) {
    jumped = true;
    ++transitions_;
    RestAt(cur_clip_, cur_frame_);
    inertializer_.Start(rest_, rest_, rest_, std::max(1, frames));
    resting_ = true;
    // Later segments stand where the rest pose stands.
    const Eigen::Vector2d here = stance_.At(cur_clip_, cur_frame_) + Eigen::Vector2d(offset_(0), offset_(2));
    const Eigen::Vector2d rest = stance_.At(s_.rest.clip, s_.rest.frame);
    offset_ = Eigen::Vector3d(here.x() - rest.x(), 0, here.y() - rest.y());
    cur_clip_ = s_.rest.clip;
    cur_frame_ = s_.rest.frame;
  }
  const bool transition = jumped || inertializer_.active();
  inertializer_.Apply(rest_, out);
  Finish(transition, out);
}

void FrameAssembler::Finish(bool transition, std::span<double> out) {
  // Largest joint angular speed into this frame (as MaxJointAngularSpeedDps).
  double max_cos = 1.0;
  for (size_t j = 0; j < cur_rot_.size(); ++j) {
    const motion::Joint& joint = skel_.joint(static_cast<int>(j));
    if (joint.num_rotations == 0) continue;
    cur_rot_[j] = motion::LocalRotation(joint, out);
    if (frames_out_ > 0) max_cos = std::min(max_cos, ((prev_rot_[j].transpose() * cur_rot_[j]).trace() - 1.0) / 2.0);
  }
  if (frames_out_ > 0) {
    const double s = std::acos(std::clamp(max_cos, -1.0, 1.0)) * (180.0 / std::numbers::pi) * s_.library->frame_rate_hz;
    if (transition) {
      max_transition_dps_ = std::max(max_transition_dps_, s);
    } else {
      max_inside_dps_ = std::max(max_inside_dps_, s);
    }
  }
  std::swap(prev_rot_, cur_rot_);
  std::copy(out.begin(), out.end(), prev_.begin());
  ++frames_out_;
  if (planter_) planter_->Apply(out);
}

}  // namespace kinemo::planner::controller
