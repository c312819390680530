#include "common/motion/motion_check.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "common/motion/kinematics.h"

namespace kinemo::motion {

double Quantile(std::vector<double>& values, double q) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const double x = std::clamp(q, 0.0, 1.0) * static_cast<double>(values.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(x));
  const size_t hi = std::min(values.size() - 1, lo + 1);
  return values[lo] + (x - static_cast<double>(lo)) * (values[hi] - values[lo]);
}

StatusOr<JointSpeedLimits> BuildJointSpeedLimits(std::span<const Clip* const> clips, double quantile) {
  if (!(quantile > 0 && quantile <= 1)) return InvalidField("quantile", quantile, " must be in (0, 1]");
  if (clips.empty()) return InvalidField("reference", "no clips");
  JointSpeedLimits out;
  out.quantile = quantile;
  std::unordered_map<std::string, size_t> index;
  std::vector<std::vector<double>> speeds;
  for (const Clip* clip : clips) {
    KINEMO_RETURN_IF_ERROR(clip->Validate());
    const Skeleton& sk = clip->skeleton;
    for (int j = 0; j < sk.num_joints(); ++j) {
      const Joint& joint = sk.joint(j);
      if (joint.num_rotations == 0) continue;
      auto [it, added] = index.emplace(joint.name, speeds.size());
      if (added) speeds.emplace_back();
      std::vector<double>& v = speeds[it->second];
      for (int f = 1; f < clip->num_frames(); ++f) {
        v.push_back(JointAngularSpeedDps(joint, clip->frame(f - 1), clip->frame(f), clip->frame_time_s));
      }
    }
    ++out.clips;
  }
  for (const auto& [name, i] : index) {
    if (speeds[i].empty()) continue;
    out.joints.push_back(name);
    out.limit_dps.push_back(Quantile(speeds[i], quantile));
  }
  if (out.joints.empty()) return InvalidField("reference", "no clip has two frames of a rotating joint");
  return out;
}

StatusOr<MotionCheck> CheckMotion(const Clip& clip, const BodyRegionMap& regions, const MotionCheckParams& params,
                                  const JointSpeedLimits* reference) {
  KINEMO_RETURN_IF_ERROR(clip.Validate());
  if (!std::isfinite(params.floor_height_m)) return InvalidField("floor_height_m", "must be finite");
  KINEMO_RETURN_IF_ERROR(ValidateFootContactParams(params.contact));
  KINEMO_ASSIGN_OR_RETURN(FeetRig rig, FeetRig::Find(clip.skeleton, regions));
  FootContactParams contact = params.contact;
  if (params.estimate_ground) {
    const Clip* one[] = {&clip};
    KINEMO_ASSIGN_OR_RETURN(contact.ground_height_m,
                            EstimateGroundHeight(one, rig, contact.meters_per_unit, clip.num_frames()));
  }
  KINEMO_ASSIGN_OR_RETURN(FeetTrack t, AnalyzeFeet(clip, rig, contact));
  MotionCheck m;
  m.num_frames = clip.num_frames();
  m.duration_s = clip.duration_s();
  m.meters_per_unit = contact.meters_per_unit;
  m.ground_height_m = contact.ground_height_m;
  std::vector<double> slide, ankle, toe;
  int contacts = 0;
  m.min_foot_height_m = INFINITY;
  m.max_float_m = -INFINITY;
  for (int f = 0; f < t.num_frames; ++f) {
    const size_t uf = static_cast<size_t>(f);
    double lowest_contact = INFINITY;
    for (size_t i = 0; i < 2; ++i) {
      const double h = t.sole_height_m[i][uf] - params.floor_height_m;
      m.min_foot_height_m = std::min(m.min_foot_height_m, h);
      if (!t.contact[i][uf]) continue;
      ++contacts;
      lowest_contact = std::min(lowest_contact, h);
      if (f > 0 && t.contact[i][uf - 1]) {
        slide.push_back(t.slide_m_s[i][uf]);
        ankle.push_back(t.ankle_speed_m_s[i][uf]);
        toe.push_back(t.toe_speed_m_s[i][uf]);
      }
    }
    if (std::isfinite(lowest_contact)) m.max_float_m = std::max(m.max_float_m, lowest_contact);
    if (f > 0) m.hips_path_m += (t.pelvis_xz_m[uf] - t.pelvis_xz_m[uf - 1]).norm();
  }
  if (!std::isfinite(m.max_float_m)) m.max_float_m = 0;
  if (t.num_frames > 0) m.hips_drift_m = (t.pelvis_xz_m.back() - t.pelvis_xz_m.front()).norm();
  m.contact_fraction = t.num_frames > 0 ? contacts / (2.0 * t.num_frames) : 0.0;
  m.contact_samples = static_cast<int>(slide.size());
  m.foot_slide_max_m_s = slide.empty() ? 0.0 : *std::max_element(slide.begin(), slide.end());
  m.foot_slide_p95_m_s = Quantile(slide, 0.95);
  m.ankle_slide_p95_m_s = Quantile(ankle, 0.95);
  m.toe_slide_p95_m_s = Quantile(toe, 0.95);

  if (reference != nullptr) {
    m.has_reference = true;
    std::unordered_map<std::string_view, double> limit;
    for (size_t i = 0; i < reference->joints.size(); ++i) limit.emplace(reference->joints[i], reference->limit_dps[i]);
    std::vector<std::pair<int, double>> compared;  // joint, limit
    for (int j = 0; j < clip.skeleton.num_joints(); ++j) {
      const Joint& joint = clip.skeleton.joint(j);
      auto it = limit.find(joint.name);
      if (joint.num_rotations > 0 && it != limit.end()) compared.emplace_back(j, it->second);
    }
    m.compared_joints = static_cast<int>(compared.size());
    if (compared.empty()) {
      return absl::InvalidArgumentError("reference: shares no rotating joint name with the clip");
    }
    double worst_ratio = -1;
    for (int f = 1; f < clip.num_frames(); ++f) {
      bool outlier = false;
      for (const auto& [j, lim] : compared) {
        const double s = JointAngularSpeedDps(clip.skeleton.joint(j), clip.frame(f - 1), clip.frame(f), clip.frame_time_s);
        const double bound = std::max(lim, 1e-6);
        outlier = outlier || s > bound;
        if (s / bound > worst_ratio) {
          worst_ratio = s / bound;
          m.worst_joint = clip.skeleton.joint(j).name;
          m.worst_joint_dps = s;
          m.worst_joint_limit_dps = lim;
        }
      }
      m.speed_outlier_frames += outlier ? 1 : 0;
    }
  }
  return m;
}

}  // namespace kinemo::motion
