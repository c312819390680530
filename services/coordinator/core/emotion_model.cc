#include "services/coordinator/core/emotion_model.h"

#include <algorithm>
#include <cmath>

namespace kinemo::coordinator {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

Status CheckNonNegative(double v, const char* field) {
  if (!std::isfinite(v) || v < 0) {
    return absl::InvalidArgumentError(absl::StrCat(field, ": must be finite and >= 0, got ", v));
  }
  return absl::OkStatus();
}

}  // namespace

StatusOr<EmotionParams> ResolveEmotionParams(const v1::EmotionModelOptions& o) {
  KINEMO_RETURN_IF_ERROR(CheckNonNegative(o.rate_per_s(), "emotion.rate_per_s"));
  KINEMO_RETURN_IF_ERROR(CheckNonNegative(o.min_intensity_factor(), "emotion.min_intensity_factor"));
  KINEMO_RETURN_IF_ERROR(CheckNonNegative(o.enter_threshold(), "emotion.enter_threshold"));
  KINEMO_RETURN_IF_ERROR(CheckNonNegative(o.exit_threshold(), "emotion.exit_threshold"));
  KINEMO_RETURN_IF_ERROR(CheckNonNegative(o.idle_decay_per_s(), "emotion.idle_decay_per_s"));
  KINEMO_RETURN_IF_ERROR(CheckNonNegative(o.tick_s(), "emotion.tick_s"));
  EmotionParams p;
  if (o.rate_per_s() > 0) p.rate_per_s = o.rate_per_s();
  if (o.min_intensity_factor() > 0) p.min_intensity_factor = o.min_intensity_factor();
  if (o.enter_threshold() > 0) p.enter_threshold = o.enter_threshold();
  if (o.exit_threshold() > 0) p.exit_threshold = o.exit_threshold();
  p.idle_decay_per_s = o.idle_decay_per_s();
  if (o.tick_s() > 0) p.tick_s = o.tick_s();
  p.intensity_from_valence = o.intensity_from_valence();
  if (p.min_intensity_factor > 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        "emotion.min_intensity_factor: must be in [0, 1], got ", p.min_intensity_factor));
  }
  if (p.enter_threshold > 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("emotion.enter_threshold: must be in (0, 1], got ", p.enter_threshold));
  }
  if (p.exit_threshold >= p.enter_threshold) {
    return absl::InvalidArgumentError(
        absl::StrCat("emotion.exit_threshold: must be < enter_threshold (", p.enter_threshold,
                     "), got ", p.exit_threshold));
  }
  return p;
}

double IntensityFactor(const EmotionParams& p, double intensity) {
  const double i = std::clamp(intensity, -1.0, 1.0);
  return p.min_intensity_factor + (1.0 - p.min_intensity_factor) * (i + 1.0) / 2.0;
}

Emotion NextEmotion(const EmotionParams& p, Emotion previous, double v) {
  switch (previous) {
    case common::v1::EMOTION_HAPPY:
      return v <= p.exit_threshold ? common::v1::EMOTION_NEUTRAL : previous;
    case common::v1::EMOTION_ANGRY:
      return v >= -p.exit_threshold ? common::v1::EMOTION_NEUTRAL : previous;
    default:
      if (v >= p.enter_threshold) return common::v1::EMOTION_HAPPY;
      if (v <= -p.enter_threshold) return common::v1::EMOTION_ANGRY;
      return common::v1::EMOTION_NEUTRAL;
  }
}

double InitialValence(Emotion e) {
  if (e == common::v1::EMOTION_HAPPY) return 1.0;
  if (e == common::v1::EMOTION_ANGRY) return -1.0;
  return 0.0;
}

EmotionModel::EmotionModel(const EmotionParams& params, Emotion initial, double time_s)
    : params_(params),
      emotion_(initial == common::v1::EMOTION_HAPPY || initial == common::v1::EMOTION_ANGRY
                   ? initial
                   : common::v1::EMOTION_NEUTRAL),
      valence_(InitialValence(initial)),
      time_s_(time_s) {}

EmotionModel EmotionModel::Restore(const EmotionParams& params, Emotion emotion, double valence,
                                   Action action, double intensity, double time_s) {
  EmotionModel m(params, emotion, time_s);
  if (std::isfinite(valence)) m.valence_ = std::clamp(valence, -1.0, 1.0);
  const bool known = action == common::v1::ACTION_KISSES || action == common::v1::ACTION_SHOUTING;
  m.action_ = known ? action : common::v1::ACTION_IDLE;
  m.intensity_ = std::isfinite(intensity) ? std::clamp(intensity, -1.0, 1.0) : 0.0;
  return m;
}

