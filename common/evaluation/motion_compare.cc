#include "common/evaluation/motion_compare.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <Eigen/Eigenvalues>

#include "common/motion/body_regions.h"
#include "common/motion/feet.h"
#include "common/motion/kinematics.h"
#include "common/motion/motion_check.h"
#include "common/motion/resample.h"

namespace kinemo::evaluation {
namespace {

// Speeds of a role over frames (forward differences), optionally relative to
// the pelvis: n − 1 values.
std::vector<double> Speeds(const RoleTrack& t, int role, bool relative) {
  std::vector<double> out;
  const int n = t.num_frames();
  for (int f = 0; f + 1 < n; ++f) {
    Eigen::Vector3d d = t.At(f + 1, role) - t.At(f, role);
    if (relative) d -= t.At(f + 1, kPelvis) - t.At(f, kPelvis);
    out.push_back(d.norm() / t.frame_time_s);
  }
  return out;
}

// |k-th difference| / dt^k of a role's world position (k = 2, 3).
std::vector<double> Differences(const RoleTrack& t, int role, int k) {
  std::vector<double> out;
  const int n = t.num_frames();
  const double scale = std::pow(t.frame_time_s, k);
  for (int f = 0; f + k < n; ++f) {
    Eigen::Vector3d d = Eigen::Vector3d::Zero();
    if (k == 2) d = t.At(f + 2, role) - 2 * t.At(f + 1, role) + t.At(f, role);
    if (k == 3) d = t.At(f + 3, role) - 3 * t.At(f + 2, role) + 3 * t.At(f + 1, role) - t.At(f, role);
    out.push_back(d.norm() / scale);
  }
  return out;
}

double Mean(std::span<const double> v) {
  return v.empty() ? 0.0 : std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
}

double StdDev(std::span<const double> v) {
  if (v.size() < 2) return 0;
  const double m = Mean(v);
  double s = 0;
  for (double x : v) s += (x - m) * (x - m);
  return std::sqrt(s / static_cast<double>(v.size()));
}

std::vector<double> Concat(std::vector<double> a, const std::vector<double>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

// Both wrists (or elbows) pooled.
std::vector<double> PairSpeeds(const RoleTrack& t, int left) { return Concat(Speeds(t, left, false), Speeds(t, left + 1, false)); }
std::vector<double> PairDiffs(const RoleTrack& t, int left, int k) {
  return Concat(Differences(t, left, k), Differences(t, left + 1, k));
}

// Beats shifted circularly by 2, 3, ..., 10 s (those shorter than the clip).
template <typename F>
double ChanceLevel(std::span<const double> beats, double duration_s, const F& score) {
  double sum = 0;
  int n = 0;
  for (double shift = 2; shift <= 10 && shift < duration_s - 1; shift += 1) {
    std::vector<double> b;
    for (double x : beats) b.push_back(std::fmod(x + shift, duration_s));
    std::sort(b.begin(), b.end());
    sum += score(b);
    ++n;
  }
  return n > 0 ? sum / n : 0;
}

}  // namespace

double SnapMetersPerUnit(double estimate) {
  if (!(estimate > 0)) return estimate;
  for (double unit : {0.001, 0.01, 0.0254, 0.3048, 1.0}) {
    if (std::abs(std::log(estimate / unit)) < std::log(1.25)) return unit;
  }
  return estimate;
}

StatusOr<RoleTrack> ExtractRoleTrack(const motion::Clip& clip, double meters_per_unit, double fps) {
  if (!(meters_per_unit > 0) || !std::isfinite(meters_per_unit)) {
    return InvalidField("meters_per_unit", meters_per_unit, " must be > 0");
  }
  if (!(fps > 0) || fps > 1000) return InvalidField("fps", fps, " must be in (0, 1000]");
  KINEMO_RETURN_IF_ERROR(clip.Validate());
  const motion::BodyRegionMap regions = motion::MapBodyRegions(clip.skeleton);
  KINEMO_ASSIGN_OR_RETURN(motion::KeyJoints keys, motion::FindKeyJoints(clip.skeleton, regions));
  std::array<int, kNumRoles> joint{};
  joint[kHead] = keys.head;
  joint[kLeftWrist] = keys.left_hand;
  joint[kRightWrist] = keys.right_hand;
  joint[kLeftFoot] = keys.left_foot;
  joint[kRightFoot] = keys.right_foot;
  for (int side = 0; side < 2; ++side) {
    const int wrist = joint[static_cast<size_t>(kLeftWrist + side)];
    const int elbow = clip.skeleton.joint(wrist).parent;
    const int shoulder = elbow >= 0 ? clip.skeleton.joint(elbow).parent : -1;
    if (shoulder < 0) return absl::FailedPreconditionError("skeleton: a hand has no elbow and shoulder above it");
    joint[static_cast<size_t>(kLeftElbow + side)] = elbow;
    joint[static_cast<size_t>(kLeftShoulder + side)] = shoulder;
    const int ankle = joint[static_cast<size_t>(kLeftFoot + side)];
    const int knee = clip.skeleton.joint(ankle).parent;
    const int hip = knee >= 0 ? clip.skeleton.joint(knee).parent : -1;
    if (hip < 0) return absl::FailedPreconditionError("skeleton: a foot has no knee and hip above it");
    joint[static_cast<size_t>(kLeftKnee + side)] = knee;
    joint[static_cast<size_t>(kLeftHip + side)] = hip;
  }
  auto rig = motion::FeetRig::Find(clip.skeleton, regions);
  joint[kPelvis] = rig.ok() ? rig->pelvis : 0;

  motion::Clip resampled;
  const motion::Clip* src = &clip;
  if (std::abs(clip.fps() - fps) > 0.01 * fps) {
    KINEMO_ASSIGN_OR_RETURN(resampled, motion::Resample(clip, fps));
    src = &resampled;
  }
  if (src->num_frames() < 1) return InvalidField("clip", "has no frames");
  KINEMO_ASSIGN_OR_RETURN(Eigen::MatrixXd world, motion::ComputeWorldPositions(*src));
  RoleTrack t;
  t.frame_time_s = src == &clip ? clip.frame_time_s : 1.0 / fps;
  t.p.resize(world.rows(), 3 * kNumRoles);
  for (int r = 0; r < kNumRoles; ++r) t.p.middleCols(3 * r, 3) = world.middleCols(3 * joint[static_cast<size_t>(r)], 3) * meters_per_unit;
  return t;
}

double HellingerDistance(std::span<const double> p, std::span<const double> q) {
  const double sp = std::accumulate(p.begin(), p.end(), 0.0), sq = std::accumulate(q.begin(), q.end(), 0.0);
  if (!(sp > 0) || !(sq > 0) || p.size() != q.size()) return 1.0;
  double bc = 0;
  for (size_t i = 0; i < p.size(); ++i) bc += std::sqrt(p[i] / sp * q[i] / sq);
  return std::sqrt(std::max(0.0, 1 - bc));
}

std::vector<double> Histogram(std::span<const double> values, double width, int bins) {
  std::vector<double> h(static_cast<size_t>(bins) + 1, 0.0);
  for (double v : values) {
    const double k = std::floor(v / width);
    h[static_cast<size_t>(std::clamp(k, 0.0, static_cast<double>(bins)))] += 1;
  }
  return h;
}

double FrechetDistance(const Eigen::VectorXd& mu1, const Eigen::MatrixXd& s1, const Eigen::VectorXd& mu2,
                       const Eigen::MatrixXd& s2) {
  // tr((Σ1 Σ2)^½) = tr((A Σ2 A)^½) with A = Σ1^½ (both symmetric PSD).
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> e1(s1);
  const Eigen::VectorXd l1 = e1.eigenvalues().cwiseMax(0).cwiseSqrt();
  const Eigen::MatrixXd a = e1.eigenvectors() * l1.asDiagonal() * e1.eigenvectors().transpose();
  const Eigen::MatrixXd m = a * s2 * a;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> e2(0.5 * (m + m.transpose()), Eigen::EigenvaluesOnly);
  const double tr_sqrt = e2.eigenvalues().cwiseMax(0).cwiseSqrt().sum();
  return std::max(0.0, (mu1 - mu2).squaredNorm() + s1.trace() + s2.trace() - 2 * tr_sqrt);
}

const std::vector<std::string>& KineticFeatureNames() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n;
    for (const char* j : {"left_wrist", "right_wrist", "left_elbow", "right_elbow"}) {
      for (const char* f : {"speed_mean", "speed_std", "accel_mean", "jerk_mean"}) n.push_back(kinemo::StrCat(j, "_", f));
    }
    for (const char* j : {"left_wrist", "right_wrist"}) {
      for (const char* f : {"height_mean", "height_std", "reach_mean"}) n.push_back(kinemo::StrCat(j, "_", f));
    }
    n.push_back("hands_distance_mean");
    n.push_back("hands_distance_std");
    return n;
  }();
  return names;
}

