#include "common/face/face_compose.h"

#include <algorithm>
#include <cmath>

namespace kinemo::face {
namespace {

constexpr double kSpeechStepS = 0.01;
constexpr double kExpressionRampS = 0.3;
constexpr double kBrowRiseS = 0.15, kBrowHoldS = 0.1, kBrowFallS = 0.4;

// The first and last times an accent touches a frame: its brows (from
// kBrowRiseS before it to kBrowHoldS + kBrowFallS after) and its emphasis
// (its syllable, or 0.1 s either side without one).
double AccentFromS(const FaceAccent& a) {
  const bool span = a.syllable_end_s > a.syllable_start_s;
  return span ? std::min(a.time_s - kBrowRiseS, a.syllable_start_s) : a.time_s - kBrowRiseS;
}
double AccentUntilS(const FaceAccent& a) {
  const bool span = a.syllable_end_s > a.syllable_start_s;
  return span ? std::max(a.time_s + kBrowHoldS + kBrowFallS, a.syllable_end_s) : a.time_s + kBrowHoldS + kBrowFallS;
}

bool IsVowelClass(int c) {
  switch (static_cast<PhoneClass>(c)) {
    case PhoneClass::kAA:
    case PhoneClass::kAO:
    case PhoneClass::kIY:
    case PhoneClass::kOW:
    case PhoneClass::kEY:
    case PhoneClass::kER:
    case PhoneClass::kWUW:
      return true;
    default:
      return false;
  }
}

}  // namespace

Expression ExpressionForTone(std::string_view tone) {
  if (tone == "happy") return Expression::kHappy;
  if (tone == "angry") return Expression::kAngry;
  if (tone == "energetic") return Expression::kSurprised;
  if (tone == "subdued") return Expression::kSad;
  return Expression::kNeutral;
}

FaceComposer::FaceComposer(const ComposeOptions& options) : o_(options), rng_(options.seed * 0x9E3779B97F4A7C15ull + 1) {}

void FaceComposer::AddSpeech(const SpeechFaceFrame& frame) { speech_.push_back(frame); }

void FaceComposer::AddAccent(const FaceAccent& accent) {
  if (first_accent_ < accents_.size() && AccentFromS(accent) < AccentFromS(accents_.back())) accents_ordered_ = false;
  accents_.push_back(accent);
}

void FaceComposer::SetExpression(double time_s, Expression expression, float weight) {
  expressions_.push_back({time_s, expression, std::clamp(weight, 0.0f, 1.0f)});
}

double FaceComposer::NextUniform() {
  // xorshift64*: deterministic, the same blinks for the same speech.
  rng_ ^= rng_ >> 12;
  rng_ ^= rng_ << 25;
  rng_ ^= rng_ >> 27;
  return static_cast<double>((rng_ * 0x2545F4914F6CDD1Dull) >> 11) * (1.0 / 9007199254740992.0);
}

SpeechFaceFrame FaceComposer::SpeechAt(double t) {
  // Drop frames no later call needs (times are non-decreasing).
  while (speech_.size() > 2 && speech_[1].time_s <= t) {
    last_speech_s_ = speech_.front().time_s;
    speech_.pop_front();
  }
  if (speech_.empty()) {
    SpeechFaceFrame rest;
    rest.time_s = t;
    rest.classes[static_cast<int>(PhoneClass::kSil)] = 1;
    return rest;
  }
  const SpeechFaceFrame& a = speech_.front();
  if (speech_.size() == 1 || t <= a.time_s) return a;
  const SpeechFaceFrame& b = speech_[1];
  if (t >= b.time_s) return b;
  const float w = static_cast<float>((t - a.time_s) / std::max(b.time_s - a.time_s, 1e-9));
  SpeechFaceFrame out;
  out.time_s = t;
  out.jaw_open_deg = a.jaw_open_deg + w * (b.jaw_open_deg - a.jaw_open_deg);
  for (int c = 0; c < kNumPhoneClasses; ++c) out.classes[c] = a.classes[c] + w * (b.classes[c] - a.classes[c]);
  return out;
}

void FaceComposer::UpdateBlinks(double t, bool silent) {
  const double dt = last_t_ < 0 ? 0.0 : t - last_t_;
  if (silent) {
    if (silent_since_ < 0) {
      silent_since_ = t;
      onset_checked_ = false;
    }
  } else {
    silent_since_ = -1;
  }
  if (t - blink_start_ < o_.min_blink_gap_s) return;
  bool start = false;
  if (silent_since_ >= 0 && !onset_checked_ && t - silent_since_ >= o_.pause_onset_s) {
    onset_checked_ = true;
    start = NextUniform() < o_.pause_onset_blink_probability;
  }
  if (!start && dt > 0) {
    const double rate = (silent_since_ >= 0 ? o_.pause_blinks_per_min : o_.speech_blinks_per_min) / 60.0;
    start = NextUniform() < 1 - std::exp(-rate * dt);
  }
  if (start) blink_start_ = t;
}

float FaceComposer::BrowAt(double t) const {
  float brow = 0;
  for (std::size_t i = first_accent_; i < accents_.size(); ++i) {
    const FaceAccent& a = accents_[i];
    if (accents_ordered_ && AccentFromS(a) > t) break;
    const double d = t - a.time_s;
    if (d < -kBrowRiseS || d > kBrowHoldS + kBrowFallS) continue;
    double shape = 1;
    if (d < 0) shape = 1 + d / kBrowRiseS;
    else if (d > kBrowHoldS) shape = 1 - (d - kBrowHoldS) / kBrowFallS;
    const double s = std::clamp(a.strength + o_.face_emphasis, 0.0, 1.0);
    brow = std::max(brow, static_cast<float>(s * shape));
  }
  return std::clamp(brow, 0.0f, 1.0f);
}

float FaceComposer::EmphasisAt(double t, const std::array<float, kNumPhoneClasses>& classes) const {
  float vowel = 0;
  for (int c = 0; c < kNumPhoneClasses; ++c) {
    if (IsVowelClass(c)) vowel += classes[c];
  }
  for (std::size_t i = first_accent_; i < accents_.size(); ++i) {
    const FaceAccent& a = accents_[i];
    if (accents_ordered_ && AccentFromS(a) > t) break;
    const bool span = a.syllable_end_s > a.syllable_start_s;
    const bool inside = span ? (t >= a.syllable_start_s && t < a.syllable_end_s) : std::abs(t - a.time_s) < 0.1;
    if (!inside) continue;
    const double s = std::clamp(a.strength + o_.face_emphasis, 0.0, 1.0);
    return std::clamp(static_cast<float>(2 * s - 1) * vowel, -1.0f, 1.0f);
  }
  return 0;
}

FaceFrame FaceComposer::Compose(double t) {
  FaceFrame f;
  f.time_s = t;
  // Accents that ended before t touch no frame from now on.
  while (first_accent_ < accents_.size() && AccentUntilS(accents_[first_accent_]) < t) ++first_accent_;
  if (first_accent_ >= 1024 && 2 * first_accent_ >= accents_.size()) {
    accents_.erase(accents_.begin(), accents_.begin() + static_cast<std::ptrdiff_t>(first_accent_));
    first_accent_ = 0;
  }
  const SpeechFaceFrame s = SpeechAt(t);
  std::array<float, kNumPhoneClasses> classes = s.classes;
  float sum = 0;
  for (float& c : classes) sum += (c = std::max(c, 0.0f));
  if (sum > 0) {
    for (float& c : classes) c /= sum;
  } else {
    classes[static_cast<int>(PhoneClass::kSil)] = 1;
  }
  ClassesToCategories(classes, &f.categories);
  ClassesToOvr(classes, &f.ovr);
  f.jaw_open_deg = s.jaw_open_deg;
  // Blinks.
  const bool silent = Dominant(classes) == static_cast<int>(PhoneClass::kSil);
  UpdateBlinks(t, silent);
  const double b = t - blink_start_;
  float blink = 0;
  if (b >= 0 && b < o_.blink_close_s) {
    blink = static_cast<float>(b / o_.blink_close_s);
  } else if (b >= o_.blink_close_s && b < o_.blink_close_s + o_.blink_hold_s) {
    blink = 1;
  } else if (b >= o_.blink_close_s + o_.blink_hold_s && b < o_.blink_close_s + o_.blink_hold_s + o_.blink_open_s) {
    blink = static_cast<float>(1 - (b - o_.blink_close_s - o_.blink_hold_s) / o_.blink_open_s);
  }
  f.blink_left = f.blink_right = std::clamp(blink, 0.0f, 1.0f);
  f.brow_raise = BrowAt(t);
  f.emphasis = EmphasisAt(t, classes);
  // Expression: move toward the newest change at or before t.
  while (!expressions_.empty() && expressions_.front().time_s <= t + 1e-9) {
    target_ = expressions_.front().expression;
    target_weight_ = expressions_.front().weight;
    expressions_.pop_front();
  }
  const float step = last_t_ < 0 ? 1.0f : static_cast<float>((t - last_t_) / kExpressionRampS);
  if (target_ != shown_) {
    shown_weight_ = std::max(0.0f, shown_weight_ - step);
    if (shown_weight_ == 0) shown_ = target_;
  } else if (shown_weight_ < target_weight_) {
    shown_weight_ = std::min(target_weight_, shown_weight_ + step);
  } else {
    shown_weight_ = std::max(target_weight_, shown_weight_ - step);
  }
  f.expression = shown_;
  f.expression_weight = shown_ == Expression::kNeutral ? 0.0f : shown_weight_;
  last_t_ = t;
  return f;
}

FaceTrack ComposeTrack(const std::vector<SpeechFaceFrame>& speech, const std::vector<FaceAccent>& accents,
                       Expression expression, float expression_weight, double frame_time_s, double duration_s,
                       const ComposeOptions& options) {
  FaceComposer c(options);
  for (const SpeechFaceFrame& s : speech) c.AddSpeech(s);
  for (const FaceAccent& a : accents) c.AddAccent(a);
  c.SetExpression(0, expression, expression_weight);
  c.FinishSpeech();
  FaceTrack track;
  track.frame_time_s = frame_time_s;
  const int n = frame_time_s > 0 ? static_cast<int>(std::floor(duration_s / frame_time_s + 1e-9)) + 1 : 0;
  track.frames.reserve(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) track.frames.push_back(c.Compose(i * frame_time_s));
  (void)kSpeechStepS;
  return track;
}

}  // namespace kinemo::face
