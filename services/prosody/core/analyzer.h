// Offline prosody analysis of a whole recording.
#pragma once

#include <span>

#include "common/status/status.h"
#include "services/prosody/core/options.h"
#include "services/prosody/core/types.h"

namespace kinemo::prosody {

// Where frames are centred. Default: t_k = k * step for every k with
// t_k < duration (windows reaching outside the audio see zeros).
struct FrameGrid {
  double first_time_s = 0;
  int count = -1;  // -1 = up to the end of the audio
};

// Analyses mono samples (in pascal for calibrated dB; full scale = 1 Pa) at
// `sample_rate_hz`. INVALID_ARGUMENT for bad options or rates.
StatusOr<ProsodyResult> AnalyzeSamples(std::span<const float> samples, double sample_rate_hz,
                                       const AnalysisOptions& options, const FrameGrid& grid = {});

// Frames only (pitch and intensity), e.g. for comparison with Praat.
StatusOr<std::vector<Frame>> AnalyzeFrames(std::span<const float> samples, double sample_rate_hz,
                                           const AnalysisOptions& options,
                                           const FrameGrid& grid = {});

// Syllables, pauses and accents from frames (used by AnalyzeSamples).
void Segment(const AnalysisOptions& options, ProsodyResult* result);

}  // namespace kinemo::prosody
