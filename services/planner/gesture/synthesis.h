// Gesture synthesis from pitch accents over a GestureGraph.
//
// GMG (thesis §4.4.4): accents in order; for accent i an anticipation time
// Ta_i (PAPT − apex, positive = the apex comes first, as in the thesis) is
// drawn uniformly in the synchrony window [synchrony_min_s,
// synchrony_max_s] and sets the anchor A_i = t_i − Ta_i. From the previous
// phrase m, every successor n gets the target length (4.3)
//   Tt = A_i − (A_{i−1} + w_{i−1}·Tap_{i−1}) − Tb·[edge is not E1]
// and the warp (4.4) w = Tt / (T_GP − Tap); its cost (4.7) is
//   S (edge weight / st) + I (0 if GSI_raw ∈ (0.6633·x + 10.24,
//   0.6633·x + 12.24), x = ln PSI, else penalty) + T (w mapped to [0, 1]
//   on [1, MAX_WARP] and on [1/MAX_WARP, 1], else penalty);
// the cheapest is played, the whole phrase time-warped by w; E2 transitions
// are start-end blends of `blend_s`.
//
// BodySpeech (§4.5.2): the same walk from a rest-pose node, but strokes are
// not warped: a phrase with a preparation ('gestural phrase') warps only its
// non-stroke phases by w = original / target length, allowed in [0.8, 1.2];
// a phrase that starts with its stroke ('only stroke') warps the stroke,
// allowed in [0.9, 1.1], and its GSI is recomputed for the new duration.
// Cost (4.8) = edge weight (pose distance) + |s − GSI| (s = the accent's
// strength shifted by the gesture-emphasis slider, GSI normalised) + Ctime
// (4.9: w normalised from [min, max] to [0, 1], else penalty). Blends use the
// edge's optimal blend length.
//
// Both: besides the graph's edges, the current phrase may be left early, where
// its stroke ends (skipping its hold and retraction: Kendon's gesture units
// chain phrases without retracting), toward any phrase whose start pose is within the similarity
// threshold of that pose (an E2 transition with its blend); and a phrase may
// be reached through the rest
// pose (blend to rest, hold, blend into the phrase at its natural speed) when
// the gap allows it; its smoothness term is that of both rest edges. No
// phrase plays more than `max_speed_change` times faster or slower than
// recorded. When no
// candidate fits before the anchor (even with the latest apex the window
// allows), the accent is left without gesture and the reason is reported.
// The motion ends with a blend to the rest pose, held to `duration_s`; the
// last phrase's tail is cut (never before its apex) so that the blend ends by
// `duration_s`. Blends are rendered as inertialized joins (docs/gesture.md,
// "Synthesis"): the difference from the motion shown decays over the blend, at
// least 0.8 s.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "common/status/cancel.h"
#include "common/motion/feet.h"
#include "common/motion/skeleton.h"
#include "common/status/status.h"
#include "services/planner/gesture/graph.h"