Eigen::MatrixXd KineticFeatures(const RoleTrack& t, const CompareOptions& o) {
  const int w = std::max(4, static_cast<int>(std::lround(o.window_s / t.frame_time_s)));
  const int hop = std::max(1, static_cast<int>(std::lround(o.hop_s / t.frame_time_s)));
  const int n = t.num_frames();
  const int windows = n >= w ? 1 + (n - w) / hop : 0;
  Eigen::MatrixXd out(windows, static_cast<Eigen::Index>(KineticFeatureNames().size()));
  const double dt = t.frame_time_s;
  // Positions relative to the pelvis.
  auto rel = [&](int f, int role) { return Eigen::Vector3d(t.At(f, role) - t.At(f, kPelvis)); };
  for (int k = 0; k < windows; ++k) {
    const int f0 = k * hop;
    int col = 0;
    for (int role : {kLeftWrist, kRightWrist, kLeftElbow, kRightElbow}) {
      std::vector<double> v, a, j;
      for (int f = f0; f + 1 < f0 + w; ++f) v.push_back((rel(f + 1, role) - rel(f, role)).norm() / dt);
      for (int f = f0; f + 2 < f0 + w; ++f)
        a.push_back((rel(f + 2, role) - 2 * rel(f + 1, role) + rel(f, role)).norm() / (dt * dt));
      for (int f = f0; f + 3 < f0 + w; ++f)
        j.push_back((rel(f + 3, role) - 3 * rel(f + 2, role) + 3 * rel(f + 1, role) - rel(f, role)).norm() /
                    (dt * dt * dt));
      out(k, col++) = Mean(v);
      out(k, col++) = StdDev(v);
      out(k, col++) = Mean(a);
      out(k, col++) = Mean(j);
    }
    for (int role : {kLeftWrist, kRightWrist}) {
      std::vector<double> h, r;
      for (int f = f0; f < f0 + w; ++f) {
        const Eigen::Vector3d x = rel(f, role);
        h.push_back(x.y());
        r.push_back(std::hypot(x.x(), x.z()));
      }
      out(k, col++) = Mean(h);
      out(k, col++) = StdDev(h);
      out(k, col++) = Mean(r);
    }
    std::vector<double> d;
    for (int f = f0; f < f0 + w; ++f) d.push_back((t.At(f, kLeftWrist) - t.At(f, kRightWrist)).norm());
    out(k, col++) = Mean(d);
    out(k, col++) = StdDev(d);
  }
  return out;
}

