// Prosody features per syllable (Gesture Controllers §5.2) from a mono
// signal: a minimal, documented stand-in until the prosody service's core
// library can fill the same interface (ProsodyExtractor).
//
//   frames     10 ms hop, 40 ms window; intensity = 10 log10(mean x²) dB FS;
//              F0 by normalised autocorrelation over 75..400 Hz (peak ≥ 0.5
//              and intensity within 30 dB of the loudest frame = voiced).
//   syllables  the smoothed (50 ms) intensity curve is split into speech runs
//              (≥ max − 30 dB) and silences; inside a run, local maxima
//              ("peaks") are merged until each adjacent pair is separated by
//              a trough ≥ 2 dB below the lower of the two; syllable
//              boundaries are those troughs ("troughs separated by peaks").
//              Silences become unvoiced steps of at most 0.5 s.
//   per step   mean F0 over voiced frames (voiced if ≥ 50 % of frames are),
//              mean intensity, length.
//   accents    voiced steps whose strength (z-score of intensity + z-score of
//              F0 within the recording) exceeds 0.5, at least 0.5 s apart,
//              strongest first; used only to build the paired corpus.
#pragma once

#include <functional>
#include <span>
#include <vector>

#include "common/status/status.h"
#include "services/inference/core/prosody_clusters.h"

namespace kinemo::inference {

struct Accent {
  double time_s = 0.0;    // intensity peak of the syllable
  double strength = 0.0;  // z-score sum, > 0.5
  int step = 0;           // index into ProsodyTrack::steps
};

struct ProsodyTrack {
  std::vector<ProsodyStep> steps;
  std::vector<Accent> accents;  // sorted by time
};

// The interface the prosody core can implement: mono samples → steps.
using ProsodyExtractor =
    std::function<StatusOr<ProsodyTrack>(std::span<const float> samples, int sample_rate_hz)>;

// The minimal extractor described above.
StatusOr<ProsodyTrack> ExtractProsody(std::span<const float> samples, int sample_rate_hz);

}  // namespace kinemo::inference
