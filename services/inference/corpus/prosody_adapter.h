// ProsodyExtractor backed by the prosody service's core library
// (services/prosody/core): its syllables (mean F0 over voiced frames, mean
// intensity, length, voiced flag) become the steps; pauses and other gaps
// between syllables become unvoiced steps of at most 0.5 s with intensity
// 0 dB (as the coordinator sends pauses at run time), so that the steps tile
// the recording; its pitch accents (PAPT, strength in [0, 1])
// become the accents used by the synthetic pairing (strength rescaled ×3 to
// the range of the minimal extractor's z-scores).
#pragma once

#include "services/inference/corpus/prosody_features.h"

namespace kinemo::inference {

StatusOr<ProsodyTrack> ExtractProsodyWithProsodyCore(std::span<const float> samples,
                                                     int sample_rate_hz);

}  // namespace kinemo::inference
