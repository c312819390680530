// The published measures of motion_compare.h (GENEA, AIST++, BEAT/EMAGE),
// the near-copy detector and the ankle lift: their definitions and sources
// are in docs/evaluation.md.
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "common/evaluation/motion_compare.h"

namespace kinemo::evaluation {
namespace {

constexpr std::array<int, kNumRoles> kAllRoles = {kPelvis,    kHead,      kLeftShoulder, kRightShoulder, kLeftElbow,
                                                  kRightElbow, kLeftWrist, kRightWrist,   kLeftFoot,      kRightFoot,
                                                  kLeftKnee,  kRightKnee, kLeftHip,      kRightHip};
constexpr std::array<int, 7> kUpperRoles = {kHead,      kLeftShoulder, kRightShoulder, kLeftElbow,
                                            kRightElbow, kLeftWrist,    kRightWrist};
static_assert(kUpperRoles.size() == kNumUpperRoles);

// Central-difference speeds of a role (forward at the first frame, backward
// at the last), m/s: EMAGE's velocity.
std::vector<double> CentralSpeeds(const RoleTrack& t, int role) {
  const int n = t.num_frames();
  std::vector<double> v(static_cast<size_t>(std::max(n, 0)), 0.0);
  if (n < 2) return v;
  const double dt = t.frame_time_s;
  v[0] = (t.At(1, role) - t.At(0, role)).norm() / dt;
  for (int f = 1; f + 1 < n; ++f) v[static_cast<size_t>(f)] = (t.At(f + 1, role) - t.At(f - 1, role)).norm() / (2 * dt);
  v[static_cast<size_t>(n - 1)] = (t.At(n - 1, role) - t.At(n - 2, role)).norm() / dt;
  return v;
}

// Upper-body pose of frame f relative to the pelvis, turned about the
// vertical so that the hips (left minus right) point along +x.
using UpperPose = Eigen::Matrix<double, 3, kNumUpperRoles>;
UpperPose PoseOf(const RoleTrack& t, int f) {
  const Eigen::Vector3d pelvis = t.At(f, kPelvis);
  const Eigen::Vector3d hips = t.At(f, kLeftHip) - t.At(f, kRightHip);
  const double h = std::hypot(hips.x(), hips.z());
  const double c = h > 1e-6 ? hips.x() / h : 1, s = h > 1e-6 ? hips.z() / h : 0;
  UpperPose m;
  for (int k = 0; k < kNumUpperRoles; ++k) {
    const Eigen::Vector3d d = t.At(f, kUpperRoles[static_cast<size_t>(k)]) - pelvis;
    m.col(k) = Eigen::Vector3d(c * d.x() + s * d.z(), d.y(), -s * d.x() + c * d.z());
  }
  return m;
}

}  // namespace

std::vector<double> GeneaHistogram(const RoleTrack& t, std::span<const int> roles, int k, double bin_cm,
                                   double max_cm) {
  // numpy.arange(0, max + bin, bin): edges 0, bin, ..., the last ≤ max + bin
  // (within rounding); numpy.histogram puts a value equal to the last edge
  // in the last bin and drops values beyond.
  const int bins = std::max(1, static_cast<int>(std::floor(max_cm / bin_cm + 1e-9)));
  const double last_edge = bins * bin_cm;
  std::vector<double> h(static_cast<size_t>(bins), 0.0);
  const int n = t.num_frames();
  for (int role : roles) {
    for (int f = 0; f + k < n; ++f) {
      Eigen::Vector3d d = k == 1 ? Eigen::Vector3d(t.At(f + 1, role) - t.At(f, role))
                                 : Eigen::Vector3d(t.At(f + 2, role) - 2 * t.At(f + 1, role) + t.At(f, role));
      const double v = 100 * d.norm();  // cm
      if (v > last_edge) continue;
      const int b = std::min(bins - 1, static_cast<int>(std::floor(v / bin_cm)));
      h[static_cast<size_t>(b)] += 1;
    }
  }
  return h;
}

std::span<const int> FidRoles() { return kAllRoles; }
std::span<const int> BeatRoles() { return kUpperRoles; }

Eigen::VectorXd AistKineticFeatures(const RoleTrack& t, int first, int count, std::span<const int> roles,
                                    int w) {
  Eigen::VectorXd out = Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(roles.size()));
  if (count < 2 || first < 0 || first + count > t.num_frames()) return out;
  const double dt = t.frame_time_s;
  auto p = [&](int i, int role) { return t.At(first + i, role); };
  Eigen::Index col = 0;
  for (int role : roles) {
    double kh = 0, kv = 0, ee = 0;
    // fairmotion: for i in 1..count-1, velocities averaged over the forward
    // differences i+j for j in [-w, w] that exist, accelerations over the
    // second differences centred on i+j that exist.
    for (int i = 1; i < count; ++i) {
      Eigen::Vector3d v = Eigen::Vector3d::Zero();
      int nv = 0;
      for (int j = -w; j <= w; ++j) {
        if (i + j - 1 < 0 || i + j >= count) continue;
        v += p(i + j, role) - p(i + j - 1, role);
        ++nv;
      }
      if (nv > 0) {
        v /= nv * dt;
        kh += v.x() * v.x() + v.z() * v.z();
        kv += v.y() * v.y();
      }
      Eigen::Vector3d a = Eigen::Vector3d::Zero();
      int na = 0;
      for (int j = -w; j <= w; ++j) {
        if (i + j - 1 < 0 || i + j + 1 >= count) continue;
        a += (p(i + j + 1, role) - 2 * p(i + j, role) + p(i + j - 1, role)) / (dt * dt);
        ++na;
      }
      if (na > 0) ee += (a / na).norm();
    }
    const double m = count - 1.0;
    out(col++) = kh / m;
    out(col++) = kv / m;
    out(col++) = ee / m;
  }
  return out;
}

