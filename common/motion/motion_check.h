// Plausibility measures of a clip (`kinemo motion check`): how much the feet
// slide while they stand, how high the soles are (floating, penetration), how
// far the hips travel, and which joints turn faster than a reference library
// ever does. The foot terms (sole, slide, contact, ground) are those of
// feet.h; heights are above the floor, the plane y = floor_height_m of the
// file (after meters_per_unit).
#pragma once

#include <span>
#include <string>
#include <vector>

#include "common/motion/body_regions.h"
#include "common/motion/feet.h"
#include "common/motion/skeleton.h"
#include "common/status/status.h"

namespace kinemo::motion {

struct MotionCheckParams {
  // Scale and contact thresholds. Contacts are detected from the clip's own
  // ground level (EstimateGroundHeight) when estimate_ground, else from
  // contact.ground_height_m.
  FootContactParams contact;
  bool estimate_ground = true;
  double floor_height_m = 0;
};

// Per-joint angular speed limits: the `quantile` of each joint's angular speed
// (JointAngularSpeedDps) over every frame of the reference clips.
struct JointSpeedLimits {
  std::vector<std::string> joints;  // names
  std::vector<double> limit_dps;    // same order
  double quantile = 0.999;
  int clips = 0;
};
// INVALID_ARGUMENT when there are no clips or no frame pairs; quantile in (0, 1].
StatusOr<JointSpeedLimits> BuildJointSpeedLimits(std::span<const Clip* const> clips, double quantile = 0.999);

struct MotionCheck {
  int num_frames = 0;
  double duration_s = 0;
  double meters_per_unit = 0;
  double ground_height_m = 0;       // the level contacts were detected from
  // Slide during contact (both feet in contact at f-1 and f), both feet pooled.
  double foot_slide_p95_m_s = 0;    // slower of ankle and toe (feet.h "slide")
  double ankle_slide_p95_m_s = 0;
  double toe_slide_p95_m_s = 0;
  double foot_slide_max_m_s = 0;
  int contact_samples = 0;          // slide samples
  double min_foot_height_m = 0;     // lowest sole over the clip; < 0 = penetration
  double max_float_m = 0;           // largest height of the lowest contact sole
  double hips_path_m = 0;           // horizontal path length of the pelvis
  double hips_drift_m = 0;          // its net horizontal displacement
  double contact_fraction = 0;      // foot-frames in contact / (2 · frames)
  // Against a reference (when given): frames in which some joint turns faster
  // than its limit; the joint with the largest speed / limit ratio.
  bool has_reference = false;
  int compared_joints = 0;
  int speed_outlier_frames = 0;
  std::string worst_joint;
  double worst_joint_dps = 0;
  double worst_joint_limit_dps = 0;
};

// `reference` may be null. Joints are matched to the reference by name.
StatusOr<MotionCheck> CheckMotion(const Clip& clip, const BodyRegionMap& regions, const MotionCheckParams& params,
                                  const JointSpeedLimits* reference);

// The q-quantile (linear interpolation between order statistics) of `values`
// (reordered); 0 when empty.
double Quantile(std::vector<double>& values, double q);

}  // namespace kinemo::motion
