// Tones from styled capture (Gesture Controllers §8.2), across corpora.
//
// A tone m is a transform T_m of the kinematic parameters y = (T, D, V, A, C,
// H) of gesture segments (common/gesture/kinematics.h). It is estimated on a
// corpus that has the same actions performed neutrally and in style m (the
// Bandai-Namco dataset: bow, bye, byebye, guide ... in "normal", "angry",
// "happy", "sad", "active" ...): Gaussians are fitted to the segments of the
// styled takes and to those of the normal takes of the *same* actions, and
// T_m is the optimal-transport affine map between them (FitStyleTransform):
//   T_m(y) = A_m (y − μ_n) + μ_m.
//
// Transfer to another library (the conversational BEAT2 library): the source
// neutral mean μ_n describes the source corpus, not the target, so the
// controller applies the tone around the *target* library's own neutral mean
// μ_t:  T'_m(y) = A_m (y − μ_t) + μ_t + (μ_m − μ_n),
// i.e. the styled/normal difference as a shift on the log scales (a factor on
// durations, speeds, accelerations, heights) and the spread change A_m about
// the target's mean. ToneTransfer holds (A_m, shift = μ_m − μ_n);
// ApplyTransfer gives the StyleTransform for a target mean.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "common/status/status.h"
#include "services/planner/controller/expected_distance.h"

namespace kinemo::planner::controller {

// A tone estimated on a source corpus, ready to apply to any library.
struct ToneTransfer {
  std::string name;        // tone name, e.g. "energetic"
  std::string source;      // where it came from, e.g. "bandai style 'active' vs 'normal'"
  Matrix6 A = Matrix6::Identity();
  Vector6 shift = Vector6::Zero();  // μ_m − μ_n on the log scales
  Vector6 source_neutral_mean = Vector6::Zero();
  Vector6 source_tone_mean = Vector6::Zero();
  std::vector<std::string> actions;  // actions both sides share
  int neutral_segments = 0, tone_segments = 0;
};

// Bounds a transfer must meet (INVALID_ARGUMENT naming `field` otherwise):
// name [a-z0-9_-]{1,32}; A finite, symmetric, eigenvalues in [0.05, 20];
// shift finite, each |value| ≤ 10.
Status ValidateToneTransfer(const ToneTransfer& t, const std::string& field);

// T'_m for a target library whose neutral segments have mean `target_mean`.
StyleTransform ApplyTransfer(const ToneTransfer& t, const Vector6& target_mean);

struct ToneEstimationOptions {
  // Style token (the file name's third field) -> tone name. Default:
  // angry -> angry, happy -> happy, sad -> subdued, active -> energetic
  // (Bandai's "tired" takes move the hands faster and wider than its normal
  // ones, segment by segment; "sad" is the slow, low, small style).
  std::map<std::string, std::string> style_tones;
  std::string neutral_style = "normal";
  // Actions (the file name's second field) to use; empty = every action with
  // both a neutral and a styled take.
  std::vector<std::string> actions;
};
ToneEstimationOptions DefaultToneEstimationOptions();

// Estimates the tones from BVH files (paths, or directories read for *.bvh)
// named like the Bandai dataset: `<prefix>_<action>_<style>_<take>.bvh`.
// Files whose style is neither neutral nor mapped are ignored. Per tone:
// the actions that have takes in both the neutral and the tone's style, all
// their segments pooled on each side. INVALID_ARGUMENT naming `field` for a
// missing path or a bad BVH; FAILED_PRECONDITION when a tone has no
// action in common with the neutral takes or too few segments (< 2).
// Tones come out sorted by name.
StatusOr<std::vector<ToneTransfer>> EstimateTones(const std::vector<std::string>& paths,
                                                  const ToneEstimationOptions& options,
                                                  const std::string& field);

}  // namespace kinemo::planner::controller
