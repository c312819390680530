// AudioOnsets(): librosa.onset.onset_detect with librosa 0.10's defaults, as
// BEAT / EMAGE call it for their beat consistency (docs/evaluation.md).
#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <numbers>

#include "common/evaluation/motion_compare.h"
#include "services/prosody/core/fft.h"

namespace kinemo::evaluation {
namespace {

constexpr int kOnsetFft = 2048;
constexpr int kOnsetHop = 512;
constexpr int kOnsetMels = 128;

// librosa.hz_to_mel / mel_to_hz with htk=False (Slaney's scale: linear below
// 1 kHz, logarithmic above).
double SlaneyMel(double hz) {
  constexpr double f_sp = 200.0 / 3, min_log_hz = 1000, min_log_mel = min_log_hz / f_sp;
  const double logstep = std::log(6.4) / 27;
  return hz >= min_log_hz ? min_log_mel + std::log(hz / min_log_hz) / logstep : hz / f_sp;
}
double SlaneyHz(double mel) {
  constexpr double f_sp = 200.0 / 3, min_log_hz = 1000, min_log_mel = min_log_hz / f_sp;
  const double logstep = std::log(6.4) / 27;
  return mel >= min_log_mel ? min_log_hz * std::exp(logstep * (mel - min_log_mel)) : f_sp * mel;
}

// librosa.filters.mel(sr, n_fft, n_mels, fmin=0, fmax=sr/2, htk=False,
// norm="slaney"): n_mels × (n_fft/2 + 1).
Eigen::MatrixXd MelFilters(int sr) {
  const int bins = kOnsetFft / 2 + 1;
  std::vector<double> fft_hz(static_cast<size_t>(bins));
  for (int k = 0; k < bins; ++k) fft_hz[static_cast<size_t>(k)] = k * (sr / 2.0) / (bins - 1);
  std::vector<double> mel_hz(kOnsetMels + 2);
  const double lo = SlaneyMel(0), hi = SlaneyMel(sr / 2.0);
  for (int i = 0; i < kOnsetMels + 2; ++i) {
    mel_hz[static_cast<size_t>(i)] = SlaneyHz(lo + (hi - lo) * i / (kOnsetMels + 1));
  }
  Eigen::MatrixXd w = Eigen::MatrixXd::Zero(kOnsetMels, bins);
  for (int i = 0; i < kOnsetMels; ++i) {
    const auto u = static_cast<size_t>(i);
    const double d0 = mel_hz[u + 1] - mel_hz[u], d1 = mel_hz[u + 2] - mel_hz[u + 1];
    const double norm = 2.0 / (mel_hz[u + 2] - mel_hz[u]);
    for (int k = 0; k < bins; ++k) {
      const double f = fft_hz[static_cast<size_t>(k)];
      const double lower = (f - mel_hz[u]) / d0, upper = (mel_hz[u + 2] - f) / d1;
      w(i, k) = std::max(0.0, std::min(lower, upper)) * norm;
    }
  }
  return w;
}

}  // namespace

StatusOr<std::vector<double>> AudioOnsets(std::span<const float> y, int sr) {
  if (sr < 1000 || sr > 384000) return InvalidField("sample_rate_hz", sr, " must be in [1000, 384000]");
  const int len = static_cast<int>(y.size());
  std::vector<double> out;
  if (len < 1) return out;
  // STFT, centred (n_fft/2 zeros on each side: librosa 0.10's pad_mode
  // "constant"), periodic Hann window, power.
  const int frames = 1 + len / kOnsetHop;
  const Eigen::MatrixXd mel = MelFilters(sr);
  const prosody::RealFft fft(kOnsetFft);
  std::vector<float> window(kOnsetFft), buf(kOnsetFft);
  for (int i = 0; i < kOnsetFft; ++i) {
    window[static_cast<size_t>(i)] = static_cast<float>(0.5 - 0.5 * std::cos(2 * std::numbers::pi * i / kOnsetFft));
  }
  std::vector<std::complex<float>> spec(kOnsetFft / 2 + 1), work(kOnsetFft / 2);
  Eigen::MatrixXd db(kOnsetMels, frames);
  Eigen::VectorXd power(kOnsetFft / 2 + 1);
  for (int t = 0; t < frames; ++t) {
    const int start = t * kOnsetHop - kOnsetFft / 2;
    for (int i = 0; i < kOnsetFft; ++i) {
      const int s = start + i;
      buf[static_cast<size_t>(i)] = s >= 0 && s < len ? y[static_cast<size_t>(s)] * window[static_cast<size_t>(i)] : 0.0f;
    }
    fft.Forward(buf, spec, work);
    for (int k = 0; k <= kOnsetFft / 2; ++k) power(k) = std::norm(spec[static_cast<size_t>(k)]);
    db.col(t) = mel * power;
  }
  // power_to_db(ref=1, amin=1e-10, top_db=80).
  db = (db.array().max(1e-10).log10() * 10).matrix();
  db = db.array().max(db.maxCoeff() - 80).matrix();
  // Onset strength: mean over bands of the positive difference with the
  // previous frame (lag 1), shifted right by lag + n_fft / (2 hop) = 3
  // frames (librosa's centring), cut to the frame count.
  const int pad = 1 + kOnsetFft / (2 * kOnsetHop);
  std::vector<double> env(static_cast<size_t>(frames), 0.0);
  for (int j = 0; j + 1 < frames; ++j) {
    const int k = j + pad;
    if (k >= frames) break;
    env[static_cast<size_t>(k)] = (db.col(j + 1) - db.col(j)).cwiseMax(0.0).mean();
  }
  // onset_detect: normalise to [0, 1], then peak_pick with pre_max = 0.03 sr
  // // hop, post_max = 1, pre_avg = 0.1 sr // hop, post_avg = pre_avg + 1,
  // wait = 0.03 sr // hop, delta = 0.07.
  const double lo = *std::min_element(env.begin(), env.end());
  for (double& e : env) e -= lo;
  const double hi = *std::max_element(env.begin(), env.end());
  if (!(hi > 0)) return out;
  for (double& e : env) e /= hi + std::numeric_limits<double>::min();
  const double rate = static_cast<double>(sr) / kOnsetHop;
  const int pre_max = static_cast<int>(std::floor(0.03 * sr / kOnsetHop));
  const int post_max = 1;
  const int pre_avg = static_cast<int>(std::floor(0.10 * sr / kOnsetHop));
  const int post_avg = pre_avg + 1;
  const int wait = pre_max;
  const double delta = 0.07;
  for (int n = 0; n < frames; ++n) {
    const auto un = static_cast<size_t>(n);
    double mx = -std::numeric_limits<double>::infinity();
    for (int i = std::max(0, n - pre_max); i < std::min(frames, n + post_max); ++i) mx = std::max(mx, env[static_cast<size_t>(i)]);
    if (env[un] != mx) continue;
    double avg = 0;
    int c = 0;
    for (int i = std::max(0, n - pre_avg); i < std::min(frames, n + post_avg); ++i, ++c) avg += env[static_cast<size_t>(i)];
    if (!(env[un] > 0) || env[un] < avg / c + delta) continue;
    out.push_back(n / rate);
    n += wait;
  }
  return out;
}

}  // namespace kinemo::evaluation