double MeanSpeed(const RoleTrack& t, int role) {
  const std::vector<double> v = CentralSpeeds(t, role);
  return v.empty() ? 0 : std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
}

std::vector<double> EmageMotionBeats(const RoleTrack& t, int role, int order, double threshold_m_s) {
  const std::vector<double> v = CentralSpeeds(t, role);
  const int n = static_cast<int>(v.size());
  std::vector<double> beats;
  auto at = [&](int i) { return v[static_cast<size_t>(std::clamp(i, 0, n - 1))]; };  // scipy's mode="clip"
  for (int i = 0; i < n; ++i) {
    bool minimum = true;
    for (int s = 1; s <= order && minimum; ++s) minimum = at(i) < at(i + s) && at(i) < at(i - s);
    if (minimum && v[static_cast<size_t>(i)] > threshold_m_s) beats.push_back(i * t.frame_time_s);
  }
  return beats;
}

double GaussianAlignment(std::span<const double> beats, std::span<const double> onsets, double sigma_s) {
  if (beats.empty() || onsets.empty()) return 0;
  std::vector<double> sorted(beats.begin(), beats.end());
  std::sort(sorted.begin(), sorted.end());
  double sum = 0;
  for (double o : onsets) {
    const auto it = std::lower_bound(sorted.begin(), sorted.end(), o);
    double d = std::numeric_limits<double>::infinity();
    if (it != sorted.end()) d = *it - o;
    if (it != sorted.begin()) d = std::min(d, o - *(it - 1));
    sum += std::exp(-d * d / (2 * sigma_s * sigma_s));
  }
  return sum / static_cast<double>(onsets.size());
}

double L1Diversity(const RoleTrack& t) {
  const int n = t.num_frames();
  if (n < 1) return 0;
  Eigen::MatrixXd rel(n, 3 * kNumRoles);
  for (int r = 0; r < kNumRoles; ++r) {
    rel.middleCols(3 * r, 3) = t.p.middleCols(3 * r, 3) - t.p.middleCols(3 * kPelvis, 3);
  }
  const Eigen::RowVectorXd mean = rel.colwise().mean();
  return (rel.rowwise() - mean).cwiseAbs().sum() / n;
}

double AnkleLiftShare(const RoleTrack& t, double lift_m) {
  const int n = t.num_frames();
  if (n < 1) return 0;
  double low[2] = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
  for (int f = 0; f < n; ++f) {
    for (int s = 0; s < 2; ++s) low[s] = std::min(low[s], t.At(f, kLeftFoot + s).y());
  }
  int lifted = 0;
  for (int f = 0; f < n; ++f) {
    lifted += t.At(f, kLeftFoot).y() > low[0] + lift_m || t.At(f, kRightFoot).y() > low[1] + lift_m;
  }
  return static_cast<double>(lifted) / n;
}

std::vector<double> HandSpeedEnvelope(const RoleTrack& t, double bin_s) {
  const int bin = std::max(1, static_cast<int>(std::lround(bin_s / t.frame_time_s)));
  const int n = t.num_frames();
  std::vector<double> out;
  // Speed sample f lies between frames f and f + 1.
  for (int b0 = 0; b0 + bin < n; b0 += bin) {
    double sum = 0;
    for (int f = b0; f < b0 + bin; ++f) {
      const Eigen::Vector3d dp = t.At(f + 1, kPelvis) - t.At(f, kPelvis);
      for (int role : {kLeftWrist, kRightWrist}) sum += (t.At(f + 1, role) - t.At(f, role) - dp).norm() / t.frame_time_s;
    }
    out.push_back(sum / (2 * bin));
  }
  return out;
}

std::vector<double> LoudnessEnvelope(std::span<const float> samples, int sr, double bin_s) {
  std::vector<double> out;
  const auto bin = static_cast<size_t>(std::max(1L, std::lround(bin_s * sr)));
  for (size_t b0 = 0; b0 + bin <= samples.size(); b0 += bin) {
    double e = 0;
    for (size_t i = b0; i < b0 + bin; ++i) e += static_cast<double>(samples[i]) * samples[i];
    out.push_back(std::sqrt(e / static_cast<double>(bin)));
  }
  const double top = out.empty() ? 0 : *std::max_element(out.begin(), out.end());
  for (double& v : out) v = 20 * std::log10(std::max(v, std::max(top, 1e-12) * 1e-3));
  return out;
}

