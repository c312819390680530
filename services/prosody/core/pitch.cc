#include "services/prosody/core/pitch.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace kinemo::prosody {
namespace {

std::size_t NextPowerOfTwo(std::size_t n) {
  std::size_t p = 8;
  while (p < n) p <<= 1;
  return p;
}

}  // namespace

PitchFrameAnalyzer::PitchFrameAnalyzer(const PitchOptions& options, double sample_rate_hz)
    : o_(options),
      rate_(sample_rate_hz),
      half_window_(std::max(2, static_cast<int>(std::floor(options.periods_per_window /
                                                           options.floor_hz * sample_rate_hz)) /
                                   2)),
      period_(std::max(2, static_cast<int>(std::floor(sample_rate_hz / options.floor_hz)))),
      min_lag_(std::max(2, static_cast<int>(std::floor(sample_rate_hz / options.ceiling_hz)))),
      max_lag_(std::min(static_cast<int>(std::floor(2 * half_window_ / options.periods_per_window)) + 2,
                        2 * half_window_ - 2)),
      // Hanning: interpolation depth 0.5 -> 1.5 windows of room, no wrap-around.
      fft_(NextPowerOfTwo(static_cast<std::size_t>(3 * half_window_))) {
  const int n = 2 * half_window_;
  window_.resize(n);
  for (int i = 0; i < n; ++i) {
    window_[i] = static_cast<float>(0.5 - 0.5 * std::cos(2.0 * std::numbers::pi * (i + 1) / (n + 1)));
  }
  const std::size_t nfft = fft_.size();
  frame_.assign(nfft, 0.0f);
  ac_.assign(nfft, 0.0f);
  spectrum_.assign(nfft / 2 + 1, {});
  work_.assign(nfft / 2, {});
  std::copy(window_.begin(), window_.end(), frame_.begin());
  fft_.Autocorrelation(frame_, ac_, spectrum_, work_);
  window_ac_.resize(max_lag_ + 2);
  for (int k = 0; k < max_lag_ + 2; ++k) window_ac_[k] = ac_[k] / ac_[0];
}

int64_t PitchFrameAnalyzer::reach_samples() const { return std::max(half_window_, period_) + 1; }

void PitchFrameAnalyzer::Analyze(std::span<const float> samples, int64_t first_index,
                                 double time_s, float global_peak, PitchCandidates* out) {
  const int64_t total_end = first_index + static_cast<int64_t>(samples.size());
  auto at = [&](int64_t i) -> float {
    return (i >= first_index && i < total_end) ? samples[i - first_index] : 0.0f;
  };
  // Sample j sits at (j + 0.5) / rate; `left` is the last sample before the centre.
  const int64_t left = static_cast<int64_t>(std::floor(time_s * rate_ - 0.5));
  // Local mean over one longest period to each side.
  double sum = 0;
  for (int64_t j = left - period_ + 1; j <= left + period_; ++j) sum += at(j);
  const float mean = static_cast<float>(sum / (2.0 * period_));
  const int n = 2 * half_window_;
  const int64_t start = left - half_window_ + 1;
  if (start >= first_index && start + n <= total_end) {
    const float* x = samples.data() + (start - first_index);
    for (int i = 0; i < n; ++i) frame_[i] = (x[i] - mean) * window_[i];
  } else {
    for (int i = 0; i < n; ++i) {
      const int64_t j = start + i;
      frame_[i] = (j >= first_index && j < total_end) ? (at(j) - mean) * window_[i] : 0.0f;
    }
  }
  std::fill(frame_.begin() + n, frame_.end(), 0.0f);
  // Local peak over half a longest period to each side of the centre.
  float local_peak = 0;
  for (int i = std::max(0, half_window_ - period_ / 2); i < std::min(n, half_window_ + period_ / 2);
       ++i) {
    local_peak = std::max(local_peak, std::fabs(frame_[i]));
  }
  const float vt = static_cast<float>(o_.voicing_threshold);
  const float ratio = global_peak > 0 ? local_peak / global_peak : 0.0f;
  const float silence_penalty = std::max(
      0.0f, 2.0f - ratio / static_cast<float>(o_.silence_threshold / (1.0 + o_.voicing_threshold)));
  out->count = 1;
  out->c[0] = {0.0f, vt + silence_penalty};
  out->voicing_probability = 0;
  if (local_peak <= 0) return;

  fft_.Autocorrelation(frame_, ac_, spectrum_, work_);
  if (!(ac_[0] > 0)) return;
  const float inv0 = 1.0f / ac_[0];
  float* r = frame_.data();  // reuse as the normalised autocorrelation
  for (int k = 0; k <= max_lag_ + 1; ++k) r[k] = ac_[k] * inv0 / window_ac_[k];

  const int max_voiced = std::min(o_.max_candidates, PitchCandidates::kMaxCandidates) - 1;
  float best_strength = 0;
  // Rank score of each kept candidate (strength plus the octave bonus).
  float rank[PitchCandidates::kMaxCandidates];
  for (int k = std::max(min_lag_, 1); k <= max_lag_; ++k) {
    if (!(r[k] > 0.5f * vt && r[k] > r[k - 1] && r[k] >= r[k + 1])) continue;
    const float dr = 0.5f * (r[k + 1] - r[k - 1]);
    const float d2r = 2.0f * r[k] - r[k - 1] - r[k + 1];
    float lag = static_cast<float>(k);
    float strength = r[k];
    if (d2r > 0) {
      lag += dr / d2r;
      strength += 0.5f * dr * dr / d2r;
    }
    // Peaks above 1 are artefacts of the window division; reflect them.
    if (strength > 1.0f) strength = 1.0f / strength;
    const float f = static_cast<float>(rate_) / lag;
    const float score =
        strength - static_cast<float>(o_.octave_cost) * std::log2(static_cast<float>(o_.floor_hz) / f);
    best_strength = std::max(best_strength, strength);
    if (out->count - 1 < max_voiced) {
      rank[out->count] = score;
      out->c[out->count++] = {f, strength};
    } else {
      int weakest = 1;
      for (int i = 2; i < out->count; ++i) {
        if (rank[i] < rank[weakest]) weakest = i;
      }
      if (score > rank[weakest]) {
        rank[weakest] = score;
        out->c[weakest] = {f, strength};
      }
    }
  }
  out->voicing_probability = std::clamp(best_strength - silence_penalty, 0.0f, 1.0f);
}