std::vector<double> KinematicBeats(const RoleTrack& t, const CompareOptions& o) {
  std::vector<double> beats;
  for (int role : {kLeftWrist, kRightWrist}) {
    const std::vector<double> raw = Speeds(t, role, true);
    const int n = static_cast<int>(raw.size());
    std::vector<double> s(raw.size());
    for (int i = 0; i < n; ++i) {
      double sum = 0;
      int c = 0;
      for (int k = std::max(0, i - 1); k <= std::min(n - 1, i + 1); ++k, ++c) sum += raw[static_cast<size_t>(k)];
      s[static_cast<size_t>(i)] = sum / c;
    }
    // Speed sample i lies between frames i and i+1.
    for (int i = 1; i + 1 < n; ++i) {
      const auto u = static_cast<size_t>(i);
      if (!(s[u] >= s[u - 1] && s[u] > s[u + 1] && s[u] >= o.stroke_peak_m_s)) continue;
      int m = i + 1;
      while (m + 1 < n && s[static_cast<size_t>(m + 1)] < s[static_cast<size_t>(m)]) ++m;
      if (m + 1 < n) beats.push_back((m + 0.5) * t.frame_time_s);
    }
  }
  std::sort(beats.begin(), beats.end());
  // One beat for both hands when their apexes are within two frames.
  std::vector<double> out;
  for (double b : beats) {
    if (out.empty() || b - out.back() > 2.5 * t.frame_time_s) out.push_back(b);
  }
  return out;
}

double BeatAlignment(std::span<const double> events, std::span<const double> beats, double sigma_s) {
  if (events.empty() || beats.empty()) return 0;
  double sum = 0;
  for (double e : events) {
    const auto it = std::lower_bound(beats.begin(), beats.end(), e);
    double d = std::numeric_limits<double>::infinity();
    if (it != beats.end()) d = *it - e;
    if (it != beats.begin()) d = std::min(d, e - *(it - 1));
    sum += std::exp(-d * d / (2 * sigma_s * sigma_s));
  }
  return sum / static_cast<double>(events.size());
}

