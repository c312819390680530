// Intensity in dB as Praat's "To Intensity" computes it: the (optionally
// mean-subtracted) signal squared and averaged under a Kaiser-20 window whose
// effective length is 3.2 / min_pitch (total 6.4 / min_pitch), expressed in
// dB re (2e-5 Pa)^2 taking the samples as pascal.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace kinemo::prosody {

// Floor of the intensity of digital silence, in dB.
inline constexpr double kSilenceDb = -300.0;

class IntensityAnalyzer {
 public:
  IntensityAnalyzer(double min_pitch_hz, bool subtract_mean, double sample_rate_hz);
  // Samples needed on each side of a frame centre.
  int64_t reach_samples() const { return half_ + 1; }
  // Intensity of the frame centred at `time_s`; `samples` starts at absolute
  // index `first_index`; only samples inside [0, signal_end) count.
  double Analyze(std::span<const float> samples, int64_t first_index, int64_t signal_end,
                 double time_s) const;

 private:
  double rate_;
  bool subtract_mean_;
  int64_t half_;
  std::vector<double> weights_;  // 2 * half_ + 1
};

}  // namespace kinemo::prosody