double EmotionModel::Velocity() const {
  switch (action_) {
    case common::v1::ACTION_KISSES:
      return valence_ < 1.0 ? params_.rate_per_s * IntensityFactor(params_, intensity_) : 0.0;
    case common::v1::ACTION_SHOUTING:
      return valence_ > -1.0 ? -params_.rate_per_s * IntensityFactor(params_, intensity_) : 0.0;
    default:
      if (params_.idle_decay_per_s <= 0 || valence_ == 0.0) return 0.0;
      return valence_ > 0 ? -params_.idle_decay_per_s : params_.idle_decay_per_s;
  }
}

double EmotionModel::Limit() const {
  switch (action_) {
    case common::v1::ACTION_KISSES:
      return 1.0;
    case common::v1::ACTION_SHOUTING:
      return -1.0;
    default:
      return 0.0;  // idle decays toward 0 (when it moves at all)
  }
}

bool EmotionModel::NextThreshold(double velocity, double* threshold, Emotion* to) const {
  const double enter = params_.enter_threshold, exit = params_.exit_threshold;
  switch (emotion_) {
    case common::v1::EMOTION_HAPPY:
      if (velocity >= 0) return false;
      *threshold = exit;
      *to = common::v1::EMOTION_NEUTRAL;
      return true;
    case common::v1::EMOTION_ANGRY:
      if (velocity <= 0) return false;
      *threshold = -exit;
      *to = common::v1::EMOTION_NEUTRAL;
      return true;
    default:
      if (velocity > 0) {
        *threshold = enter;
        *to = common::v1::EMOTION_HAPPY;
      } else if (velocity < 0) {
        *threshold = -enter;
        *to = common::v1::EMOTION_ANGRY;
      } else {
        return false;
      }
      return true;
  }
}

void EmotionModel::AdvanceTo(double time_s, std::vector<EmotionChange>* changes) {
  // Each pass either reaches `time_s` or crosses one threshold (which flips
  // the emotion); at most two crossings lie in one direction.
  for (int pass = 0; pass < 4 && time_s > time_s_; ++pass) {
    const double velocity = Velocity();
    if (velocity == 0.0) break;
    const double limit = Limit();
    double threshold = 0;
    Emotion to = emotion_;
    const bool has_threshold = NextThreshold(velocity, &threshold, &to);
    // A threshold beyond the limit is never reached.
    const bool reachable = has_threshold && (velocity > 0 ? threshold <= limit : threshold >= limit);
    if (reachable) {
      const double t_cross = time_s_ + std::max(0.0, (threshold - valence_) / velocity);
      if (t_cross <= time_s) {
        valence_ = threshold;
        time_s_ = t_cross;
        EmotionChange c;
        c.time_s = t_cross;
        c.from = emotion_;
        c.to = to;
        c.valence = valence_;
        c.action = action_;
        c.intensity = intensity_;
        emotion_ = to;
        if (changes != nullptr) changes->push_back(c);
        continue;
      }
    }
    double v = valence_ + velocity * (time_s - time_s_);
    valence_ = velocity > 0 ? std::min(v, limit) : std::max(v, limit);
    break;
  }
  if (time_s > time_s_) time_s_ = time_s;
}

void EmotionModel::SetAction(double time_s, Action action, double intensity,
                             std::vector<EmotionChange>* changes) {
  AdvanceTo(time_s, changes);
  action_ = action;
  intensity_ = std::isfinite(intensity) ? std::clamp(intensity, -1.0, 1.0) : 0.0;
}

double EmotionModel::NextChangeTime() const {
  const double velocity = Velocity();
  if (velocity == 0.0) return kInf;
  double threshold = 0;
  Emotion to = emotion_;
  if (!NextThreshold(velocity, &threshold, &to)) return kInf;
  const double limit = Limit();
  if (velocity > 0 ? threshold > limit : threshold < limit) return kInf;
  return time_s_ + std::max(0.0, (threshold - valence_) / velocity);
}

double EmotionModel::RobotIntensity() const {
  return params_.intensity_from_valence ? std::min(1.0, std::abs(valence_)) : 1.0;
}

}  // namespace kinemo::coordinator