double PearsonCorrelation(std::span<const double> a, std::span<const double> b) {
  const size_t n = std::min(a.size(), b.size());
  if (n < 3) return 0;
  double ma = 0, mb = 0;
  for (size_t i = 0; i < n; ++i) {
    ma += a[i];
    mb += b[i];
  }
  ma /= static_cast<double>(n);
  mb /= static_cast<double>(n);
  double sab = 0, saa = 0, sbb = 0;
  for (size_t i = 0; i < n; ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  if (!(saa > 0) || !(sbb > 0)) return 0;
  return sab / std::sqrt(saa * sbb);
}

NearCopyResult NearCopies(const RoleTrack& track, std::span<const RoleTrack> library, double tol, int max_step,
                          int min_frames, int repeat_gap) {
  NearCopyResult r;
  const int n = track.num_frames();
  r.run_lengths.assign(static_cast<size_t>(std::max(n, 0)), 0);
  if (n == 0 || library.empty()) return r;
  std::vector<UpperPose> out(static_cast<size_t>(n));
  std::vector<Eigen::Vector3d> out_centroid(static_cast<size_t>(n));
  for (int f = 0; f < n; ++f) {
    out[static_cast<size_t>(f)] = PoseOf(track, f);
    out_centroid[static_cast<size_t>(f)] = out[static_cast<size_t>(f)].rowwise().mean();
  }
  // Library frames of all clips in one array; a run never crosses a clip.
  std::vector<UpperPose> lib;
  std::vector<Eigen::Vector3d> lib_centroid;
  std::vector<int> clip_of;
  for (size_t c = 0; c < library.size(); ++c) {
    for (int g = 0; g < library[c].num_frames(); ++g) {
      lib.push_back(PoseOf(library[c], g));
      lib_centroid.push_back(lib.back().rowwise().mean());
      clip_of.push_back(static_cast<int>(c));
    }
  }
  const int m = static_cast<int>(lib.size());
  const double sum_tol = tol * kNumUpperRoles;
  std::vector<int> prev(static_cast<size_t>(m), 0), cur(static_cast<size_t>(m), 0);
  // Repeats: per library frame the last output frame that played it, whether
  // its current showing is a repeat, and per run the library frame it
  // started at.
  std::vector<int> last_use(static_cast<size_t>(m), -1), run_from(static_cast<size_t>(m), 0), run_from_prev(static_cast<size_t>(m), 0);
  std::vector<char> again(static_cast<size_t>(m), 0);
  const int repeat_run = std::max(2, repeat_gap / 2);
  for (int f = 0; f < n; ++f) {
    bool repeated = false;
    const UpperPose& a = out[static_cast<size_t>(f)];
    const Eigen::Vector3d& ca = out_centroid[static_cast<size_t>(f)];
    int best = 0;
    for (int g = 0; g < m; ++g) {
      const auto ug = static_cast<size_t>(g);
      cur[ug] = 0;
      // The mean of the joint errors is at least the distance between the
      // centroids (triangle inequality): a cheap test first.
      if ((ca - lib_centroid[ug]).squaredNorm() > tol * tol) continue;
      double sum = 0;
      for (int k = 0; k < kNumUpperRoles && sum <= sum_tol; ++k) sum += (a.col(k) - lib[ug].col(k)).norm();
      if (sum > sum_tol) continue;
      ++r.candidate_pairs;
      int before = 0, from = g;
      for (int s = 0; s <= max_step && g - s >= 0; ++s) {
        if (clip_of[static_cast<size_t>(g - s)] != clip_of[ug]) break;
        if (prev[static_cast<size_t>(g - s)] > before) {
          before = prev[static_cast<size_t>(g - s)];
          from = run_from_prev[static_cast<size_t>(g - s)];
        }
      }
      cur[ug] = before + 1;
      run_from[ug] = from;
      best = std::max(best, cur[ug]);
      // Played: inside a run of repeat_gap / 2 frames or more that plays the
      // library on (at least half a library frame per output frame, not a
      // held pose). A showing of g is its plays less than repeat_gap apart;
      // a showing that follows an earlier one is a repeat.
      if (cur[ug] >= repeat_run && 2 * (g - from) >= cur[ug]) {
        if (last_use[ug] < 0) {
          again[ug] = 0;
        } else if (f - last_use[ug] >= repeat_gap) {
          again[ug] = 1;
        }
        last_use[ug] = f;
        if (again[ug]) repeated = true;
      }
    }
    r.run_lengths[static_cast<size_t>(f)] = best;
    r.frames_repeated += repeated;
    prev.swap(cur);
    run_from_prev.swap(run_from);
  }
  r.longest = *std::max_element(r.run_lengths.begin(), r.run_lengths.end());
  // A frame is inside a long run iff some long run ends at or after it and
  // starts at or before it; the longest run ending at each frame covers
  // every run ending there.
  int start = n;
  for (int f = n - 1; f >= 0; --f) {
    const int len = r.run_lengths[static_cast<size_t>(f)];
    if (len > min_frames) start = std::min(start, f - len + 1);
    r.frames_in_long_runs += start <= f;
  }
  return r;
}

}  // namespace kinemo::evaluation
