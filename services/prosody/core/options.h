// Every parameter of the prosody analysis. Defaults follow Praat's
// "To Pitch (ac)" and "To Intensity" (75-600 Hz, 10 ms) and the thesis'
// pitch-accent detector (appendix 8.2).
#pragma once

#include "common/status/status.h"

namespace kinemo::prosody {

struct PitchOptions {
  double time_step_s = 0.01;
  double floor_hz = 75;
  double ceiling_hz = 600;
  // Window length in periods of the floor (Praat: 3 for Hanning).
  double periods_per_window = 3;
  int max_candidates = 15;  // including the unvoiced candidate
  // Silence threshold: local peak relative to the global peak (Praat 0.03).
  double silence_threshold = 0.03;
  double voicing_threshold = 0.45;
  double octave_cost = 0.01;        // per octave, favours high candidates
  double octave_jump_cost = 0.35;   // per octave between consecutive frames
  double voiced_unvoiced_cost = 0.14;
};

struct IntensityOptions {
  // Kaiser-20 window whose effective length is 3.2 / min_pitch_hz (total
  // length 6.4 / min_pitch_hz), as Praat's To Intensity. 0 = pitch floor.
  double min_pitch_hz = 0;
  bool subtract_mean = true;
};

struct SegmentationOptions {
  // Frames quieter than (reference maximum - silence_threshold_db) are
  // silence. Reference: the recording's maximum intensity (offline) or the
  // running maximum (live).
  double silence_threshold_db = 25;
  // Frames below this absolute level are always silence (dB re 2e-5 Pa).
  double min_speech_db = 30;
  // Minimum fall / rise of intensity that confirms a peak / trough.
  double min_dip_db = 2;
  double min_pause_s = 0.2;
  // Shorter syllables (clicks) are dropped.
  double min_syllable_s = 0.05;
  // Nucleus: contiguous frames around the intensity peak within this many dB.
  double nucleus_drop_db = 3;
};

struct AccentOptions {
  // Share of the maximum strength indicator below which candidates drop.
  double threshold = 0.3;
  // Of two candidates closer than this (PAPT to PAPT), the stronger is kept.
  double min_distance_s = 0.3;
  // Multiplicative bonus of the indicator of a syllable before a pause.
  double pre_pause_bonus = 1.2;
  // PSI: factor applied to the pitch range of falling (H+L*) nuclei.
  double falling_range_penalty = 0.25;
};

struct AnalysisOptions {
  PitchOptions pitch;
  IntensityOptions intensity;
  SegmentationOptions segmentation;
  AccentOptions accent;
  // Live only: fixed lag of the online Viterbi path, in seconds.
  double viterbi_lag_s = 0.1;
  // Offline only: threads one analysis uses (pitch candidates and intensity
  // of blocks of frames in parallel); 0 = one per core. The results are the
  // same for any number.
  int threads = 0;
};

inline constexpr int kMaxAnalysisThreads = 256;

// Checks ranges; messages name the field ("pitch.floor_hz: ...").
Status ValidateOptions(const AnalysisOptions& options, double sample_rate_hz);

}  // namespace kinemo::prosody