namespace kinemo::planner::gesture {

enum class Algorithm { kGmg, kBodySpeech };

struct AccentInput {
  double papt_s = 0;    // pitch-accent peak time
  double strength = 0;  // in [0, 1]
  double psi = 0;       // PSI, >= 0
};

struct SynthesisParams {
  double synchrony_min_s = -0.03;  // anticipation PAPT − apex, lower bound
  double synchrony_max_s = 0.22;   // upper bound
  double max_warp = 1.5;           // GMG MAX_WARP
  double penalty = 10;             // rule-breaking penalty
  double blend_s = 0.4;            // GMG start-end blend (0.25 made pops: docs/evaluation.md)
  uint64_t seed = 0;               // 0 = fixed seed
  double gesture_emphasis = 0;     // slider in [-1, 1] (BodySpeech strength shift)
  double duration_s = 0;           // 0 = last accent + 1 s
  double max_output_s = 600;       // limit
  // BodySpeech warp bounds.
  double phrase_warp_min = 0.8, phrase_warp_max = 1.2;
  double stroke_warp_min = 0.9, stroke_warp_max = 1.1;
  // Hard limit: no phrase plays more than this many times faster or slower
  // than recorded (beyond the soft bounds the penalty applies). 2.0 let
  // strokes run twice their recorded speed (wrists at 4-5 m/s against a real
  // speaker's 1.9-2.5: pops); on BEAT2 held-out speech 1.2 took BodySpeech's
  // kinetic FD from 353 / 57 to 99 / 10.5 and its jerk from 198 / 176 to
  // 125 / 96 m/s^3, at the cost of fewer accents with an apex in the window
  // (0.79 / 0.90 -> 0.59 / 0.62, chance 0.49 / 0.51): docs/evaluation.md.
  double max_speed_change = 1.2;
  // BodySpeech: |s − GSI| at most this counts as meeting the intensity rule.
  double emphasis_tolerance = 0.2;
  // Choice, not playback (as the Gesture Controller's): a phrase's recorded
  // continuation (E1 edge, zero cost) is not taken where it would make the
  // run of unbroken library material longer than max_run_s, and a phrase
  // that ended a play less than recent_s before is not entered again; when
  // nothing fits an accent so, both are waived for it. Without them GMG and
  // BodySpeech replayed the library: 36-51 % of their output on held-out
  // BEAT2 speech lay in near copies over 2 s, the longest 8-21 s
  // (docs/evaluation.md). 0 = off.
  double max_run_s = 3.0;
  double recent_s = 4.0;
  // Planted feet (common/motion/feet.h) on the rendered motion, with the
  // library's scale and ground (LibraryFootPlantParams); on by default.
  motion::FootPlantParams feet = motion::StandingFootPlantParams();
  // No hand, elbow or head faster than this many times the library's fastest
  // (common/motion/speed_limit.h: the upper body smoothed around such
  // moments, after the feet are planted); 0 = off. Joins and warps of two
  // phrases can add their speeds: on held-out BEAT2 speech GMG's and
  // BodySpeech's wrists reached 2.1-2.9 m/s where the library's fastest is
  // 1.9-2.5 (docs/evaluation.md).
  double max_speed_scale = 1.0;
  // Checked every few accents and before rendering (null = never stops):
  // DEADLINE_EXCEEDED or CANCELLED ("synthesis: ...") once stopped.
  const CancelToken* cancel = nullptr;
};

struct Placement {
  int accent_index = 0;
  double papt_s = 0;
  double apex_s = 0;
  double psi = 0;
  double gsi = 0;   // raw for GMG, normalised for BodySpeech
  double warp = 1;  // GMG: target / original (4.4); BodySpeech: original / target
  EdgeKind edge_kind = EdgeKind::kSimilarity;
  int from_node = -1;
  int to_node = -1;
  double edge_weight = 0;
  double edge_blend_s = 0;
  int phrase = -1;
  double anticipation_s = 0;  // PAPT − apex
  double smooth_cost = 0, intensity_cost = 0, time_cost = 0;
  bool placed = false;
  bool early_exit = false;  // the previous phrase was left where its stroke ends
  bool memory_waived = false;  // nothing fitted with recent_s and max_run_s: both waived for this accent
  bool intensity_ok = false;
  // Some candidate that fitted this accent met the intensity rule (the
  // library allowed it).
  bool intensity_possible = false;
  std::string skipped_reason;
};

struct SynthesisResult {
  motion::Clip clip;  // continuous motion at the library's frame rate
  std::vector<Placement> report;
  double synchrony_rate = 0;       // placed with PAPT − apex in the window / accents
  double intensity_rule_rate = 0;  // placed meeting the intensity rule / placed
  // The same over the placed accents where some fitting candidate met it.
  double intensity_rule_rate_where_possible = 0;
  bool feet_planted = false;  // false when off, or the skeleton has no legs
  std::string feet_note;      // why not, when asked for
  // The upper body's ceiling (m/s; 0 = off or no head and hands), the
  // fastest it moved before the ceiling and the frames it changed.
  double speed_limit_m_s = 0, speed_max_before_m_s = 0;
  int speed_limited_frames = 0;
  double compute_s = 0;
};

// Validates accents (finite, in time order, strength in [0, 1], psi >= 0) and
// parameters; INVALID_ARGUMENT names the field.
StatusOr<SynthesisResult> Synthesize(const GestureGraph& graph, std::span<const AccentInput> accents,
                                     Algorithm algorithm, const SynthesisParams& params);

// The intensity rule of §4.4.3 (4.1) on the GSI_raw scale with x = ln PSI.
bool IntensityRuleHolds(double gsi_raw, double psi);

}  // namespace kinemo::planner::gesture
