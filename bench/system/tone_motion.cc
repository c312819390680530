#include "bench/system/tone_motion.h"

#include <cmath>

#include "common/evaluation/motion_compare.h"
#include "services/planner/library/library.h"

namespace kinemo::coordinator {
namespace {

namespace ev = ::kinemo::evaluation;

StatusOr<ev::RoleTrack> Track(const motion::Clip& clip) {
  return ev::ExtractRoleTrack(clip, ev::SnapMetersPerUnit(planner::EstimateMetersPerUnit(clip.skeleton)));
}

}  // namespace

StatusOr<ToneMotion> MeasureToneMotion(const motion::Clip& clip, const motion::Clip* neutral) {
  KINEMO_ASSIGN_OR_RETURN(ev::RoleTrack t, Track(clip));
  ToneMotion out;
  const ev::ClipMeasures m = ev::MeasureClip(t, nullptr);
  out.hand_speed_mean_m_s = m.hand_speed_mean_m_s;
  out.hand_speed_p95_m_s = m.hand_speed_p95_m_s;
  const int n = t.num_frames();
  double sum = 0;
  for (int role : {ev::kLeftWrist, ev::kRightWrist}) {
    Eigen::MatrixXd rel(n, 3);
    for (int f = 0; f < n; ++f) rel.row(f) = (t.At(f, role) - t.At(f, ev::kPelvis)).transpose();
    const Eigen::RowVector3d mean = rel.colwise().mean();
    sum += (rel.rowwise() - mean).rowwise().squaredNorm().sum();
  }
  out.amplitude_m = n > 0 ? std::sqrt(sum / (2.0 * n)) : 0.0;
  if (neutral != nullptr) {
    KINEMO_ASSIGN_OR_RETURN(ev::RoleTrack r, Track(*neutral));
    const std::vector<ev::RoleTrack> refs = {r};
    KINEMO_ASSIGN_OR_RETURN(ev::Comparison c, ev::Compare(t, refs, nullptr, {}));
    out.hellinger_speed_to_neutral = c.hellinger_speed;
  }
  return out;
}

}  // namespace kinemo::coordinator
