// Gesture phrases (thesis §4.2, §4.4.2) found in a motion library without
// manual annotation, with their phases, apex and gesture strength (GSI).
//
// Automatic segmentation (per clip), from the hands' speed and acceleration
// relative to the hips (so that trunk sway and root drift do not count):
//   1. Activity: frames where either hand is farther than `rest_distance_m`
//      from where it rests (its position in the clip's first frame) or moves
//      faster than `rest_speed_mps`. Runs of activity separated by less than
//      `min_gap_s` merge; runs shorter than `min_phrase_s` are dropped. Each
//      run is a gesture unit (rest to rest).
//   2. Strokes: peaks of the hand speed (smoothed over 3 frames) inside the
//      gesture space (extension ≥ `space_fraction` of the run's largest
//      extension) that reach `stroke_peak_fraction` of the run's peak speed
//      and at least `min_stroke_speed_mps`. A stroke runs from the speed
//      minimum before its peak to its apex: the first zero crossing of the
//      tangential acceleration (deceleration ending) after the peak, i.e. the
//      speed minimum where the hand reaches its furthest extension (thesis
//      §4.4.2: in discrete strokes the apex coincides with a speed minimum).
//   3. Phases: preparation = run start to the first stroke; hold = frames
//      after a stroke's apex while the hands stay slower than
//      `hold_speed_mps`; retraction = after the last stroke (and its hold) to
//      the run's end. A phrase begins at most `max_preparation_s` before its
//      stroke and ends at most `max_after_stroke_s` after it. A unit with k
//      strokes gives k phrases; phrases after the first start with their
//      stroke (BodySpeech's 'only stroke' case when they also have no hold or
//      retraction).
//
// GSI: FMDistance (Onuma et al. 2008) in its log form on the stroke:
//   GSI_raw = ln(1 + Σ_j ½ m_j · mean_t |ω_j(t)|²)
// with ω_j the angular velocity of joint j's local rotation in degrees per
// second, over shoulders (m = 3), upper arms (m = 3) and forearms (m = 2) of
// both arms. `gsi` is GSI_raw min-max normalised to [0, 1] over the library.
//
// Manual correction: a manifest clip's "phrases" value (kept verbatim by the
// library loader in LibraryClip::annotation_json) replaces the automatic
// phrases of that clip. Format (times in seconds from the clip's start):
//
//   "phrases": [
//     {"start_s": 0.40, "end_s": 2.10,          // required, start < end ≤ clip length
//      "apex_s": 1.20,                          // optional, default: end of the stroke
//      "phases": [                              // required, in order, inside [start_s, end_s]
//        {"phase": "preparation", "start_s": 0.40, "end_s": 0.85},
//        {"phase": "stroke",      "start_s": 0.85, "end_s": 1.25},   // exactly one stroke
//        {"phase": "hold",        "start_s": 1.25, "end_s": 1.50},
//        {"phase": "retraction",  "start_s": 1.50, "end_s": 2.10}]}
//   ]
//
// An empty array means "no gesture phrase in this clip". Phase names:
// preparation, stroke, hold, retraction. The apex must lie in the stroke.
// `kinemo gestures phrases --library DIR --json` prints the automatic
// phrases in this format, ready to be corrected and put in a manifest.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "common/status/status.h"
#include "services/planner/library/library.h"

namespace kinemo::planner::gesture {

enum class Phase { kPreparation, kStroke, kHold, kRetraction };
std::string_view PhaseName(Phase phase);

// [first_frame, end_frame) in the clip's frames.
struct PhaseSpan {
  Phase phase = Phase::kStroke;
  int first_frame = 0;
  int end_frame = 0;
};

struct Phrase {
  int clip = 0;         // index in Library::clips
  int first_frame = 0;  // [first_frame, end_frame) in the clip
  int end_frame = 0;
  std::vector<PhaseSpan> phases;  // in order, covering [first_frame, end_frame)
  double apex_frame = 0;          // fractional frame of the apex (inside the stroke)
  double gsi_raw = 0;             // log FMDistance of the stroke
  double gsi = 0;                 // normalised to [0, 1] over the library
  bool annotated = false;         // from a manifest annotation

  int frames() const { return end_frame - first_frame; }
  const PhaseSpan& stroke() const;
  // Frames of the phases before the stroke (preparation).
  int pre_stroke_frames() const { return stroke().first_frame - first_frame; }
};

struct PhraseParams {
  double rest_distance_m = 0.08;      // hand displacement from rest that counts as activity
  double rest_speed_mps = 0.15;       // hand speed that counts as activity
  double min_gap_s = 0.2;             // shorter rests inside a unit are ignored
  double min_phrase_s = 0.4;          // shortest gesture unit kept
  double space_fraction = 0.5;        // gesture space: extension ≥ this share of the unit's max
  double stroke_peak_fraction = 0.5;  // stroke peak: ≥ this share of the unit's peak speed
  double min_stroke_speed_mps = 0.3;  // and at least this fast
  double hold_speed_mps = 0.15;       // hold: slower than this after the apex
  // A phrase starts at most max_preparation_s before its stroke and ends at
  // most max_after_stroke_s after it (0 = uncut: the unit's start or end,
  // or the next stroke): BEAT2's speaker rarely returns his hands to rest, and
  // uncut units made phrases of 10-23 s that played whole.
  double max_preparation_s = 1.5;
  double max_after_stroke_s = 1.5;
  int max_phrases = 100000;           // limit over the library
};

struct PhraseSet {
  std::vector<Phrase> phrases;   // clip order, then time order
  std::vector<int> clip_counts;  // phrases per clip
  double gsi_raw_min = 0;        // normalisation range of gsi
  double gsi_raw_max = 0;
  std::vector<std::string> warnings;
};

// Phrases of every clip (annotation where given, else automatic), GSI filled.
// Fails (INVALID_ARGUMENT naming clip and field) on a malformed annotation,
// FAILED_PRECONDITION when the skeleton has no hands/arms.
StatusOr<PhraseSet> ExtractPhrases(const Library& library, const PhraseParams& params = {});

// GSI_raw of frames [first, end) of a clip (FMDistance log form); `time_scale`
// multiplies durations (a stroke played `time_scale` times longer has its
// angular velocities divided by it).
double FmDistance(const Library& library, const LibraryClip& clip, int first, int end,
                  double time_scale = 1.0);

// The phrases of one clip in the manifest annotation format (JSON array).
std::string PhrasesToAnnotationJson(const Library& library, const PhraseSet& set, int clip);

}  // namespace kinemo::planner::gesture
