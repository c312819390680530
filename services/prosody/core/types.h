// Plain result types of the prosody analysis (no protobuf, no gRPC).
#pragma once

#include <vector>

namespace kinemo::prosody {

// One analysis frame (10 ms hop by default).
struct Frame {
  double time_s = 0;               // centre of the analysis windows
  double f0_hz = 0;                // 0 when unvoiced
  bool voiced = false;             // chosen by the Viterbi path
  double voicing_probability = 0;  // best periodicity minus the silence penalty, in [0, 1]
  double intensity_db = 0;         // dB re 2e-5 Pa, samples taken as Pa (as Praat)
};

// A syllable delimited by intensity troughs (or silence).
struct Syllable {
  double start_s = 0;
  double end_s = 0;
  double f0_mean_hz = 0;  // over voiced frames; 0 when none
  double intensity_mean_db = 0;
  double length_s = 0;
  bool voiced = false;  // at least half of its frames voiced
  double nucleus_time_s = 0;  // intensity peak
  int accent_index = -1;
  // Frame range [first_frame, end_frame) in the track.
  int first_frame = 0;
  int end_frame = 0;
  // Index of the intensity-peak frame.
  int peak_frame = 0;
  // Followed by a pause (or by the end of the audio).
  bool before_pause = false;
};

// A pitch accent (thesis appendix 8.1-8.2).
struct Accent {
  double time_s = 0;    // PAPT: time of the F0 maximum in the accented syllable
  double strength = 0;  // §8.2 indicator normalised by the series maximum, in [0, 1]
  double psi = 0;       // PSI = D * E * (0.5 PR + 0.5 MP) over the nucleus
  double indicator = 0;  // the §8.2 strength indicator before normalisation
  int syllable_index = -1;
  double syllable_start_s = 0;
  double syllable_end_s = 0;
  bool before_pause = false;
};

struct Pause {
  double start_s = 0;
  double end_s = 0;
};

// The prosody of a recording.
struct ProsodyResult {
  double duration_s = 0;
  double sample_rate_hz = 0;
  double frame_step_s = 0.01;
  std::vector<Frame> frames;
  std::vector<Syllable> syllables;
  std::vector<Accent> accents;
  std::vector<Pause> pauses;
};

}  // namespace kinemo::prosody
