// Syllables, pauses and pitch accents from analysis frames.
//
// Syllables (Gesture Controllers §5.2): troughs separated by peaks in the
// intensity curve. A causal peak/trough tracker with hysteresis `min_dip_db`
// confirms a peak once intensity has fallen that far below it, and a trough
// (a syllable boundary) once intensity has risen that far above it; silence
// (below the reference level minus silence_threshold_db) ends a syllable too.
// Because it is causal, offline and live analysis segment identically given
// the same reference level.
//
// Accents (thesis appendix 8.2): for each voiced syllable, its nucleus (the
// frames around the intensity peak within nucleus_drop_db) gives a strength
// indicator SI = F0/F0max + (I - floor)/(Imax - floor) (pitch and intensity
// normalised by the series maxima), multiplied by pre_pause_bonus before a
// pause. Candidates below threshold * max SI drop; a candidate is kept if no
// candidate within min_distance_s (PAPT to PAPT) is stronger. Strength =
// SI / max SI. PAPT is the time of the F0 maximum in the syllable.
// PSI (appendix 8.1) = D * E * (0.5 PR + 0.5 MP) over the nucleus: D in
// seconds, E the nucleus' mean intensity in dB, PR the relative F0 range
// (max - min) / max (times falling_range_penalty for a falling, H+L*-like
// nucleus), MP the nucleus' mean F0 / pitch ceiling.
#pragma once

#include <span>
#include <vector>

#include "services/prosody/core/options.h"
#include "services/prosody/core/types.h"

namespace kinemo::prosody {

// A segment the tracker completed.
struct SegmentEvent {
  enum class Kind { kSyllable, kPauseStart, kPauseEnd };
  Kind kind = Kind::kSyllable;
  int first_frame = 0;  // syllable: first frame; pause: first silent frame
  int end_frame = 0;    // syllable: boundary frame (exclusive); pause end: first speech frame
  int peak_frame = 0;   // syllable: intensity peak
};

class SyllableTracker {
 public:
  SyllableTracker(const SegmentationOptions& options, double step_s);
  // Frame `index` (consecutive from 0) with its intensity; `reference_db` is
  // the level silence is measured against. Completed segments go to `out`.
  void Push(int index, double intensity_db, double reference_db, std::vector<SegmentEvent>* out);
  // End of the audio at frame `end_index` (exclusive).
  void Finish(int end_index, std::vector<SegmentEvent>* out);
  bool in_pause() const { return in_pause_; }
  bool in_syllable() const { return state_ != State::kSilence; }
  // First frame of the open syllable (valid while in_syllable()).
  int open_start() const { return start_; }

 private:
  enum class State { kSilence, kRising, kFalling };
  void EndSyllable(int end_frame, std::vector<SegmentEvent>* out);
  SegmentationOptions o_;
  double step_s_;
  State state_ = State::kSilence;
  int start_ = 0;
  double max_db_ = 0;
  int max_frame_ = 0;
  double min_db_ = 0;
  int min_frame_ = 0;
  bool seen_speech_ = false;
  int silent_run_ = 0;
  int silent_start_ = 0;
  bool in_pause_ = false;
  int min_pause_frames_;
  int min_syllable_frames_;
};

// Fills the per-syllable features of `s` (frame range and peak set) from
// `frames` (indexed by frame number).
void FillSyllableFeatures(std::span<const Frame> frames, double step_s, Syllable* s);

// Nucleus measures of a syllable.
struct Nucleus {
  bool voiced = false;     // has voiced frames
  double duration_s = 0;   // D
  double mean_db = 0;      // E
  double peak_db = 0;
  double f0_mean_hz = 0;
  double f0_range = 0;     // PR, after the falling penalty
  double papt_s = 0;       // F0 maximum in the syllable
  double psi = 0;
};
Nucleus ComputeNucleus(std::span<const Frame> frames, const Syllable& s,
                       const AnalysisOptions& options);

// Normalisers of the §8.2 indicator.
struct IndicatorScale {
  double max_f0_hz = 0;
  double max_peak_db = 0;
  double floor_db = 0;
};
double StrengthIndicator(const Nucleus& n, bool before_pause, const IndicatorScale& scale,
                         const AccentOptions& options);

// Offline: accents of a complete syllable list (updates accent_index).
std::vector<Accent> SelectAccents(std::span<const Frame> frames, std::vector<Syllable>* syllables,
                                  const AnalysisOptions& options, double reference_db);

}  // namespace kinemo::prosody
