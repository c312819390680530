#include "services/inference/corpus/prosody_features.h"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace kinemo::inference {
namespace {

constexpr double kHopS = 0.01;
constexpr double kWindowS = 0.04;
constexpr double kSpeechRangeDb = 30.0;
constexpr double kTroughDb = 2.0;
constexpr double kMaxSilenceStepS = 0.5;

struct Frames {
  std::vector<double> intensity_db, f0_hz;
  std::vector<unsigned char> voiced;
};

Frames AnalyseFrames(std::span<const float> x, int rate) {
  // Decimate to ≤ 16 kHz by block averaging (enough for F0 ≤ 400 Hz).
  const int factor = std::max(1, rate / 16000);
  std::vector<double> y(x.size() / factor);
  for (size_t i = 0; i < y.size(); ++i) {
    double s = 0;
    for (int k = 0; k < factor; ++k) s += x[i * factor + k];
    y[i] = s / factor;
  }
  const double fs = static_cast<double>(rate) / factor;
  const int hop = std::max(1, static_cast<int>(std::lround(kHopS * fs)));
  const int win = static_cast<int>(std::lround(kWindowS * fs));
  const int min_lag = static_cast<int>(fs / 400.0), max_lag = std::min(win - 1, static_cast<int>(fs / 75.0));
  Frames f;
  if (static_cast<int>(y.size()) < win) return f;
  const int n = 1 + (static_cast<int>(y.size()) - win) / hop;
  f.intensity_db.resize(n);
  f.f0_hz.assign(n, 0.0);
  f.voiced.assign(n, 0);
  std::vector<double> seg(win);
  std::vector<double> r(max_lag + 2);
  for (int i = 0; i < n; ++i) {
    const double* p = y.data() + static_cast<size_t>(i) * hop;
    double mean = 0;
    for (int k = 0; k < win; ++k) mean += p[k];
    mean /= win;
    double energy = 0;
    for (int k = 0; k < win; ++k) {
      seg[k] = p[k] - mean;
      energy += seg[k] * seg[k];
    }
    f.intensity_db[i] = 10.0 * std::log10(energy / win + 1e-10);
    if (energy <= 0) continue;
    double best = 0;
    int best_lag = 0;
    for (int lag = min_lag; lag <= max_lag + 1 && lag < win; ++lag) {
      double c = 0, e1 = 0, e2 = 0;
      for (int k = 0; k + lag < win; ++k) {
        c += seg[k] * seg[k + lag];
        e1 += seg[k] * seg[k];
        e2 += seg[k + lag] * seg[k + lag];
      }
      r[lag] = c / std::sqrt(e1 * e2 + 1e-20);
    }
    for (int lag = min_lag + 1; lag <= max_lag; ++lag) {
      if (r[lag] > r[lag - 1] && r[lag] >= r[lag + 1] && r[lag] > best) {
        best = r[lag];
        best_lag = lag;
      }
    }
    if (best_lag > 0 && best >= 0.5) {
      const double a = r[best_lag - 1], b = r[best_lag], c = r[best_lag + 1];
      const double denom = a - 2 * b + c;
      const double shift = std::abs(denom) > 1e-12 ? 0.5 * (a - c) / denom : 0.0;
      f.f0_hz[i] = fs / (best_lag + std::clamp(shift, -0.5, 0.5));
      f.voiced[i] = 1;
    }
  }
  const double mx = *std::max_element(f.intensity_db.begin(), f.intensity_db.end());
  for (int i = 0; i < n; ++i) {
    if (f.intensity_db[i] < mx - kSpeechRangeDb) f.voiced[i] = 0;
  }
  // Octave-jump guard: frames more than ~0.8 octave from the recording's
  // median F0 are treated as unvoiced.
  std::vector<double> voiced_f0;
  for (int i = 0; i < n; ++i)
    if (f.voiced[i]) voiced_f0.push_back(f.f0_hz[i]);
  if (!voiced_f0.empty()) {
    std::nth_element(voiced_f0.begin(), voiced_f0.begin() + voiced_f0.size() / 2, voiced_f0.end());
    const double median = voiced_f0[voiced_f0.size() / 2];
    for (int i = 0; i < n; ++i) {
      if (f.voiced[i] && (f.f0_hz[i] > 1.7 * median || f.f0_hz[i] < 0.6 * median)) f.voiced[i] = 0;
    }
  }
  return f;
}

}  // namespace

