// Pitch (F0) by autocorrelation as Boersma (1993) describes it and Praat's
// "To Pitch (ac)" implements it: a Hanning-windowed, mean-subtracted frame;
// its autocorrelation (by FFT) divided by the window's autocorrelation;
// parabolic interpolation of the peaks between 1/ceiling and 1/floor; an
// unvoiced candidate whose strength grows in quiet frames; and a Viterbi path
// over the candidates with octave-jump and voiced/unvoiced transition costs.
#pragma once

#include <complex>
#include <cstdint>
#include <span>
#include <vector>

#include "services/prosody/core/fft.h"
#include "services/prosody/core/options.h"

namespace kinemo::prosody {

struct PitchCandidate {
  float f0_hz = 0;     // 0 = the unvoiced candidate
  float strength = 0;  // normalised autocorrelation (voiced) or unvoiced strength
};

// The candidates of one frame; slot 0 is the unvoiced candidate.
struct PitchCandidates {
  static constexpr int kMaxCandidates = 32;
  PitchCandidate c[kMaxCandidates];
  int count = 1;
  float voicing_probability = 0;
};

// Computes the candidates of single frames. Holds its scratch buffers, so one
// instance serves one thread; Analyze allocates nothing.
class PitchFrameAnalyzer {
 public:
  PitchFrameAnalyzer(const PitchOptions& options, double sample_rate_hz);

  // Samples needed on each side of a frame centre (window and local mean).
  int64_t reach_samples() const;
  // Candidates of the frame centred at `time_s`. `samples` holds the signal
  // from absolute sample index `first_index` on; samples outside it are zero.
  // `global_peak` is the largest absolute amplitude of the signal (live: so far).
  void Analyze(std::span<const float> samples, int64_t first_index, double time_s,
               float global_peak, PitchCandidates* out);

 private:
  PitchOptions o_;
  double rate_;
  int half_window_;  // window = 2 * half_window_ samples
  int period_;       // samples in one period of the floor
  int min_lag_;
  int max_lag_;
  RealFft fft_;
  std::vector<float> window_;
  std::vector<float> window_ac_;  // normalised, up to max_lag_ + 1
  std::vector<float> frame_;
  std::vector<float> ac_;
  std::vector<std::complex<float>> spectrum_;
  std::vector<std::complex<float>> work_;
};

// Viterbi over frames of candidates. Works offline (keep every frame) and
// online (a ring of the last `history_frames`).
class PitchPath {
 public:
  PitchPath(const PitchOptions& options, int64_t history_frames);
  void Push(const PitchCandidates& candidates);
  int64_t frames() const { return count_; }
  // Traces the best path back from the newest frame and writes the chosen
  // candidate of frames [first, frames()) into `f0_hz` (0 = unvoiced).
  // `first` must be within the history.
  void TraceBack(int64_t first, std::span<float> f0_hz) const;
  // Chosen F0 of frame frames()-1-lag along the best path to the newest frame.
  float DecideLagged(int64_t lag) const;

 private:
  bool Voiced(float f) const { return f > 0 && f < ceiling_; }
  float Transition(float from, float to) const;
  PitchOptions o_;
  float ceiling_;
  float step_correction_;
  int64_t history_;
  int64_t count_ = 0;
  std::vector<PitchCandidates> cands_;  // ring
  std::vector<uint8_t> back_;           // ring, kMaxCandidates per frame
  std::vector<double> delta_;           // newest frame's scores
  std::vector<double> next_delta_;
};

}  // namespace kinemo::prosody
