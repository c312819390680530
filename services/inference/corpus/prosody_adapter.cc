#include "services/inference/corpus/prosody_adapter.h"

#include <algorithm>
#include <cmath>

#include "services/prosody/core/analyzer.h"
#include "services/prosody/core/options.h"

namespace kinemo::inference {
namespace {

constexpr double kMaxGapStepS = 0.5;

// Steps that tile a pause carry no measured intensity (0 dB, unvoiced): the
// coordinator's live and batch paths (services/coordinator/core/animate_plan.cc,
// GapSteps) send pauses to the model that way, so training must see them the
// same way. (Before, training gave them the pause's mean frame intensity:
// room noise at ~30 dB, or -274 dB over digital silence, which the model's
// input bounds refuse.)
constexpr double kPauseStepIntensityDb = 0.0;

void AddGap(double from, double to, std::vector<ProsodyStep>* steps) {
  while (to - from > 1e-3) {
    const double end = std::min(to, from + kMaxGapStepS);
    ProsodyStep s;
    s.start_s = from;
    s.end_s = end;
    s.length_s = end - from;
    s.intensity_mean_db = kPauseStepIntensityDb;
    s.voiced = false;
    steps->push_back(s);
    from = end;
  }
}

}  // namespace

StatusOr<ProsodyTrack> ExtractProsodyWithProsodyCore(std::span<const float> samples,
                                                     int sample_rate_hz) {
  prosody::AnalysisOptions options;
  KINEMO_ASSIGN_OR_RETURN(prosody::ProsodyResult r,
                          prosody::AnalyzeSamples(samples, sample_rate_hz, options));
  if (r.syllables.empty()) return InvalidField("samples", "no syllable found");
  ProsodyTrack track;
  std::vector<int> step_of_syllable(r.syllables.size());
  double t = 0.0;
  for (size_t k = 0; k < r.syllables.size(); ++k) {
    const auto& syl = r.syllables[k];
    if (syl.start_s > t) AddGap(t, syl.start_s, &track.steps);
    ProsodyStep s;
    s.start_s = std::max(t, syl.start_s);
    s.end_s = syl.end_s;
    s.length_s = s.end_s - s.start_s;
    s.intensity_mean_db = syl.intensity_mean_db;
    s.voiced = syl.voiced && syl.f0_mean_hz > 0;
    s.f0_mean_hz = s.voiced ? syl.f0_mean_hz : 0.0;
    if (s.length_s <= 0 || !std::isfinite(s.intensity_mean_db)) continue;
    step_of_syllable[k] = static_cast<int>(track.steps.size());
    track.steps.push_back(s);
    t = s.end_s;
  }
  if (r.duration_s > t) AddGap(t, r.duration_s, &track.steps);
  for (const auto& a : r.accents) {
    if (a.syllable_index < 0 || a.syllable_index >= static_cast<int>(r.syllables.size())) continue;
    track.accents.push_back({a.time_s, 3.0 * a.strength, step_of_syllable[a.syllable_index]});
  }
  std::sort(track.accents.begin(), track.accents.end(),
            [](const Accent& a, const Accent& b) { return a.time_s < b.time_s; });
  return track;
}

}  // namespace kinemo::inference