double SyncFraction(std::span<const double> accents, std::span<const double> beats, double min_s, double max_s) {
  if (accents.empty()) return 0;
  int hit = 0;
  for (double a : accents) {
    // accent − b ∈ [min, max]  ⇔  b ∈ [a − max, a − min].
    const auto it = std::lower_bound(beats.begin(), beats.end(), a - max_s - 1e-9);
    hit += it != beats.end() && *it <= a - min_s + 1e-9;
  }
  return static_cast<double>(hit) / static_cast<double>(accents.size());
}

int LongestCopy(const RoleTrack& t, std::span<const RoleTrack> library, double tolerance_m,
                std::vector<int>* run_lengths) {
  const int n = t.num_frames();
  std::vector<int> best(static_cast<size_t>(n), 0);
  const double tol2 = tolerance_m * tolerance_m;
  // Pose of frame f relative to the pelvis (the upper-body roles; foot
  // planting moves the legs).
  using Pose = Eigen::Matrix<double, 3, kNumUpperRoles>;
  auto pose = [](const RoleTrack& r, int f) {
    Pose m;
    for (int k = 0; k < kNumUpperRoles; ++k) m.col(k) = r.At(f, kFirstUpperRole + k) - r.At(f, kPelvis);
    return m;
  };
  std::vector<Pose> gen(static_cast<size_t>(n));
  for (int f = 0; f < n; ++f) gen[static_cast<size_t>(f)] = pose(t, f);
  for (const RoleTrack& lib : library) {
    const int m = lib.num_frames();
    std::vector<Pose> lp(static_cast<size_t>(m));
    for (int g = 0; g < m; ++g) lp[static_cast<size_t>(g)] = pose(lib, g);
    std::vector<int> prev(static_cast<size_t>(m), 0), cur(static_cast<size_t>(m), 0);
    for (int f = 0; f < n; ++f) {
      for (int g = 0; g < m; ++g) {
        const bool match =
            (gen[static_cast<size_t>(f)] - lp[static_cast<size_t>(g)]).colwise().squaredNorm().maxCoeff() <= tol2;
        cur[static_cast<size_t>(g)] = match ? 1 + (g > 0 ? prev[static_cast<size_t>(g - 1)] : 0) : 0;
        best[static_cast<size_t>(f)] = std::max(best[static_cast<size_t>(f)], cur[static_cast<size_t>(g)]);
      }
      prev.swap(cur);
    }
  }
  if (run_lengths) *run_lengths = best;
  return n > 0 ? *std::max_element(best.begin(), best.end()) : 0;
}

ClipMeasures MeasureClip(const RoleTrack& t, const AudioEvents* audio, const CompareOptions& o) {
  ClipMeasures m;
  const int n = t.num_frames();
  m.duration_s = n * t.frame_time_s;
  std::vector<double> speed = PairSpeeds(t, kLeftWrist);
  m.hand_speed_mean_m_s = Mean(speed);
  m.hand_speed_p95_m_s = motion::Quantile(speed, 0.95);
  m.accel_mean_m_s2 = Mean(PairDiffs(t, kLeftWrist, 2));
  m.jerk_mean_m_s3 = Mean(PairDiffs(t, kLeftWrist, 3));
  m.knee_jerk_mean_m_s3 = Mean(PairDiffs(t, kLeftKnee, 3));
  const std::vector<double> ls = Speeds(t, kLeftWrist, true), rs = Speeds(t, kRightWrist, true);
  int moving = 0;
  for (size_t i = 0; i < ls.size(); ++i) moving += std::max(ls[i], rs[i]) > o.moving_speed_m_s;
  m.hands_moving_fraction = ls.empty() ? 0 : static_cast<double>(moving) / static_cast<double>(ls.size());
  int raised = 0;
  double height = 0;
  for (int f = 0; f < n; ++f) {
    bool up = false;
    for (int side = 0; side < 2; ++side) {
      const double wy = t.At(f, kLeftWrist + side).y();
      up = up || wy > t.At(f, kLeftShoulder + side).y() - o.raised_below_shoulder_m;
      height += (wy - t.At(f, kPelvis).y()) / 2;
    }
    raised += up;
  }
  m.hands_raised_fraction = n > 0 ? static_cast<double>(raised) / n : 0;
  m.hand_height_mean_m = n > 0 ? height / n : 0;
  for (int r = 1; r < kNumRoles; ++r) {
    for (double v : Speeds(t, r, false)) m.max_joint_speed_m_s = std::max(m.max_joint_speed_m_s, v);
  }
  m.l1_div = L1Diversity(t);
  m.ankle_lift_share = AnkleLiftShare(t, o.ankle_lift_m);
  const std::vector<double> beats = KinematicBeats(t, o);
  m.kinematic_beats = static_cast<int>(beats.size());
  if (audio != nullptr) {
    // Only the events the motion covers.
    std::vector<double> onsets, accents;
    for (double x : audio->onsets_s)
      if (x <= m.duration_s) onsets.push_back(x);
    for (double x : audio->accents_s)
      if (x <= m.duration_s) accents.push_back(x);
    m.accents = static_cast<int>(accents.size());
    m.kinemo_beat_alignment = BeatAlignment(onsets, beats, o.beat_sigma_s);
    m.kinemo_beat_alignment_chance = ChanceLevel(beats, m.duration_s, [&](const std::vector<double>& b) {
      return BeatAlignment(onsets, b, o.beat_sigma_s);
    });
    m.accent_sync_fraction = SyncFraction(accents, beats, o.sync_min_s, o.sync_max_s);
    m.accent_sync_chance = ChanceLevel(beats, m.duration_s, [&](const std::vector<double>& b) {
      return SyncFraction(accents, b, o.sync_min_s, o.sync_max_s);
    });
  }
  return m;
}

