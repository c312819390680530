#include "services/prosody/core/intensity.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace kinemo::prosody {
namespace {

// Modified Bessel function of the first kind, order 0 (power series).
double BesselI0(double x) {
  double sum = 1, term = 1;
  const double q = 0.25 * x * x;
  for (int k = 1; k < 200; ++k) {
    term *= q / (static_cast<double>(k) * k);
    sum += term;
    if (term < sum * 1e-17) break;
  }
  return sum;
}

}  // namespace

IntensityAnalyzer::IntensityAnalyzer(double min_pitch_hz, bool subtract_mean,
                                     double sample_rate_hz)
    : rate_(sample_rate_hz), subtract_mean_(subtract_mean) {
  const double half_duration = 3.2 / min_pitch_hz;  // half of the 6.4 / f total length
  half_ = static_cast<int64_t>(std::floor(half_duration * sample_rate_hz));
  weights_.resize(2 * half_ + 1);
  const double beta = 2 * std::numbers::pi * std::numbers::pi + 0.5;  // "Kaiser-20"
  for (int64_t i = -half_; i <= half_; ++i) {
    const double x = static_cast<double>(i) / sample_rate_hz / half_duration;
    const double root = 1 - x * x;
    weights_[i + half_] = root <= 0 ? 0.0 : BesselI0(beta * std::sqrt(root));
  }
}

double IntensityAnalyzer::Analyze(std::span<const float> samples, int64_t first_index,
                                  int64_t signal_end, double time_s) const {
  const int64_t centre = static_cast<int64_t>(std::llround(time_s * rate_ - 0.5));
  const int64_t lo = std::max({centre - half_, first_index, int64_t{0}});
  const int64_t hi = std::min({centre + half_, first_index + static_cast<int64_t>(samples.size()) - 1,
                               signal_end - 1});
  if (hi < lo) return kSilenceDb;
  const float* x = samples.data() + (lo - first_index);
  const double* w = weights_.data() + (lo - centre + half_);
  const int64_t n = hi - lo + 1;
  double mean = 0;
  if (subtract_mean_) {
    for (int64_t i = 0; i < n; ++i) mean += x[i];
    mean /= static_cast<double>(n);
  }
  double sumw = 0, sumxw = 0;
  for (int64_t i = 0; i < n; ++i) {
    const double d = x[i] - mean;
    sumxw += d * d * w[i];
    sumw += w[i];
  }
  if (!(sumw > 0) || !(sumxw > 0)) return kSilenceDb;
  const double power = sumxw / sumw;
  return std::max(kSilenceDb, 10.0 * std::log10(power / 4.0e-10));
}

}  // namespace kinemo::prosody
