#include "common/face/viseme_scores.h"

#include <algorithm>
#include <array>

#include "common/face/visemes.h"

namespace kinemo::face {

VisemeScores ScoreVisemes(std::span<const int> reference, const FaceTrack& track) {
  const std::size_t n = std::min(reference.size(), track.frames.size());
  const auto category = [&](std::size_t i) { return kClassCategory[static_cast<std::size_t>(reference[i])]; };
  const auto is_bpm = [&](std::size_t i) { return category(i) == Category::kBPM; };
  const auto is_closed = [&](std::size_t i) {
    return Dominant(track.frames[i].categories) == static_cast<int>(Category::kBPM);
  };
  VisemeScores s;
  std::array<int, kNumCategories> counts{};
  int right = 0, closed = 0, rest = 0, false_closed = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (reference[i] == static_cast<int>(PhoneClass::kSil)) {
      ++s.pause_frames;
      rest += Dominant(track.frames[i].ovr) == static_cast<int>(OvrViseme::kSil);
      continue;
    }
    const int cat = static_cast<int>(category(i));
    ++s.speech_frames;
    ++counts[static_cast<std::size_t>(cat)];
    right += Dominant(track.frames[i].categories) == cat;
    if (is_bpm(i)) {
      ++s.bpm_frames;
      closed += is_closed(i);
    } else {
      false_closed += is_closed(i);
    }
  }
  int phones_closed = 0;
  for (std::size_t i = 0; i < n;) {
    std::size_t j = i + 1;
    if (is_bpm(i)) {
      bool any = is_closed(i);
      for (; j < n && is_bpm(j); ++j) any = any || is_closed(j);
      ++s.bpm_phones;
      phones_closed += any;
    }
    i = j;
  }
  for (std::size_t i = 0; i < n;) {
    std::size_t j = i + 1;
    if (is_closed(i)) {
      bool touches = is_bpm(i) || (i > 0 && is_bpm(i - 1));
      for (; j < n && is_closed(j); ++j) touches = touches || is_bpm(j);
      touches = touches || (j < n && is_bpm(j));
      ++s.closures;
      s.spurious_closures += !touches;
    }
    i = j;
  }
  const auto share = [](int a, int b) { return b > 0 ? static_cast<double>(a) / b : 0.0; };
  const int most = *std::max_element(counts.begin() + 1, counts.end());
  s.accuracy = share(right, s.speech_frames);
  s.chance = share(most, s.speech_frames);
  s.bpm_closed = share(closed, s.bpm_frames);
  s.closed_outside_bpm = share(false_closed, s.speech_frames - s.bpm_frames);
  s.pauses_at_rest = share(rest, s.pause_frames);
  s.bpm_phones_closed = share(phones_closed, s.bpm_phones);
  const double minutes = n > 1 ? (track.frames[n - 1].time_s - track.frames[0].time_s) / 60 : 0.0;
  s.spurious_closures_per_min = minutes > 0 ? s.spurious_closures / minutes : 0.0;
  return s;
}

}  // namespace kinemo::face