namespace {

// Gaussian fit of the rows of x (np.cov: n − 1).
void FitGaussian(const Eigen::MatrixXd& x, Eigen::VectorXd* mu, Eigen::MatrixXd* cov) {
  *mu = x.colwise().mean().transpose();
  const Eigen::MatrixXd c0 = x.rowwise() - mu->transpose();
  *cov = c0.transpose() * c0 / std::max<double>(1, static_cast<double>(x.rows()) - 1);
}

// AIST++ kinetic features of the fid windows of a track: rows are windows.
Eigen::MatrixXd FidFeatures(const RoleTrack& t, const CompareOptions& o) {
  const int w = std::max(4, static_cast<int>(std::lround(o.fid_window_s / t.frame_time_s)));
  const int hop = std::max(1, static_cast<int>(std::lround(o.fid_hop_s / t.frame_time_s)));
  const int n = t.num_frames();
  const int windows = n >= w ? 1 + (n - w) / hop : 0;
  const std::span<const int> roles = FidRoles();
  Eigen::MatrixXd out(windows, 3 * static_cast<Eigen::Index>(roles.size()));
  for (int k = 0; k < windows; ++k) {
    out.row(k) = AistKineticFeatures(t, k * hop, w, roles, o.kinetic_average_frames).transpose();
  }
  return out;
}

// BEAT/EMAGE motion beats of a track per beat role; `mean_speed` holds the
// roles' mean speeds in the references.
std::vector<std::vector<double>> EmageBeats(const RoleTrack& t, std::span<const double> mean_speed,
                                            const CompareOptions& o) {
  const std::span<const int> roles = BeatRoles();
  std::vector<std::vector<double>> beats;
  for (size_t i = 0; i < roles.size(); ++i) {
    beats.push_back(EmageMotionBeats(t, roles[i], o.bc_order, o.bc_speed_threshold * mean_speed[i]));
  }
  return beats;
}

// The beat consistency: per role, the Gaussian alignment of its beats with
// the onsets; mean over the roles. With `shift_s`, the beats are moved
// circularly by it first (chance level).
double EmageBeatConsistency(const std::vector<std::vector<double>>& beats, std::span<const double> onsets,
                            double duration_s, const CompareOptions& o, double shift_s = 0) {
  double sum = 0;
  for (const std::vector<double>& role_beats : beats) {
    std::vector<double> b = role_beats;
    if (shift_s != 0) {
      for (double& x : b) x = std::fmod(x + shift_s, duration_s);
    }
    sum += GaussianAlignment(b, onsets, o.bc_sigma_s);
  }
  return beats.empty() ? 0 : sum / static_cast<double>(beats.size());
}

// Mean over shifts of 2, 3, ..., 10 s (those shorter than the clip).
double EmageBeatConsistencyChance(const std::vector<std::vector<double>>& beats, std::span<const double> onsets,
                                  double duration_s, const CompareOptions& o) {
  double sum = 0;
  int n = 0;
  for (double shift = 2; shift <= 10 && shift < duration_s - 1; shift += 1) {
    sum += EmageBeatConsistency(beats, onsets, duration_s, o, shift);
    ++n;
  }
  return n > 0 ? sum / n : 0;
}

}  // namespace

