#include "services/prosody/core/segmentation.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace kinemo::prosody {

SyllableTracker::SyllableTracker(const SegmentationOptions& options, double step_s)
    : o_(options),
      step_s_(step_s),
      min_pause_frames_(std::max(1, static_cast<int>(std::ceil(options.min_pause_s / step_s - 1e-9)))),
      min_syllable_frames_(
          std::max(1, static_cast<int>(std::ceil(options.min_syllable_s / step_s - 1e-9)))) {}

void SyllableTracker::EndSyllable(int end_frame, std::vector<SegmentEvent>* out) {
  if (end_frame - start_ >= min_syllable_frames_) {
    out->push_back({SegmentEvent::Kind::kSyllable, start_, end_frame, max_frame_});
  }
}

void SyllableTracker::Push(int index, double intensity_db, double reference_db,
                           std::vector<SegmentEvent>* out) {
  const bool speech = intensity_db >= o_.min_speech_db &&
                      intensity_db >= reference_db - o_.silence_threshold_db;
  if (!speech) {
    if (state_ != State::kSilence) {
      EndSyllable(index, out);
      state_ = State::kSilence;
    }
    if (silent_run_ == 0) silent_start_ = index;
    ++silent_run_;
    if (seen_speech_ && !in_pause_ && silent_run_ >= min_pause_frames_) {
      in_pause_ = true;
      out->push_back({SegmentEvent::Kind::kPauseStart, silent_start_, silent_start_, 0});
    }
    return;
  }
  silent_run_ = 0;
  if (in_pause_) {
    in_pause_ = false;
    out->push_back({SegmentEvent::Kind::kPauseEnd, index, index, 0});
  }
  seen_speech_ = true;
  switch (state_) {
    case State::kSilence:
      state_ = State::kRising;
      start_ = index;
      max_db_ = intensity_db;
      max_frame_ = index;
      break;
    case State::kRising:
      if (intensity_db > max_db_) {
        max_db_ = intensity_db;
        max_frame_ = index;
      } else if (intensity_db < max_db_ - o_.min_dip_db) {
        state_ = State::kFalling;
        min_db_ = intensity_db;
        min_frame_ = index;
      }
      break;
    case State::kFalling:
      if (intensity_db < min_db_) {
        min_db_ = intensity_db;
        min_frame_ = index;
      } else if (intensity_db > min_db_ + o_.min_dip_db) {
        // The trough is a syllable boundary.
        EndSyllable(min_frame_, out);
        start_ = min_frame_;
        state_ = State::kRising;
        max_db_ = intensity_db;
        max_frame_ = index;
      }
      break;
  }
}

void SyllableTracker::Finish(int end_index, std::vector<SegmentEvent>* out) {
  if (state_ != State::kSilence) {
    EndSyllable(end_index, out);
    state_ = State::kSilence;
  }
  if (in_pause_) {
    in_pause_ = false;
    out->push_back({SegmentEvent::Kind::kPauseEnd, end_index, end_index, 0});
  }
}

void FillSyllableFeatures(std::span<const Frame> frames, double step_s, Syllable* s) {
  const int first = s->first_frame;
  const int end = std::min<int>(s->end_frame, static_cast<int>(frames.size()));
  s->start_s = frames[first].time_s;
  s->end_s = end < static_cast<int>(frames.size()) ? frames[end].time_s
                                                    : frames[first].time_s + (end - first) * step_s;
  s->length_s = s->end_s - s->start_s;
  s->nucleus_time_s = frames[s->peak_frame].time_s;
  double f0_sum = 0, db_sum = 0;
  int voiced = 0;
  for (int i = first; i < end; ++i) {
    db_sum += frames[i].intensity_db;
    if (frames[i].voiced) {
      f0_sum += frames[i].f0_hz;
      ++voiced;
    }
  }
  const int n = std::max(1, end - first);
  s->intensity_mean_db = db_sum / n;
  s->f0_mean_hz = voiced > 0 ? f0_sum / voiced : 0.0;
  s->voiced = voiced > 0 && 2 * voiced >= n;
}