StatusOr<ProsodyTrack> ExtractProsody(std::span<const float> samples, int rate) {
  if (rate < 4000) return InvalidField("sample_rate_hz", rate, " is below 4000");
  for (size_t i = 0; i < samples.size(); ++i) {
    if (!std::isfinite(samples[i])) return InvalidField(kinemo::StrCat("samples[", i, "]"), "not finite");
  }
  const Frames fr = AnalyseFrames(samples, rate);
  const int n = static_cast<int>(fr.intensity_db.size());
  if (n < 5) return InvalidField("samples", "shorter than 50 ms of audio");
  // Smoothed intensity (5-frame moving average).
  std::vector<double> sm(n);
  for (int i = 0; i < n; ++i) {
    double s = 0;
    int c = 0;
    for (int k = std::max(0, i - 2); k <= std::min(n - 1, i + 2); ++k, ++c) s += fr.intensity_db[k];
    sm[i] = s / c;
  }
  const double thr = *std::max_element(sm.begin(), sm.end()) - kSpeechRangeDb;
  std::vector<std::pair<int, int>> bounds;  // [begin, end) frame ranges of steps
  std::vector<unsigned char> is_speech_step;
  int i = 0;
  while (i < n) {
    const bool speech = sm[i] >= thr;
    int j = i;
    while (j < n && (sm[j] >= thr) == speech) ++j;
    if (!speech) {
      const int max_len = static_cast<int>(kMaxSilenceStepS / kHopS);
      for (int a = i; a < j; a += max_len) {
        bounds.emplace_back(a, std::min(j, a + max_len));
        is_speech_step.push_back(0);
      }
    } else {
      // Peaks inside the run, merged until troughs are deep enough.
      std::vector<int> peaks;
      for (int k = i; k < j; ++k) {
        const bool left = k == i || sm[k] >= sm[k - 1];
        const bool right = k == j - 1 || sm[k] > sm[k + 1];
        if (left && right) peaks.push_back(k);
      }
      if (peaks.empty()) peaks.push_back(i);
      auto trough = [&](int a, int b) {
        return static_cast<int>(std::min_element(sm.begin() + a, sm.begin() + b + 1) - sm.begin());
      };
      bool merged = true;
      while (merged && peaks.size() > 1) {
        merged = false;
        double worst = 1e9;
        size_t worst_k = 0;
        for (size_t k = 0; k + 1 < peaks.size(); ++k) {
          const double depth = std::min(sm[peaks[k]], sm[peaks[k + 1]]) - sm[trough(peaks[k], peaks[k + 1])];
          if (depth < worst) {
            worst = depth;
            worst_k = k;
          }
        }
        if (worst < kTroughDb) {
          // Drop the lower of the two peaks.
          const size_t drop = sm[peaks[worst_k]] < sm[peaks[worst_k + 1]] ? worst_k : worst_k + 1;
          peaks.erase(peaks.begin() + static_cast<long>(drop));
          merged = true;
        }
      }
      int start = i;
      for (size_t k = 0; k + 1 < peaks.size(); ++k) {
        const int t = trough(peaks[k], peaks[k + 1]);
        if (t > start) {
          bounds.emplace_back(start, t);
          is_speech_step.push_back(1);
          start = t;
        }
      }
      bounds.emplace_back(start, j);
      is_speech_step.push_back(1);
    }
    i = j;
  }
  ProsodyTrack track;
  std::vector<int> peak_frame;
  for (size_t k = 0; k < bounds.size(); ++k) {
    const auto [a, b] = bounds[k];
    ProsodyStep s;
    s.start_s = a * kHopS;
    s.end_s = b * kHopS + (b == n ? kWindowS - kHopS : 0.0);
    s.length_s = s.end_s - s.start_s;
    double isum = 0, fsum = 0;
    int voiced = 0;
    for (int f = a; f < b; ++f) {
      isum += fr.intensity_db[f];
      if (fr.voiced[f]) {
        fsum += fr.f0_hz[f];
        ++voiced;
      }
    }
    s.intensity_mean_db = isum / (b - a);
    s.voiced = is_speech_step[k] && voiced * 2 >= (b - a);
    s.f0_mean_hz = s.voiced ? fsum / voiced : 0.0;
    track.steps.push_back(s);
    peak_frame.push_back(static_cast<int>(std::max_element(sm.begin() + a, sm.begin() + b) - sm.begin()));
  }
  // Accents: z-scores within the recording over voiced steps.
  double mi = 0, mi2 = 0, mf = 0, mf2 = 0;
  int nv = 0;
  for (const auto& s : track.steps) {
    if (!s.voiced) continue;
    const double st = 12 * std::log2(s.f0_mean_hz / 100.0);
    mi += s.intensity_mean_db;
    mi2 += s.intensity_mean_db * s.intensity_mean_db;
    mf += st;
    mf2 += st * st;
    ++nv;
  }
  if (nv >= 2) {
    mi /= nv;
    mf /= nv;
    const double si = std::sqrt(std::max(1e-9, mi2 / nv - mi * mi));
    const double sf = std::sqrt(std::max(1e-9, mf2 / nv - mf * mf));
    std::vector<Accent> cand;
    for (size_t k = 0; k < track.steps.size(); ++k) {
      const auto& s = track.steps[k];
      if (!s.voiced) continue;
      const double z = (s.intensity_mean_db - mi) / si + (12 * std::log2(s.f0_mean_hz / 100.0) - mf) / sf;
      if (z > 0.5) cand.push_back({peak_frame[k] * kHopS + kWindowS / 2, z, static_cast<int>(k)});
    }
    std::sort(cand.begin(), cand.end(), [](const Accent& a, const Accent& b) { return a.strength > b.strength; });
    for (const auto& c : cand) {
      bool ok = true;
      for (const auto& a : track.accents) ok = ok && std::abs(a.time_s - c.time_s) >= 0.5;
      if (ok) track.accents.push_back(c);
    }
    std::sort(track.accents.begin(), track.accents.end(),
              [](const Accent& a, const Accent& b) { return a.time_s < b.time_s; });
  }
  return track;
}

}  // namespace kinemo::inference