StatusOr<Comparison> Compare(const RoleTrack& generated, std::span<const RoleTrack> references,
                             const AudioEvents* audio, std::span<const RoleTrack> library, const CompareOptions& o) {
  if (references.empty()) return InvalidField("references", "at least one is needed");
  const double min_s = o.window_s + 4 * generated.frame_time_s;
  if (generated.num_frames() * generated.frame_time_s < min_s) {
    return InvalidField("generated", "shorter than ", min_s, " s");
  }
  Comparison c;
  c.has_audio = audio != nullptr;
  c.generated = MeasureClip(generated, audio, o);
  // References: pooled samples, frame-weighted means of their own measures.
  std::vector<double> rs, ra, res, rea;
  std::vector<Eigen::MatrixXd> rf, rk;
  Eigen::Index rows = 0, fid_rows = 0;
  double total_s = 0;
  const std::array<int, 2> wrists = {kLeftWrist, kRightWrist};
  std::vector<double> genea_rs, genea_ra;
  const std::span<const int> beat_roles = BeatRoles();
  std::vector<double> mean_speed(beat_roles.size(), 0.0);
  for (size_t i = 0; i < references.size(); ++i) {
    const RoleTrack& r = references[i];
    if (r.num_frames() * r.frame_time_s < min_s) {
      return InvalidField(kinemo::StrCat("references[", i, "]"), "shorter than ", min_s, " s");
    }
    for (double v : PairSpeeds(r, kLeftWrist)) rs.push_back(v);
    for (double v : PairDiffs(r, kLeftWrist, 2)) ra.push_back(v);
    for (double v : PairSpeeds(r, kLeftElbow)) res.push_back(v);
    for (double v : PairDiffs(r, kLeftElbow, 2)) rea.push_back(v);
    auto add = [](std::vector<double>* sum, const std::vector<double>& h) {
      if (sum->empty()) sum->assign(h.size(), 0.0);
      for (size_t k = 0; k < h.size(); ++k) (*sum)[k] += h[k];
    };
    add(&genea_rs, GeneaHistogram(r, wrists, 1, o.genea_bin_cm, o.genea_max_cm));
    add(&genea_ra, GeneaHistogram(r, wrists, 2, o.genea_bin_cm, o.genea_max_cm));
    rf.push_back(KineticFeatures(r, o));
    rows += rf.back().rows();
    rk.push_back(FidFeatures(r, o));
    fid_rows += rk.back().rows();
    const ClipMeasures m = MeasureClip(r, audio, o);
    const double w = m.duration_s;
    total_s += w;
    for (size_t k = 0; k < beat_roles.size(); ++k) mean_speed[k] += w * MeanSpeed(r, beat_roles[k]);
    ClipMeasures& a = c.reference;
    a.duration_s += w;
    a.jerk_mean_m_s3 += w * m.jerk_mean_m_s3;
    a.knee_jerk_mean_m_s3 += w * m.knee_jerk_mean_m_s3;
    a.accel_mean_m_s2 += w * m.accel_mean_m_s2;
    a.hand_speed_mean_m_s += w * m.hand_speed_mean_m_s;
    a.hand_speed_p95_m_s += w * m.hand_speed_p95_m_s;
    a.hands_moving_fraction += w * m.hands_moving_fraction;
    a.hands_raised_fraction += w * m.hands_raised_fraction;
    a.hand_height_mean_m += w * m.hand_height_mean_m;
    a.max_joint_speed_m_s = std::max(a.max_joint_speed_m_s, m.max_joint_speed_m_s);
    a.kinematic_beats += m.kinematic_beats;
    a.l1_div += w * m.l1_div;
    a.ankle_lift_share += w * m.ankle_lift_share;
    a.kinemo_beat_alignment += w * m.kinemo_beat_alignment;
    a.kinemo_beat_alignment_chance += w * m.kinemo_beat_alignment_chance;
    a.accent_sync_fraction += w * m.accent_sync_fraction;
    a.accent_sync_chance += w * m.accent_sync_chance;
    a.accents += m.accents;
  }
  for (double* v : {&c.reference.jerk_mean_m_s3, &c.reference.knee_jerk_mean_m_s3, &c.reference.accel_mean_m_s2, &c.reference.hand_speed_mean_m_s,
                    &c.reference.hand_speed_p95_m_s, &c.reference.hands_moving_fraction,
                    &c.reference.hands_raised_fraction, &c.reference.hand_height_mean_m, &c.reference.l1_div,
                    &c.reference.ankle_lift_share, &c.reference.kinemo_beat_alignment,
                    &c.reference.kinemo_beat_alignment_chance, &c.reference.accent_sync_fraction,
                    &c.reference.accent_sync_chance}) {
    *v /= total_s;
  }
  for (double& v : mean_speed) v /= total_s;
  auto hd = [](const std::vector<double>& a, const std::vector<double>& b, double width, int bins) {
    const std::vector<double> ha = Histogram(a, width, bins), hb = Histogram(b, width, bins);
    return HellingerDistance(ha, hb);
  };
  c.hellinger_speed = hd(PairSpeeds(generated, kLeftWrist), rs, o.speed_bin_m_s, o.speed_bins);
  c.hellinger_accel = hd(PairDiffs(generated, kLeftWrist, 2), ra, o.accel_bin_m_s2, o.accel_bins);
  c.hellinger_speed_elbows = hd(PairSpeeds(generated, kLeftElbow), res, o.speed_bin_m_s, o.speed_bins);
  c.hellinger_accel_elbows = hd(PairDiffs(generated, kLeftElbow, 2), rea, o.accel_bin_m_s2, o.accel_bins);
  c.genea_hellinger_speed =
      HellingerDistance(GeneaHistogram(generated, wrists, 1, o.genea_bin_cm, o.genea_max_cm), genea_rs);
  c.genea_hellinger_accel =
      HellingerDistance(GeneaHistogram(generated, wrists, 2, o.genea_bin_cm, o.genea_max_cm), genea_ra);

  // Kinetic features, z-scored by the references.
  auto stack = [](const std::vector<Eigen::MatrixXd>& parts, Eigen::Index n) {
    Eigen::MatrixXd all(n, parts.empty() ? 0 : parts[0].cols());
    Eigen::Index at = 0;
    for (const auto& m : parts) {
      all.middleRows(at, m.rows()) = m;
      at += m.rows();
    }
    return all;
  };
  {
    const Eigen::MatrixXd ref = stack(rf, rows);
    const Eigen::MatrixXd gen = KineticFeatures(generated, o);
    const Eigen::RowVectorXd mean = ref.colwise().mean();
    Eigen::RowVectorXd sd = ((ref.rowwise() - mean).array().square().colwise().sum() / static_cast<double>(rows)).sqrt();
    sd = sd.cwiseMax(1e-3);
    auto z = [&](const Eigen::MatrixXd& x) -> Eigen::MatrixXd {
      return (x.rowwise() - mean).array().rowwise() / sd.array();
    };
    Eigen::VectorXd mg, mr;
    Eigen::MatrixXd sg, sr;
    FitGaussian(z(gen), &mg, &sg);
    FitGaussian(z(ref), &mr, &sr);
    c.fd_kinetic = FrechetDistance(mg, sg, mr, sr);
    c.windows = static_cast<int>(gen.rows());
    c.reference_windows = static_cast<int>(rows);
  }
  {
    // FID_k. Bailando's normalize(gt, pred) z-scores both by the references'
    // mean and (population) standard deviation + 1e-10 (fid_k_bailando);
    // fid_k z-scores by the windows of both clips pooled (docs/evaluation.md:
    // a standing reference barely varies in some features).
    const Eigen::MatrixXd ref = stack(rk, fid_rows);
    const Eigen::MatrixXd gen = FidFeatures(generated, o);
    auto fd = [&](const Eigen::MatrixXd& norm) {
      const Eigen::RowVectorXd mean = norm.colwise().mean();
      const Eigen::RowVectorXd sd =
          ((norm.rowwise() - mean).array().square().colwise().sum() / static_cast<double>(norm.rows())).sqrt() +
          1e-10;
      auto z = [&](const Eigen::MatrixXd& x) -> Eigen::MatrixXd {
        return (x.rowwise() - mean).array().rowwise() / sd.array();
      };
      Eigen::VectorXd mg, mr;
      Eigen::MatrixXd sg, sr;
      FitGaussian(z(gen), &mg, &sg);
      FitGaussian(z(ref), &mr, &sr);
      return FrechetDistance(mg, sg, mr, sr);
    };
    Eigen::MatrixXd pooled(ref.rows() + gen.rows(), ref.cols());
    pooled << ref, gen;
    // A Gaussian needs two windows of each (clips of 3 s).
    const bool enough = gen.rows() >= 2 && ref.rows() >= 2;
    c.fid_k = enough ? fd(pooled) : std::numeric_limits<double>::quiet_NaN();
    c.fid_k_bailando = enough ? fd(ref) : std::numeric_limits<double>::quiet_NaN();
    c.fid_windows = static_cast<int>(gen.rows());
    c.fid_reference_windows = static_cast<int>(fid_rows);
  }

  if (audio != nullptr) {
    std::vector<double> onsets;
    for (double x : audio->audio_onsets_s) {
      if (x <= c.generated.duration_s) onsets.push_back(x);
    }
    c.audio_onsets = static_cast<int>(onsets.size());
    const auto beats = EmageBeats(generated, mean_speed, o);
    c.beat_consistency = EmageBeatConsistency(beats, onsets, c.generated.duration_s, o);
    c.beat_consistency_chance = EmageBeatConsistencyChance(beats, onsets, c.generated.duration_s, o);
    double w_sum = 0;
    for (const RoleTrack& r : references) {
      const double d = r.num_frames() * r.frame_time_s;
      std::vector<double> ro;
      for (double x : audio->audio_onsets_s) {
        if (x <= d) ro.push_back(x);
      }
      const auto rb = EmageBeats(r, mean_speed, o);
      c.reference_beat_consistency += d * EmageBeatConsistency(rb, ro, d, o);
      c.reference_beat_consistency_chance += d * EmageBeatConsistencyChance(rb, ro, d, o);
      w_sum += d;
    }
    c.reference_beat_consistency /= w_sum;
    c.reference_beat_consistency_chance /= w_sum;
  }
  const std::vector<double> gen_envelope = HandSpeedEnvelope(generated, o.envelope_s);
  const std::vector<double> ref_envelope = HandSpeedEnvelope(references[0], o.envelope_s);
  c.envelope_correlation = PearsonCorrelation(gen_envelope, ref_envelope);
  if (audio != nullptr && !audio->loudness_db.empty()) {
    c.speech_envelope_correlation = PearsonCorrelation(gen_envelope, audio->loudness_db);
    c.reference_speech_envelope_correlation = PearsonCorrelation(ref_envelope, audio->loudness_db);
  }

  if (!library.empty()) {
    c.has_library = true;
    std::vector<int> runs;
    const int longest = LongestCopy(generated, library, o.copy_tolerance_m, &runs);
    c.longest_copy_s = longest * generated.frame_time_s;
    c.longest_copy_fraction = static_cast<double>(longest) / generated.num_frames();
    // Frames inside runs of at least copy_min_run_s (walk back from each run's end).
    const int min_run = static_cast<int>(std::ceil(o.copy_min_run_s / generated.frame_time_s));
    std::vector<bool> copied(runs.size(), false);
    for (int f = static_cast<int>(runs.size()) - 1; f >= 0; --f) {
      const int len = runs[static_cast<size_t>(f)];
      if (len >= min_run && (f + 1 == static_cast<int>(runs.size()) || runs[static_cast<size_t>(f + 1)] != len + 1)) {
        for (int k = f - len + 1; k <= f; ++k) copied[static_cast<size_t>(k)] = true;
      }
    }
    c.copied_fraction =
        static_cast<double>(std::count(copied.begin(), copied.end(), true)) / static_cast<double>(copied.size());
    c.copy_frame_fraction = static_cast<double>(std::count_if(runs.begin(), runs.end(), [](int r) { return r > 0; })) /
                            static_cast<double>(runs.size());
    const int min_frames = static_cast<int>(std::lround(o.near_copy_min_s / generated.frame_time_s));
    const int gap = std::max(1, static_cast<int>(std::lround(o.repeat_gap_s / generated.frame_time_s)));
    const NearCopyResult near =
        NearCopies(generated, library, o.near_copy_tolerance_m, o.near_copy_max_step, min_frames, gap);
    c.longest_near_copy_s = near.longest * generated.frame_time_s;
    c.near_copy_share_over_2s = static_cast<double>(near.frames_in_long_runs) / generated.num_frames();
    c.library_repeat_share = static_cast<double>(near.frames_repeated) / generated.num_frames();
  }
  return c;
}

}  // namespace kinemo::evaluation