Nucleus ComputeNucleus(std::span<const Frame> frames, const Syllable& s,
                       const AnalysisOptions& options) {
  Nucleus n;
  const int first = s.first_frame;
  const int end = std::min<int>(s.end_frame, static_cast<int>(frames.size()));
  const int peak = std::clamp(s.peak_frame, first, std::max(first, end - 1));
  n.peak_db = frames[peak].intensity_db;
  const double limit = n.peak_db - options.segmentation.nucleus_drop_db;
  int lo = peak, hi = peak;
  while (lo - 1 >= first && frames[lo - 1].intensity_db >= limit) --lo;
  while (hi + 1 < end && frames[hi + 1].intensity_db >= limit) ++hi;
  const double step = frames.size() > 1 ? frames[1].time_s - frames[0].time_s : 0.01;
  n.duration_s = (hi - lo + 1) * step;
  double db_sum = 0, f0_sum = 0;
  int voiced = 0;
  double f0_max = 0, f0_min = std::numeric_limits<double>::max();
  int f0_max_at = lo, f0_min_at = lo;
  for (int i = lo; i <= hi; ++i) {
    db_sum += frames[i].intensity_db;
    if (!frames[i].voiced) continue;
    const double f = frames[i].f0_hz;
    f0_sum += f;
    ++voiced;
    if (f > f0_max) {
      f0_max = f;
      f0_max_at = i;
    }
    if (f < f0_min) {
      f0_min = f;
      f0_min_at = i;
    }
  }
  n.mean_db = db_sum / (hi - lo + 1);
  // PAPT: the F0 maximum over the whole syllable.
  double papt_f0 = 0;
  n.papt_s = frames[peak].time_s;
  for (int i = first; i < end; ++i) {
    if (frames[i].voiced && frames[i].f0_hz > papt_f0) {
      papt_f0 = frames[i].f0_hz;
      n.papt_s = frames[i].time_s;
    }
  }
  if (voiced == 0) return n;
  n.voiced = true;
  n.f0_mean_hz = f0_sum / voiced;
  double range = (f0_max - f0_min) / f0_max;
  if (f0_max_at < f0_min_at) range *= options.accent.falling_range_penalty;  // falling: H+L*
  n.f0_range = range;
  const double mp = n.f0_mean_hz / options.pitch.ceiling_hz;
  n.psi = n.duration_s * std::max(0.0, n.mean_db) * (0.5 * range + 0.5 * mp);
  return n;
}

double StrengthIndicator(const Nucleus& n, bool before_pause, const IndicatorScale& scale,
                         const AccentOptions& options) {
  if (!n.voiced) return 0;
  const double p = scale.max_f0_hz > 0 ? n.f0_mean_hz / scale.max_f0_hz : 0.0;
  const double span = scale.max_peak_db - scale.floor_db;
  const double i = span > 0 ? std::clamp((n.peak_db - scale.floor_db) / span, 0.0, 1.0) : 0.0;
  double si = p + i;
  if (before_pause) si *= options.pre_pause_bonus;
  return si;
}

std::vector<Accent> SelectAccents(std::span<const Frame> frames, std::vector<Syllable>* syllables,
                                  const AnalysisOptions& options, double reference_db) {
  std::vector<Nucleus> nuclei;
  nuclei.reserve(syllables->size());
  IndicatorScale scale;
  scale.floor_db = reference_db - options.segmentation.silence_threshold_db;
  for (const Syllable& s : *syllables) {
    nuclei.push_back(ComputeNucleus(frames, s, options));
    if (nuclei.back().voiced) {
      scale.max_f0_hz = std::max(scale.max_f0_hz, nuclei.back().f0_mean_hz);
      scale.max_peak_db = std::max(scale.max_peak_db, nuclei.back().peak_db);
    }
  }
  std::vector<double> si(syllables->size(), 0.0);
  double max_si = 0;
  for (std::size_t k = 0; k < syllables->size(); ++k) {
    si[k] = StrengthIndicator(nuclei[k], (*syllables)[k].before_pause, scale, options.accent);
    max_si = std::max(max_si, si[k]);
  }
  std::vector<Accent> accents;
  if (max_si <= 0) return accents;
  const double cut = options.accent.threshold * max_si;
  for (std::size_t k = 0; k < syllables->size(); ++k) {
    if (!nuclei[k].voiced || si[k] < cut) continue;
    bool kept = true;
    for (std::size_t m = 0; m < syllables->size() && kept; ++m) {
      if (m == k || !nuclei[m].voiced || si[m] < cut) continue;
      if (std::fabs(nuclei[m].papt_s - nuclei[k].papt_s) >= options.accent.min_distance_s) continue;
      // The stronger one wins; on a tie, the earlier.
      if (si[m] > si[k] || (si[m] == si[k] && m < k)) kept = false;
    }
    if (!kept) continue;
    Syllable& s = (*syllables)[k];
    Accent a;
    a.time_s = nuclei[k].papt_s;
    a.strength = si[k] / max_si;
    a.psi = nuclei[k].psi;
    a.indicator = si[k];
    a.syllable_index = static_cast<int>(k);
    a.syllable_start_s = s.start_s;
    a.syllable_end_s = s.end_s;
    a.before_pause = s.before_pause;
    s.accent_index = static_cast<int>(accents.size());
    accents.push_back(a);
  }
  return accents;
}

}  // namespace kinemo::prosody
