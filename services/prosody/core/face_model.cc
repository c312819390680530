#include "services/prosody/core/face_model.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <numbers>

namespace kinemo::prosody {
namespace {

constexpr int kWindow = 400;  // 25 ms at 16 kHz
constexpr int kHop = 160;     // 10 ms
constexpr int kFftSize = 512;
constexpr int kBands = 26;
constexpr int kCeps = 13;
constexpr float kPreEmphasis = 0.97f;
constexpr double kCmnTimeS = 3.0;
constexpr int kClasses = face::kNumPhoneClasses;

double HzToMel(double f) { return 1127.0 * std::log(1.0 + f / 700.0); }
double MelToHz(double m) { return 700.0 * (std::exp(m / 1127.0) - 1.0); }

// Stacked, normalised features of frame k (offsets clamped to [lo, hi]).
template <typename Get>
void StackFrame(const std::vector<int>& offsets, int64_t k, int64_t lo, int64_t hi, Get get, float* x) {
  for (std::size_t o = 0; o < offsets.size(); ++o) {
    const int64_t j = std::clamp<int64_t>(k + offsets[o], lo, hi);
    const float* f = get(j);
    std::copy(f, f + kFaceFeatureDims, x + o * kFaceFeatureDims);
  }
}

float Dot(const float* a, const float* b, int n) {
  float s = 0;
  for (int i = 0; i < n; ++i) s += a[i] * b[i];
  return s;
}

// Scores -> posteriors (softmax), in place.
void Softmax(std::array<double, kClasses>* s) {
  const double m = *std::max_element(s->begin(), s->end());
  double sum = 0;
  for (double& v : *s) sum += (v = std::exp(v - m));
  for (double& v : *s) v /= sum;
}

// One HMM step: alpha' = (stay alpha + (1 - stay)/C) * likelihood, normalised.
void Forward(double stay, const std::array<double, kClasses>& post, std::array<double, kClasses>* alpha) {
  double sum = 0;
  for (int c = 0; c < kClasses; ++c) {
    const double prior = stay * (*alpha)[c] + (1 - stay) / kClasses;
    (*alpha)[c] = prior * post[c];
    sum += (*alpha)[c];
  }
  for (double& a : *alpha) a = sum > 0 ? a / sum : 1.0 / kClasses;
}

constexpr int kBpm = static_cast<int>(face::PhoneClass::kBPM);

// Offline: every run of frames where B/P/M dominates, shorter than
// `min_frames`, widened on both sides to `min_frames` with its most closed
// frame's classes.
void HoldClosures(int min_frames, std::vector<SpeechFaceFrame>* frames) {
  if (min_frames <= 1) return;
  std::vector<SpeechFaceFrame>& f = *frames;
  const int64_t n = static_cast<int64_t>(f.size());
  int64_t k = 0;
  while (k < n) {
    if (face::Dominant(f[k].classes) != kBpm) {
      ++k;
      continue;
    }
    int64_t end = k, peak = k;
    for (; end < n && face::Dominant(f[end].classes) == kBpm; ++end) {
      if (f[end].classes[kBpm] > f[peak].classes[kBpm]) peak = end;
    }
    const int64_t missing = min_frames - (end - k);
    if (missing <= 0) {
      k = end;
      continue;
    }
    const auto closed = f[peak].classes;
    const int64_t from = std::max<int64_t>(0, k - missing / 2), to = std::min(n, end + (missing - missing / 2));
    for (int64_t j = from; j < to; ++j) f[j].classes = closed;
    k = to;
  }
}

}  // namespace

// ---- Features ---------------------------------------------------------------

FaceFeatureStream::FaceFeatureStream()
    : fft_(kFftSize),
      window_(kWindow),
      history_(),
      frame_(kFftSize, 0.0f),
      spectrum_(kFftSize / 2 + 1),
      work_(kFftSize / 2),
      power_(kFftSize / 2 + 1),
      dct_(kCeps * kBands) {
  for (int i = 0; i < kWindow; ++i) {
    window_[i] = static_cast<float>(0.54 - 0.46 * std::cos(2 * std::numbers::pi * i / (kWindow - 1)));
  }
  const double lo = HzToMel(60), hi = HzToMel(7600);
  std::vector<double> edge(kBands + 2);
  for (int i = 0; i < kBands + 2; ++i) edge[i] = MelToHz(lo + (hi - lo) * i / (kBands + 1));
  bands_.resize(kBands);
  for (int m = 0; m < kBands; ++m) {
    Band& b = bands_[m];
    b.first_bin = -1;
    for (int k = 0; k <= kFftSize / 2; ++k) {
      const double f = static_cast<double>(k) * kFaceSampleRateHz / kFftSize;
      double w = 0;
      if (f > edge[m] && f <= edge[m + 1]) w = (f - edge[m]) / (edge[m + 1] - edge[m]);
      else if (f > edge[m + 1] && f < edge[m + 2]) w = (edge[m + 2] - f) / (edge[m + 2] - edge[m + 1]);
      if (w <= 0) continue;
      if (b.first_bin < 0) b.first_bin = k;
      b.weights.resize(static_cast<std::size_t>(k - b.first_bin + 1), 0.0f);
      b.weights[static_cast<std::size_t>(k - b.first_bin)] = static_cast<float>(w);
    }
    if (b.first_bin < 0) b.first_bin = 0;
  }
  for (int q = 0; q < kCeps; ++q) {
    for (int m = 0; m < kBands; ++m) {
      dct_[q * kBands + m] = static_cast<float>(std::cos(std::numbers::pi * q * (m + 0.5) / kBands));
    }
  }
}

void FaceFeatureStream::Push(std::span<const float> samples, std::vector<float>* out) {
  // history_ holds samples [base_, base_ + size) of the stream, zeros before 0.
  history_.insert(history_.end(), samples.begin(), samples.end());
  received_ += static_cast<int64_t>(samples.size());
  // Frame k's window is the kWindow samples before sample k * kHop (exclusive).
  while (next_frame_ * kHop <= received_) {
    const int64_t end = next_frame_ * kHop;
    const int64_t first = end - kWindow - 1;  // one more, for the pre-emphasis
    auto at = [&](int64_t i) { return i < 0 ? 0.0f : history_[static_cast<std::size_t>(i - base_)]; };
    std::fill(frame_.begin(), frame_.end(), 0.0f);
    double energy = 1e-10;
    for (int i = 0; i < kWindow; ++i) {
      const float x = at(first + 1 + i), prev = at(first + i);
      frame_[i] = (x - kPreEmphasis * prev) * window_[i];
      energy += static_cast<double>(x) * x;
    }
    fft_.Forward(frame_, spectrum_, work_);
    for (int k = 0; k <= kFftSize / 2; ++k) power_[k] = std::norm(spectrum_[k]);
    float logmel[kBands];
    for (int m = 0; m < kBands; ++m) {
      const Band& b = bands_[m];
      double e = 1e-10;
      for (std::size_t i = 0; i < b.weights.size(); ++i) e += b.weights[i] * power_[b.first_bin + i];
      logmel[m] = static_cast<float>(std::log(e));
    }
    for (int q = 0; q < kCeps; ++q) out->push_back(Dot(dct_.data() + q * kBands, logmel, kBands));
    out->push_back(static_cast<float>(std::log(energy)));
    ++next_frame_;
  }
  // Keep what the next frame needs.
  const int64_t keep_from = std::max<int64_t>(0, next_frame_ * kHop - kWindow - 1);
  if (keep_from - base_ > 4096) {
    history_.erase(history_.begin(), history_.begin() + (keep_from - base_));
    base_ = keep_from;
  }
}

namespace {

// Every frame's features of a whole recording, frames 0 .. floor(n / hop).
std::vector<float> AllFeatures(std::span<const float> samples) {
  FaceFeatureStream s;
  std::vector<float> out;
  out.reserve((samples.size() / kHop + 2) * kFaceFeatureDims);
  // Frame 0's window ends before the first sample: all zeros (silence).
  s.Push(samples, &out);
  return out;
}

// In-place normalisation of a whole recording: its own mean, the model's scale.
void NormaliseOffline(std::vector<float>* f, const std::array<float, kFaceFeatureDims>& inv_sd) {
  const std::size_t n = f->size() / kFaceFeatureDims;
  if (n == 0) return;
  std::array<double, kFaceFeatureDims> mean{};
  for (std::size_t k = 0; k < n; ++k) {
    for (int q = 0; q < kFaceFeatureDims; ++q) mean[q] += (*f)[k * kFaceFeatureDims + q];
  }
  for (double& m : mean) m /= static_cast<double>(n);
  for (std::size_t k = 0; k < n; ++k) {
    for (int q = 0; q < kFaceFeatureDims; ++q) {
      float& v = (*f)[k * kFaceFeatureDims + q];
      v = static_cast<float>((v - mean[q]) * inv_sd[q]);
    }
  }
}

}  // namespace

// ---- Live ------------------------------------------------------------------

FaceStream::FaceStream(std::shared_ptr<const FaceModel> model) : model_(std::move(model)) {
  int min_offset = 0;
  for (int o : model_->live.offsets) min_offset = std::min(min_offset, o);
  span_ = 1 - min_offset;
  ring_.assign(static_cast<std::size_t>(span_) * kFaceFeatureDims, 0.0f);
  x_.resize(static_cast<std::size_t>(model_->live.dims()));
  cmn_ = model_->mean;
  alpha_.fill(1.0 / kClasses);
}

void FaceStream::Push(std::span<const float> samples, std::vector<SpeechFaceFrame>* out) {
  raw_.clear();
  features_.Push(samples, &raw_);
  const FaceHead& h = model_->live;
  const double cmn_rate = kFaceStepS / kCmnTimeS;
  for (std::size_t f = 0; f + kFaceFeatureDims <= raw_.size(); f += kFaceFeatureDims) {
    const int64_t k = frame_++;
    float* slot = ring_.data() + (k % span_) * kFaceFeatureDims;
    for (int q = 0; q < kFaceFeatureDims; ++q) {
      const float v = raw_[f + q];
      cmn_[q] = static_cast<float>(cmn_[q] + cmn_rate * (v - cmn_[q]));
      slot[q] = (v - cmn_[q]) * model_->inv_sd[q];
    }
    StackFrame(h.offsets, k, 0, k, [&](int64_t j) { return ring_.data() + (j % span_) * kFaceFeatureDims; }, x_.data());
    SpeechFaceFrame out_frame;
    out_frame.time_s = static_cast<double>(k) * kFaceStepS;
    const int d = h.dims();
    const float jaw = Dot(h.jaw_w.data(), x_.data(), d) + h.jaw_b;
    jaw_ = started_ ? jaw_ + model_->jaw_smooth * (jaw - jaw_) : jaw;
    std::array<double, kClasses> post;
    for (int c = 0; c < kClasses; ++c) post[c] = Dot(h.class_w.data() + c * d, x_.data(), d) + h.class_b[c];
    Softmax(&post);
    Forward(model_->stay, post, &alpha_);
    started_ = true;
    for (int c = 0; c < kClasses; ++c) out_frame.classes[c] = static_cast<float>(alpha_[c]);
    // A B/P/M closure is shown for at least live_min_closure_frames from its start.
    if (face::Dominant(out_frame.classes) == kBpm) {
      if (closure_frames_ == 0 || out_frame.classes[kBpm] >= closure_[kBpm]) closure_ = out_frame.classes;
      ++closure_frames_;
    } else if (closure_frames_ > 0 && closure_frames_ < model_->live_min_closure_frames) {
      out_frame.classes = closure_;
      ++closure_frames_;
    } else {
      closure_frames_ = 0;
    }
    float class_jaw = 0;
    for (int c = 0; c < kClasses; ++c) class_jaw += out_frame.classes[c] * model_->class_jaw[c];
    out_frame.jaw_open_deg = (1 - model_->class_jaw_mix) * jaw_ + model_->class_jaw_mix * class_jaw;
    out->push_back(out_frame);
  }
}

std::vector<SpeechFaceFrame> AnalyzeFaceLive(std::span<const float> samples, std::shared_ptr<const FaceModel> model,
                                             double chunk_s) {
  FaceStream s(std::move(model));
  std::vector<SpeechFaceFrame> out;
  const std::size_t chunk = std::max<std::size_t>(1, static_cast<std::size_t>(chunk_s * kFaceSampleRateHz));
  s.Push({}, &out);
  for (std::size_t i = 0; i < samples.size(); i += chunk) {
    s.Push(samples.subspan(i, std::min(chunk, samples.size() - i)), &out);
  }
  return out;
}

// ---- Offline ----------------------------------------------------------------

std::vector<SpeechFaceFrame> AnalyzeFace(std::span<const float> samples, const FaceModel& model,
                                         std::span<const FacePhone> phones, double phone_weight,
                                         double phone_delay_s) {
  return AnalyzeFaceFeatures(AllFeatures(samples), model, phones, phone_weight, phone_delay_s);
}

std::vector<float> OfflineFaceFeatures(std::span<const float> samples) { return AllFeatures(samples); }

std::vector<SpeechFaceFrame> AnalyzeFaceFeatures(std::vector<float> f, const FaceModel& model,
                                                 std::span<const FacePhone> phones, double phone_weight,
                                                 double phone_delay_s) {
  NormaliseOffline(&f, model.inv_sd);
  const int64_t n = static_cast<int64_t>(f.size() / kFaceFeatureDims);
  const FaceHead& h = model.offline;
  const int d = h.dims();
  std::vector<float> x(static_cast<std::size_t>(d));
  std::vector<SpeechFaceFrame> out(static_cast<std::size_t>(n));
  std::vector<std::array<double, kClasses>> post(static_cast<std::size_t>(n)), alpha(static_cast<std::size_t>(n));
  for (int64_t k = 0; k < n; ++k) {
    StackFrame(h.offsets, k, 0, n - 1, [&](int64_t j) { return f.data() + j * kFaceFeatureDims; }, x.data());
    out[k].time_s = static_cast<double>(k) * kFaceStepS;
    out[k].jaw_open_deg = Dot(h.jaw_w.data(), x.data(), d) + h.jaw_b;
    for (int c = 0; c < kClasses; ++c) post[k][c] = Dot(h.class_w.data() + c * d, x.data(), d) + h.class_b[c];
    Softmax(&post[k]);
  }
  // The recogniser's phones as a second opinion.
  if (!phones.empty() && phone_weight != 1) {
    std::size_t p = 0;
    for (int64_t k = 0; k < n; ++k) {
      const double t = static_cast<double>(k) * kFaceStepS - phone_delay_s;
      while (p < phones.size() && phones[p].end_s <= t) ++p;
      face::PhoneClass c = face::PhoneClass::kSil;
      if (p < phones.size() && phones[p].start_s <= t) (void)face::PhoneToClass(phones[p].phone, &c);
      post[k][static_cast<int>(c)] *= phone_weight;
      double sum = 0;
      for (double v : post[k]) sum += v;
      for (double& v : post[k]) v /= sum;
    }
  }
  // Forward-backward over the sticky HMM.
  std::array<double, kClasses> a;
  a.fill(1.0 / kClasses);
  for (int64_t k = 0; k < n; ++k) {
    Forward(model.stay, post[k], &a);
    alpha[k] = a;
  }
  std::array<double, kClasses> beta;
  beta.fill(1.0);
  for (int64_t k = n - 1; k >= 0; --k) {
    double sum = 0;
    std::array<double, kClasses> g;
    for (int c = 0; c < kClasses; ++c) sum += (g[c] = alpha[k][c] * beta[c]);
    for (int c = 0; c < kClasses; ++c) out[k].classes[c] = static_cast<float>(sum > 0 ? g[c] / sum : 1.0 / kClasses);
    // beta_{k-1}(i) = sum_j T(i, j) post_k(j) beta_k(j), T = stay I + (1 - stay)/C.
    double mix = 0;
    for (int c = 0; c < kClasses; ++c) mix += post[k][c] * beta[c];
    double norm = 0;
    for (int c = 0; c < kClasses; ++c) {
      beta[c] = model.stay * post[k][c] * beta[c] + (1 - model.stay) / kClasses * mix;
      norm += beta[c];
    }
    for (double& b : beta) b = norm > 0 ? b / norm : 1.0;
  }
  HoldClosures(model.min_closure_frames, &out);
  if (model.class_jaw_mix > 0) {
    for (SpeechFaceFrame& f : out) {
      float class_jaw = 0;
      for (int c = 0; c < kClasses; ++c) class_jaw += f.classes[c] * model.class_jaw[c];
      f.jaw_open_deg = (1 - model.class_jaw_mix) * f.jaw_open_deg + model.class_jaw_mix * class_jaw;
    }
  }
  return out;
}

// ---- Training ---------------------------------------------------------------

StatusOr<FaceModel> TrainFaceModel(std::span<const FaceTrainingTake> takes, const FaceTrainOptions& options) {
  if (takes.empty()) return absl::InvalidArgumentError("takes: none");
  struct Prepared {
    std::vector<float> f;   // normalised later
    std::vector<float> live_f;  // normalised as the live stream does (live_running_cmn)
    std::vector<int> label;
    std::vector<double> jaw;  // NaN = no jaw at this frame
  };
  std::vector<Prepared> prep(takes.size());
  std::array<double, kFaceFeatureDims> mean{}, var{};
  double frames_total = 0, training_s = 0;
  for (std::size_t t = 0; t < takes.size(); ++t) {
    const FaceTrainingTake& take = takes[t];
    const std::string field = kinemo::StrCat("takes[", t, "] (", take.name, ")");
    if (take.samples.size() < static_cast<std::size_t>(kFaceSampleRateHz)) return InvalidField(field, "under 1 s of audio");
    if (take.jaw_open_deg.empty()) return InvalidField(field, "no jaw frames");
    if (take.phones.empty()) return InvalidField(field, "no phones");
    if (!(take.jaw_frame_time_s > 0)) return InvalidField(field, "jaw_frame_time_s must be > 0");
    training_s += static_cast<double>(take.samples.size()) / kFaceSampleRateHz;
    Prepared& p = prep[t];
    p.f = AllFeatures(take.samples);
    if (options.live_running_cmn) p.live_f = p.f;
    const int64_t n = static_cast<int64_t>(p.f.size() / kFaceFeatureDims);
    // Per-take mean removal (as offline analysis does).
    std::array<double, kFaceFeatureDims> m{};
    for (int64_t k = 0; k < n; ++k) {
      for (int q = 0; q < kFaceFeatureDims; ++q) m[q] += p.f[k * kFaceFeatureDims + q];
    }
    for (int q = 0; q < kFaceFeatureDims; ++q) {
      m[q] /= static_cast<double>(n);
      mean[q] += m[q] * static_cast<double>(n);
    }
    for (int64_t k = 0; k < n; ++k) {
      for (int q = 0; q < kFaceFeatureDims; ++q) {
        float& v = p.f[k * kFaceFeatureDims + q];
        v = static_cast<float>(v - m[q]);
        var[q] += static_cast<double>(v) * v;
      }
    }
    frames_total += static_cast<double>(n);
    p.label.assign(static_cast<std::size_t>(n), 0);
    std::size_t pi = 0;
    for (int64_t k = 0; k < n; ++k) {
      const double t_s = static_cast<double>(k) * kFaceStepS;
      while (pi < take.phones.size() && take.phones[pi].end_s <= t_s) ++pi;
      face::PhoneClass c = face::PhoneClass::kSil;
      if (pi < take.phones.size() && take.phones[pi].start_s <= t_s) (void)face::PhoneToClass(take.phones[pi].phone, &c);
      p.label[k] = static_cast<int>(c);
    }
    p.jaw.assign(static_cast<std::size_t>(n), std::nan(""));
    const double last = static_cast<double>(take.jaw_open_deg.size() - 1) * take.jaw_frame_time_s;
    for (int64_t k = 0; k < n; ++k) {
      const double t_s = static_cast<double>(k) * kFaceStepS;
      if (t_s > last) break;
      const double pos = t_s / take.jaw_frame_time_s;
      const std::size_t i = static_cast<std::size_t>(pos);
      const double a = pos - static_cast<double>(i);
      const double v0 = take.jaw_open_deg[i];
      const double v1 = i + 1 < take.jaw_open_deg.size() ? take.jaw_open_deg[i + 1] : v0;
      p.jaw[k] = v0 * (1 - a) + v1 * a;
    }
  }
  FaceModel model;
  for (int q = 0; q < kFaceFeatureDims; ++q) {
    model.mean[q] = static_cast<float>(mean[q] / frames_total);
    model.inv_sd[q] = static_cast<float>(1.0 / std::sqrt(var[q] / frames_total + 1e-12));
  }
  for (Prepared& p : prep) {
    for (std::size_t i = 0; i < p.f.size(); ++i) p.f[i] *= model.inv_sd[i % kFaceFeatureDims];
    if (options.live_running_cmn) {
      // What FaceStream does: a running mean from the training mean on.
      std::array<float, kFaceFeatureDims> cmn = model.mean;
      const double rate = kFaceStepS / kCmnTimeS;
      for (std::size_t i = 0; i < p.live_f.size(); ++i) {
        const int q = static_cast<int>(i % kFaceFeatureDims);
        const float v = p.live_f[i];
        cmn[q] = static_cast<float>(cmn[q] + rate * (v - cmn[q]));
        p.live_f[i] = (v - cmn[q]) * model.inv_sd[q];
      }
    }
  }
  auto train_head = [&](const std::vector<int>& offsets, bool live, FaceHead* head) {
    auto feats = [&](const Prepared& p) -> const std::vector<float>& { return live && options.live_running_cmn ? p.live_f : p.f; };
    head->offsets = offsets;
    const int d = head->dims();
    Eigen::MatrixXd xtx = Eigen::MatrixXd::Zero(d + 1, d + 1);
    Eigen::VectorXd xty = Eigen::VectorXd::Zero(d + 1);
    std::vector<Eigen::VectorXd> sum(kClasses, Eigen::VectorXd::Zero(d));
    std::vector<double> count(kClasses, 0);
    Eigen::MatrixXd scatter = Eigen::MatrixXd::Zero(d, d);
    std::vector<float> x(static_cast<std::size_t>(d));
    Eigen::VectorXd xe(d + 1);
    double n_all = 0;
    // Pass 1: ridge sums and class sums.
    for (const Prepared& p : prep) {
      const int64_t n = static_cast<int64_t>(p.label.size());
      for (int64_t k = 0; k < n; ++k) {
        StackFrame(offsets, k, 0, n - 1, [&](int64_t j) { return feats(p).data() + j * kFaceFeatureDims; }, x.data());
        for (int i = 0; i < d; ++i) xe[i] = x[i];
        xe[d] = 1;
        if (!std::isnan(p.jaw[k])) {
          xtx.selfadjointView<Eigen::Lower>().rankUpdate(xe);
          xty += xe * p.jaw[k];
        }
        sum[p.label[k]] += xe.head(d);
        count[p.label[k]] += 1;
        n_all += 1;
      }
    }
    Eigen::MatrixXd a = xtx.selfadjointView<Eigen::Lower>();
    for (int i = 0; i < d; ++i) a(i, i) += options.jaw_ridge;
    const Eigen::VectorXd w = a.ldlt().solve(xty);
    head->jaw_w.resize(static_cast<std::size_t>(d));
    for (int i = 0; i < d; ++i) head->jaw_w[i] = static_cast<float>(w[i]);
    head->jaw_b = static_cast<float>(w[d]);
    // Pass 2: within-class scatter.
    std::vector<Eigen::VectorXd> mu(kClasses);
    for (int c = 0; c < kClasses; ++c) mu[c] = count[c] > 0 ? Eigen::VectorXd(sum[c] / count[c]) : Eigen::VectorXd::Zero(d);
    for (const Prepared& p : prep) {
      const int64_t n = static_cast<int64_t>(p.label.size());
      for (int64_t k = 0; k < n; ++k) {
        StackFrame(offsets, k, 0, n - 1, [&](int64_t j) { return feats(p).data() + j * kFaceFeatureDims; }, x.data());
        for (int i = 0; i < d; ++i) xe[i] = x[i] - mu[p.label[k]][i];
        scatter.selfadjointView<Eigen::Lower>().rankUpdate(xe.head(d));
      }
    }
    Eigen::MatrixXd cov = scatter.selfadjointView<Eigen::Lower>();
    cov /= n_all;
    const double mean_var = cov.diagonal().mean();
    cov *= 1 - options.class_shrink;
    cov.diagonal().array() += options.class_shrink * mean_var;
    const Eigen::LDLT<Eigen::MatrixXd> ldlt(cov);
    head->class_w.assign(static_cast<std::size_t>(kClasses) * d, 0.0f);
    for (int c = 0; c < kClasses; ++c) {
      if (count[c] == 0) {
        head->class_b[c] = -1e4f;  // never seen: never chosen
        continue;
      }
      const Eigen::VectorXd s = ldlt.solve(mu[c]);
      const double scale = options.score_scale;
      for (int i = 0; i < d; ++i) head->class_w[c * d + i] = static_cast<float>(scale * s[i]);
      head->class_b[c] = static_cast<float>(
          scale * (-0.5 * mu[c].dot(s) + (1 - (c == kBpm ? options.bpm_prior_power : options.prior_power)) * std::log(count[c] / n_all)));
    }
  };
  {
    std::array<double, kClasses> sum{}, count{};
    for (const Prepared& p : prep) {
      for (std::size_t k = 0; k < p.label.size(); ++k) {
        if (std::isnan(p.jaw[k])) continue;
        sum[p.label[k]] += p.jaw[k];
        count[p.label[k]] += 1;
      }
    }
    double all = 0, n = 0;
    for (int c = 0; c < kClasses; ++c) all += sum[c], n += count[c];
    for (int c = 0; c < kClasses; ++c) {
      model.class_jaw[c] = static_cast<float>(count[c] > 0 ? sum[c] / count[c] : (n > 0 ? all / n : 0.0));
    }
    model.class_jaw_mix = static_cast<float>(options.class_jaw_mix);
    model.min_closure_frames = static_cast<int>(std::lround(std::clamp(options.min_closure_s, 0.0, 0.5) / kFaceStepS));
    model.live_min_closure_frames =
        static_cast<int>(std::lround(std::clamp(options.live_min_closure_s, 0.0, 0.5) / kFaceStepS));
  }
  train_head(options.live_offsets, true, &model.live);
  train_head(options.offline_offsets, false, &model.offline);
  model.stay = static_cast<float>(options.stay);
  model.jaw_smooth = static_cast<float>(options.jaw_smooth);
  model.training_s = training_s;
  return model;
}

// ---- Files --------------------------------------------------------------------

namespace {

nlohmann::json HeadJson(const FaceHead& h) {
  return {{"offsets", h.offsets}, {"jaw_w", h.jaw_w},     {"jaw_b", h.jaw_b},
          {"class_w", h.class_w}, {"class_b", h.class_b}};
}

template <typename T>
Status ReadFloats(const nlohmann::json& j, const char* key, std::size_t count, const std::string& prefix, T* out) {
  const auto it = j.find(key);
  if (it == j.end() || !it->is_array() || it->size() != count) {
    return InvalidField(kinemo::StrCat(prefix, key), "must be a list of ", count, " numbers");
  }
  for (std::size_t i = 0; i < count; ++i) {
    const nlohmann::json& v = (*it)[i];
    if (!v.is_number() || !std::isfinite(v.get<double>())) {
      return InvalidField(kinemo::StrCat(prefix, key, "[", i, "]"), "must be a finite number");
    }
    (*out)[i] = static_cast<float>(v.get<double>());
  }
  return absl::OkStatus();
}

Status ReadHead(const nlohmann::json& j, const char* key, FaceHead* h) {
  const auto it = j.find(key);
  const std::string prefix = kinemo::StrCat(key, ".");
  if (it == j.end() || !it->is_object()) return InvalidField(key, "missing");
  const auto off = it->find("offsets");
  if (off == it->end() || !off->is_array() || off->empty() || off->size() > 64) {
    return InvalidField(prefix + "offsets", "must be a list of 1..64 frame offsets");
  }
  for (std::size_t i = 0; i < off->size(); ++i) {
    const nlohmann::json& v = (*off)[i];
    if (!v.is_number_integer() || v.get<int64_t>() < -200 || v.get<int64_t>() > 200) {
      return InvalidField(kinemo::StrCat(prefix, "offsets[", i, "]"), "must be an integer in -200..200");
    }
    h->offsets.push_back(static_cast<int>(v.get<int64_t>()));
  }
  const std::size_t d = static_cast<std::size_t>(h->dims());
  h->jaw_w.resize(d);
  h->class_w.resize(d * kClasses);
  KINEMO_RETURN_IF_ERROR(ReadFloats(*it, "jaw_w", d, prefix, &h->jaw_w));
  KINEMO_RETURN_IF_ERROR(ReadFloats(*it, "class_w", d * kClasses, prefix, &h->class_w));
  KINEMO_RETURN_IF_ERROR(ReadFloats(*it, "class_b", kClasses, prefix, &h->class_b));
  std::array<float, 1> b{};
  const nlohmann::json wrapped = {{"jaw_b", nlohmann::json::array({it->value("jaw_b", nlohmann::json())})}};
  KINEMO_RETURN_IF_ERROR(ReadFloats(wrapped, "jaw_b", 1, prefix, &b));
  h->jaw_b = b[0];
  return absl::OkStatus();
}

}  // namespace

std::string FaceModelToJson(const FaceModel& m) {
  nlohmann::json j = {{"format", "kinemo-face-model"},
                      {"version", FaceModel::kFormatVersion},
                      {"mean", m.mean},
                      {"inv_sd", m.inv_sd},
                      {"live", HeadJson(m.live)},
                      {"offline", HeadJson(m.offline)},
                      {"stay", m.stay},
                      {"jaw_smooth", m.jaw_smooth},
                      {"class_jaw", m.class_jaw},
                      {"class_jaw_mix", m.class_jaw_mix},
                      {"min_closure_frames", m.min_closure_frames},
                      {"live_min_closure_frames", m.live_min_closure_frames},
                      {"training_s", m.training_s},
                      {"description", m.description},
                      {"classes", face::kPhoneClassNames}};
  return j.dump();
}

StatusOr<FaceModel> FaceModelFromJson(std::string_view text, std::string_view name) {
  auto parse = [&]() -> StatusOr<FaceModel> {
    const nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
    if (j.is_discarded() || !j.is_object()) return absl::InvalidArgumentError("not a JSON object");
    if (j.value("format", "") != "kinemo-face-model") return InvalidField("format", "not a kinemo face model");
    if (!j.contains("version") || !j["version"].is_number_integer() || j["version"].get<int64_t>() != FaceModel::kFormatVersion) {
      return InvalidField("version", "must be ", FaceModel::kFormatVersion);
    }
    FaceModel m;
    KINEMO_RETURN_IF_ERROR(ReadFloats(j, "mean", kFaceFeatureDims, "", &m.mean));
    KINEMO_RETURN_IF_ERROR(ReadFloats(j, "inv_sd", kFaceFeatureDims, "", &m.inv_sd));
    KINEMO_RETURN_IF_ERROR(ReadHead(j, "live", &m.live));
    KINEMO_RETURN_IF_ERROR(ReadHead(j, "offline", &m.offline));
    std::array<float, 2> p{};
    const nlohmann::json both = {{"p", nlohmann::json::array({j.value("stay", nlohmann::json()), j.value("jaw_smooth", nlohmann::json())})}};
    KINEMO_RETURN_IF_ERROR(ReadFloats(both, "p", 2, "stay/jaw_smooth ", &p));
    if (!(p[0] >= 0 && p[0] < 1)) return InvalidField("stay", "must be in [0, 1)");
    if (!(p[1] > 0 && p[1] <= 1)) return InvalidField("jaw_smooth", "must be in (0, 1]");
    m.stay = p[0];
    m.jaw_smooth = p[1];
    if (j.contains("class_jaw")) {
      KINEMO_RETURN_IF_ERROR(ReadFloats(j, "class_jaw", kClasses, "", &m.class_jaw));
      std::array<float, 1> mix{};
      const nlohmann::json wrapped = {{"class_jaw_mix", nlohmann::json::array({j.value("class_jaw_mix", nlohmann::json())})}};
      KINEMO_RETURN_IF_ERROR(ReadFloats(wrapped, "class_jaw_mix", 1, "", &mix));
      if (!(mix[0] >= 0 && mix[0] <= 1)) return InvalidField("class_jaw_mix", "must be in [0, 1]");
      m.class_jaw_mix = mix[0];
    }
    // Older files hold one value for both.
    for (const char* key : {"min_closure_frames", "live_min_closure_frames"}) {
      if (!j.contains(key)) continue;
      const nlohmann::json& v = j[key];
      if (!v.is_number_integer() || v.get<int64_t>() < 0 || v.get<int64_t>() > 50) {
        return InvalidField(key, "must be an integer in 0..50");
      }
      const int frames = static_cast<int>(v.get<int64_t>());
      if (std::string_view(key) == "min_closure_frames") {
        m.min_closure_frames = m.live_min_closure_frames = frames;
      } else {
        m.live_min_closure_frames = frames;
      }
    }
    if (j.contains("training_s") && j["training_s"].is_number()) m.training_s = j["training_s"].get<double>();
    if (j.contains("description") && j["description"].is_string()) m.description = j["description"].get<std::string>();
    return m;
  };
  auto m = parse();
  if (!m.ok()) return Annotate(m.status(), name);
  return m;
}

}  // namespace kinemo::prosody