PitchPath::PitchPath(const PitchOptions& options, int64_t history_frames)
    : o_(options),
      ceiling_(static_cast<float>(options.ceiling_hz)),
      step_correction_(static_cast<float>(0.01 / options.time_step_s)),
      history_(std::max<int64_t>(history_frames, 2)),
      cands_(history_),
      back_(history_ * PitchCandidates::kMaxCandidates, 0),
      delta_(PitchCandidates::kMaxCandidates, 0.0),
      next_delta_(PitchCandidates::kMaxCandidates, 0.0) {}

float PitchPath::Transition(float from, float to) const {
  const bool v1 = Voiced(from);
  const bool v2 = Voiced(to);
  if (!v1 && !v2) return 0.0f;
  if (v1 != v2) return static_cast<float>(o_.voiced_unvoiced_cost) * step_correction_;
  return static_cast<float>(o_.octave_jump_cost) * std::fabs(std::log2(from / to)) *
         step_correction_;
}

void PitchPath::Push(const PitchCandidates& in) {
  const int64_t slot = count_ % history_;
  PitchCandidates& cur = cands_[slot];
  cur = in;
  // Local scores: voiced candidates pay the octave cost relative to the ceiling.
  double local[PitchCandidates::kMaxCandidates];
  for (int j = 0; j < cur.count; ++j) {
    const float f = cur.c[j].f0_hz;
    local[j] = Voiced(f) ? cur.c[j].strength - o_.octave_cost * std::log2(ceiling_ / f)
                         : cur.c[j].strength;
  }
  uint8_t* back = &back_[slot * PitchCandidates::kMaxCandidates];
  if (count_ == 0) {
    for (int j = 0; j < cur.count; ++j) {
      delta_[j] = local[j];
      back[j] = 0;
    }
  } else {
    const PitchCandidates& prev = cands_[(count_ - 1) % history_];
    double best_all = -1e300;
    for (int j = 0; j < cur.count; ++j) {
      double best = -1e300;
      int arg = 0;
      for (int i = 0; i < prev.count; ++i) {
        const double v = delta_[i] - Transition(prev.c[i].f0_hz, cur.c[j].f0_hz);
        if (v > best) {
          best = v;
          arg = i;
        }
      }
      next_delta_[j] = best + local[j];
      back[j] = static_cast<uint8_t>(arg);
      best_all = std::max(best_all, next_delta_[j]);
    }
    // Keep the scores bounded on long streams.
    for (int j = 0; j < cur.count; ++j) delta_[j] = next_delta_[j] - best_all;
  }
  ++count_;
}

void PitchPath::TraceBack(int64_t first, std::span<float> f0_hz) const {
  if (count_ == 0) return;
  const int64_t last = count_ - 1;
  const PitchCandidates& lc = cands_[last % history_];
  int state = 0;
  for (int j = 1; j < lc.count; ++j) {
    if (delta_[j] > delta_[state]) state = j;
  }
  for (int64_t t = last; t >= first; --t) {
    const int64_t slot = t % history_;
    const PitchCandidates& c = cands_[slot];
    const float f = c.c[state].f0_hz;
    f0_hz[t - first] = Voiced(f) ? f : 0.0f;
    state = back_[slot * PitchCandidates::kMaxCandidates + state];
  }
}

float PitchPath::DecideLagged(int64_t lag) const {
  if (count_ == 0) return 0.0f;
  const int64_t last = count_ - 1;
  const int64_t target = std::max<int64_t>(0, last - lag);
  const PitchCandidates& lc = cands_[last % history_];
  int state = 0;
  for (int j = 1; j < lc.count; ++j) {
    if (delta_[j] > delta_[state]) state = j;
  }
  for (int64_t t = last; t > target; --t) {
    state = back_[(t % history_) * PitchCandidates::kMaxCandidates + state];
  }
  const float f = cands_[target % history_].c[state].f0_hz;
  return Voiced(f) ? f : 0.0f;
}

}  // namespace kinemo::prosody
