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
#include <numbers>

#include <Eigen/Geometry>

#include "common/motion/body_regions.h"
#include "common/motion/kinematics.h"
#include "services/planner/controller/controller_internal.h"
#include "services/planner/library/feet.h"

namespace kinemo::planner::controller {

using internal::kInf;

// ---------------------------------------------------------------------------
// Policy

Policy::Policy(const Controller& controller, double min_play_s)
    : c_(controller),
      alpha_(controller.state_model().initial),
      tmp_(controller.num_states()),
      style_(Eigen::VectorXd::Zero(controller.num_tones())),
      min_play_frames_(std::max(0, static_cast<int>(std::lround(min_play_s / controller.frame_time_s())))) {
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
  return best;
}

Decision Policy::Decide(int e) {
  const SegmentLibrary& L = c_.segments();
  const EndPoint& ep = L.end_points[static_cast<size_t>(e)];
  const auto& sa = L.segments[static_cast<size_t>(ep.segment)];
  const int w = keyword_ + 1;
  const int S = c_.num_states(), M = c_.num_tones();
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
  if (!ep.last) {
    best.expected_cost = dot_row([&](int m) { return c_.Vc(m, w).data() + static_cast<Eigen::Index>(e) * S; });
    best.segment = ep.segment;
    best.start = ep.frame + 1;
    best.end_point = e + 1;
    best.continuation = true;
    if (w > 0 && c_.Matches(ep.segment, w)) best.keyword = keyword_;
    // A young play continues (no pending keyword): see kDefaultMinPlaySeconds.
    if (w == 0 && ep.segment == play_segment_ && ep.frame + 1 - play_start_ < min_play_frames_) return best;
  }
  const float* srow = L.transition.data() + static_cast<size_t>(e) * L.num_segments();
  for (int b : c_.Kept(w, e)) {
    const double v = srow[b] + dot_row([&](int m) { return c_.U(m, w).data() + static_cast<Eigen::Index>(b) * S; });
    if (v < best.expected_cost) {
      best = Decision{};
      best.expected_cost = v;
      best.segment = b;
      best.end_point = L.segments[static_cast<size_t>(b)].first_end;
      best.interrupted = !ep.last;
    }
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
  (void)sa;
  if (best.keyword >= 0) keyword_ = -1;
  if (!best.continuation) {
    play_segment_ = best.segment;
    play_start_ = best.start;
  }
  return best;
}

// ---------------------------------------------------------------------------
// Frame assembly

FrameAssembler::FrameAssembler(const SegmentLibrary& segments, int blend_frames, const motion::FootPlantParams& feet)
    : s_(segments),
      skel_(segments.library->skeleton),
      blend_frames_(std::max(0, blend_frames)),
      stance_(*segments.library) {
  const size_t n = static_cast<size_t>(skel_.num_channels());
  prev_.resize(n);
  prev_rot_.resize(static_cast<size_t>(skel_.num_joints()));
  cur_rot_.resize(prev_rot_.size());
  if (StatusOr<motion::KeyJoints> key = motion::FindKeyJoints(skel_, segments.library->regions); key.ok()) {
    const int ends[] = {key->head, key->left_hand, key->right_hand, key->left_foot, key->right_foot};
    gap_joints_ = motion::JointsWithAncestors(skel_, ends);
  } else {
    for (int j = 0; j < skel_.num_joints(); ++j) gap_joints_.push_back(j);
  }
  hold_.resize(n);
  a_.resize(n);
  b_.resize(n);
  if (feet.enabled) {
    const Library& lib = *segments.library;
    const double dt = lib.frame_rate_hz > 0 ? 1.0 / lib.frame_rate_hz : 1.0 / 30;
    auto planter = [&]() -> StatusOr<std::unique_ptr<motion::FootPlanter>> {
      KINEMO_ASSIGN_OR_RETURN(motion::FootPlantParams p, LibraryFootPlantParams(lib, feet));
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
  const auto src = clip.frame(f);
  std::copy(src.begin(), src.end(), out.begin());
  for (int k : {0, 2})
    if (root.position_column[static_cast<size_t>(k)] >= 0) out[static_cast<size_t>(root.position_column[static_cast<size_t>(k)])] += offset(k);
}

// out = from (w = 0) → to (w = 1), per joint.
void BlendFrames(const motion::Skeleton& skel, std::span<const double> from, std::span<const double> to, double w,
                 std::span<double> out) {
  for (const auto& j : skel.joints()) {
    for (int c = j.first_channel; c < j.first_channel + j.num_channels(); ++c)
      out[static_cast<size_t>(c)] = (1 - w) * from[static_cast<size_t>(c)] + w * to[static_cast<size_t>(c)];
    if (j.num_rotations == 3 && j.has_euler_rotation()) {
      const Eigen::Quaterniond qa(motion::LocalRotation(j, from)), qb(motion::LocalRotation(j, to));
      const Eigen::Matrix3d r = qa.slerp(w, qb).toRotationMatrix();
      Eigen::Vector3d ref;
      for (int k = 0; k < 3; ++k) ref(k) = to[static_cast<size_t>(j.rotation_column[static_cast<size_t>(k)])];
      const Eigen::Vector3d ang = motion::MatrixToEuler(r, j.rotation_axis, ref);
      for (int k = 0; k < 3; ++k) out[static_cast<size_t>(j.rotation_column[static_cast<size_t>(k)])] = ang(k);
    }
  }
}

}  // namespace

void FrameAssembler::Next(int segment, int f, std::span<double> out) {
  const auto& seg = s_.segments[static_cast<size_t>(segment)];
  const auto& clips = s_.library->clips;
  const motion::Joint& root = skel_.joint(0);
  const int c = seg.clip, g = std::min(seg.first_frame + f, clips[static_cast<size_t>(c)].clip.num_frames() - 1);
  bool jumped = false;
  if (frames_out_ > 0 && !(c == cur_clip_ && g == cur_frame_ + 1)) {
    jumped = true;
    ++transitions_;
    const motion::Clip& old = clips[static_cast<size_t>(cur_clip_)].clip;
    // A jump inside a running blend fades from the pose last shown (held).
    hold_source_ = src_clip_ >= 0 && blend_k_ < cur_blend_;
    if (hold_source_) std::copy(prev_.begin(), prev_.end(), hold_.begin());
    src_clip_ = cur_clip_;
    src_frame_ = cur_frame_;
    src_offset_ = offset_;
    // The new segment stands where the old one would have stood next.
    const Eigen::Vector2d next_stance =
        stance_.At(cur_clip_, std::min(cur_frame_ + 1, old.num_frames() - 1)) + Eigen::Vector2d(offset_(0), offset_(2));
    const Eigen::Vector2d new_stance = stance_.At(c, g);
    offset_ = Eigen::Vector3d(next_stance.x() - new_stance.x(), 0, next_stance.y() - new_stance.y());
    blend_k_ = 0;
  }
  CopyFrame(clips[static_cast<size_t>(c)].clip, g, offset_, root, a_);
  if (jumped && blend_frames_ > 0) {
    // Long enough that the fade itself (peak rate 1.5/blend of the largest
    // joint angle between the two poses) stays under 0.4 x the library's
    // 99th-percentile joint speed; at most 4x the nominal length.
    const motion::Clip& old = clips[static_cast<size_t>(src_clip_)].clip;
    if (hold_source_) {
      std::copy(hold_.begin(), hold_.end(), b_.begin());
    } else {
      CopyFrame(old, std::min(src_frame_ + 1, old.num_frames() - 1), src_offset_, root, b_);
    }
    const double dt = 1.0 / s_.library->frame_rate_hz;
    double gap_deg = 0;
    for (int j : gap_joints_) {
      gap_deg = std::max(gap_deg, motion::JointAngularSpeedDps(skel_.joint(j), b_, a_, 1.0));
    }
    const double limit_dps = std::max(30.0, 0.4 * s_.angular_speed_p99_dps);
    const int need = static_cast<int>(std::ceil(1.5 * gap_deg / (limit_dps * dt)));
    cur_blend_ = std::clamp(need, blend_frames_, 4 * blend_frames_);
  }
  const bool blending = src_clip_ >= 0 && blend_k_ < cur_blend_;
  if (blending) {
    const motion::Clip& old = clips[static_cast<size_t>(src_clip_)].clip;
    src_frame_ = std::min(src_frame_ + 1, old.num_frames() - 1);
    if (hold_source_) {
      std::copy(hold_.begin(), hold_.end(), b_.begin());
    } else {
      CopyFrame(old, src_frame_, src_offset_, root, b_);
    }
    const double x = static_cast<double>(blend_k_ + 1) / (cur_blend_ + 1);
    const double w = x * x * (3 - 2 * x);
    BlendFrames(skel_, b_, a_, w, out);
    ++blend_k_;
  } else {
    std::copy(a_.begin(), a_.end(), out.begin());
  }
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
    if (jumped || blending) {
      max_transition_dps_ = std::max(max_transition_dps_, s);
    } else {
      max_inside_dps_ = std::max(max_inside_dps_, s);
    }
  }
  std::swap(prev_rot_, cur_rot_);
  std::copy(out.begin(), out.end(), prev_.begin());
  cur_clip_ = c;
  cur_frame_ = g;
  ++frames_out_;
  if (planter_) planter_->Apply(out);
}

}  // namespace kinemo::planner::controller
