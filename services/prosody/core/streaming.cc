#include "services/prosody/core/streaming.h"

#include <algorithm>
#include <cmath>

namespace kinemo::prosody {
namespace {

double MinPitch(const AnalysisOptions& o) {
  return o.intensity.min_pitch_hz > 0 ? o.intensity.min_pitch_hz : o.pitch.floor_hz;
}

}  // namespace

StatusOr<std::unique_ptr<StreamingAnalyzer>> StreamingAnalyzer::Create(
    double sample_rate_hz, const AnalysisOptions& options, bool emit_frames) {
  KINEMO_RETURN_IF_ERROR(ValidateOptions(options, sample_rate_hz));
  return std::unique_ptr<StreamingAnalyzer>(
      new StreamingAnalyzer(sample_rate_hz, options, emit_frames));
}

StreamingAnalyzer::StreamingAnalyzer(double rate, const AnalysisOptions& options, bool emit_frames)
    : rate_(rate),
      o_(options),
      emit_frames_(emit_frames),
      step_(options.pitch.time_step_s),
      lag_frames_(std::max<int64_t>(1, std::llround(options.viterbi_lag_s / step_))),
      pitch_(options.pitch, rate),
      path_(options.pitch, lag_frames_ + 64),
      intensity_(MinPitch(options), options.intensity.subtract_mean, rate),
      tracker_(options.segmentation, step_),
      reach_(std::max(pitch_.reach_samples(), intensity_.reach_samples())) {
  result_.sample_rate_hz = rate;
  result_.frame_step_s = step_;
  trace_.resize(lag_frames_ + 64);
}

double StreamingAnalyzer::accent_latency_s() const {
  return std::max(o_.accent.min_distance_s, o_.segmentation.min_pause_s) + reach_s() + step_;
}

int64_t StreamingAnalyzer::NeededEnd(int64_t frame) const {
  return static_cast<int64_t>(std::floor(FrameTime(frame) * rate_ - 0.5)) + reach_ + 1;
}

Status StreamingAnalyzer::Push(std::span<const float> samples, std::vector<StreamEvent>* out) {
  if (finished_) return absl::FailedPreconditionError("stream: audio pushed after Finish");
  for (std::size_t i = 0; i < samples.size(); ++i) {
    if (!std::isfinite(samples[i])) {
      return InvalidField(kinemo::StrCat("samples[", received_ + static_cast<int64_t>(i), "]"),
                          "not a finite number");
    }
  }
  if (samples.empty()) return absl::OkStatus();
  // Drop samples no future frame needs.
  const int64_t keep_from =
      static_cast<int64_t>(std::floor(FrameTime(next_frame_) * rate_ - 0.5)) - reach_ - 2;
  const int64_t drop = keep_from - base_;
  if (drop > 0 && drop > static_cast<int64_t>(buffer_.size()) / 2 && drop > 4096) {
    buffer_.erase(buffer_.begin(), buffer_.begin() + drop);
    base_ += drop;
  }
  buffer_.insert(buffer_.end(), samples.begin(), samples.end());
  for (float x : samples) peak_ = std::max(peak_, std::fabs(x));
  received_ += static_cast<int64_t>(samples.size());
  while (NeededEnd(next_frame_) <= received_) {
    AnalyzeFrame(out);
    HandleSegments(out);
    ResolvePauseStatus();
    DecideAccents(false, out);
  }
  FlushFrames(decided_, out);
  return absl::OkStatus();
}

void StreamingAnalyzer::AnalyzeFrame(std::vector<StreamEvent>* out) {
  (void)out;
  const int64_t k = next_frame_;
  const double t = FrameTime(k);
  pitch_.Analyze(buffer_, base_, t, peak_, &cands_);
  path_.Push(cands_);
  Frame f;
  f.time_s = t;
  f.voicing_probability = cands_.voicing_probability;
  f.intensity_db = intensity_.Analyze(buffer_, base_, received_, t);
  result_.frames.push_back(f);
  max_db_ = std::max(max_db_, f.intensity_db);
  tracker_.Push(static_cast<int>(k), f.intensity_db, max_db_, &segs_);
  ++next_frame_;
  if (next_frame_ - 1 - lag_frames_ >= decided_) {
    const float f0 = path_.DecideLagged(lag_frames_);
    Frame& d = result_.frames[decided_];
    d.f0_hz = f0;
    d.voiced = f0 > 0;
    ++decided_;
  }
}

void StreamingAnalyzer::MakeProvisional() {
  const int64_t n = next_frame_ - decided_;
  if (n <= 0) return;
  path_.TraceBack(decided_, std::span<float>(trace_.data(), n));
  for (int64_t i = 0; i < n; ++i) {
    Frame& f = result_.frames[decided_ + i];
    f.f0_hz = trace_[i];
    f.voiced = trace_[i] > 0;
  }
}

void StreamingAnalyzer::HandleSegments(std::vector<StreamEvent>* out) {
  for (const SegmentEvent& e : segs_) {
    StreamEvent ev;
    ev.emitted_at_s = received_s();
    switch (e.kind) {
      case SegmentEvent::Kind::kSyllable: {
        MakeProvisional();
        Syllable s;
        s.first_frame = e.first_frame;
        s.end_frame = e.end_frame;
        s.peak_frame = e.peak_frame;
        FillSyllableFeatures(result_.frames, step_, &s);
        const Nucleus n = ComputeNucleus(result_.frames, s, o_);
        if (n.voiced) {
          scale_.max_f0_hz = std::max(scale_.max_f0_hz, n.f0_mean_hz);
          scale_.max_peak_db = std::max(scale_.max_peak_db, n.peak_db);
        }
        // Ended at a trough (the next syllable has begun): not before a pause.
        const bool resolved = tracker_.in_syllable() && tracker_.open_start() == e.end_frame;
        result_.syllables.push_back(s);
        nuclei_.push_back(n);
        resolved_.push_back(resolved);
        ev.kind = StreamEvent::Kind::kSyllable;
        ev.syllable = s;
        out->push_back(std::move(ev));
        break;
      }
      case SegmentEvent::Kind::kPauseStart: {
        result_.pauses.push_back({FrameTime(e.first_frame), 0});
        if (!result_.syllables.empty() &&
            result_.syllables.back().end_frame <= e.first_frame) {
          result_.syllables.back().before_pause = true;
          resolved_.back() = true;
        }
        ev.kind = StreamEvent::Kind::kPauseStart;
        ev.pause = result_.pauses.back();
        out->push_back(std::move(ev));
        break;
      }
      case SegmentEvent::Kind::kPauseEnd: {
        if (result_.pauses.empty()) break;
        result_.pauses.back().end_s = FrameTime(e.end_frame);
        ev.kind = StreamEvent::Kind::kPauseEnd;
        ev.pause = result_.pauses.back();
        out->push_back(std::move(ev));
        break;
      }
    }
  }
  segs_.clear();
}

void StreamingAnalyzer::ResolvePauseStatus() {
  while (unresolved_ < resolved_.size()) {
    if (!resolved_[unresolved_]) {
      const bool later_syllable = unresolved_ + 1 < resolved_.size();
      if (tracker_.in_syllable() || later_syllable) {
        resolved_[unresolved_] = true;  // speech resumed before a pause
      } else {
        break;
      }
    }
    ++unresolved_;
  }
}

void StreamingAnalyzer::DecideAccents(bool final, std::vector<StreamEvent>* out) {
  const double d = o_.accent.min_distance_s;
  const double now = next_frame_ > 0 ? FrameTime(next_frame_ - 1) : 0.0;
  auto& syl = result_.syllables;
  while (next_accent_ < syl.size()) {
    const std::size_t j = next_accent_;
    const Nucleus& n = nuclei_[j];
    if (!n.voiced) {
      ++next_accent_;
      continue;
    }
    const double horizon = n.papt_s + d;
    // Later syllables whose PAPT could fall within the distance.
    std::size_t hi = j + 1;
    while (hi < syl.size() && syl[hi].start_s < horizon) ++hi;
    if (!final) {
      if (!resolved_[j] || now < horizon) break;
      if (tracker_.in_syllable() && FrameTime(tracker_.open_start()) < horizon) break;
      bool all = true;
      for (std::size_t m = j + 1; m < hi; ++m) all = all && resolved_[m];
      if (!all) break;
    }
    std::size_t lo = j;
    while (lo > 0 && j - lo < 64 && syl[lo - 1].end_s > n.papt_s - d) --lo;
    const double si = StrengthIndicator(n, syl[j].before_pause, scale_, o_.accent);
    max_si_ = std::max(max_si_, si);
    double neighbour_si[128];
    for (std::size_t m = lo; m < hi && m - lo < 128; ++m) {
      neighbour_si[m - lo] = nuclei_[m].voiced
                                 ? StrengthIndicator(nuclei_[m], syl[m].before_pause, scale_,
                                                     o_.accent)
                                 : 0.0;
      max_si_ = std::max(max_si_, neighbour_si[m - lo]);
    }
    const double cut = o_.accent.threshold * max_si_;
    bool kept = si > 0 && si >= cut;
    for (std::size_t m = lo; m < hi && m - lo < 128 && kept; ++m) {
      if (m == j || !nuclei_[m].voiced) continue;
      const double sm = neighbour_si[m - lo];
      if (sm < cut || std::fabs(nuclei_[m].papt_s - n.papt_s) >= d) continue;
      if (sm > si || (sm == si && m < j)) kept = false;
    }
    if (kept) {
      Accent a;
      a.time_s = n.papt_s;
      a.strength = max_si_ > 0 ? si / max_si_ : 0.0;
      a.psi = n.psi;
      a.indicator = si;
      a.syllable_index = static_cast<int>(j);
      a.syllable_start_s = syl[j].start_s;
      a.syllable_end_s = syl[j].end_s;
      a.before_pause = syl[j].before_pause;
      syl[j].accent_index = static_cast<int>(result_.accents.size());
      result_.accents.push_back(a);
      StreamEvent ev;
      ev.kind = StreamEvent::Kind::kAccent;
      ev.emitted_at_s = received_s();
      ev.accent = a;
      out->push_back(std::move(ev));
    }
    ++next_accent_;
  }
}

void StreamingAnalyzer::FlushFrames(int64_t up_to, std::vector<StreamEvent>* out) {
  if (!emit_frames_) {
    emitted_frames_ = up_to;
    return;
  }
  if (up_to <= emitted_frames_) return;
  StreamEvent ev;
  ev.kind = StreamEvent::Kind::kFrames;
  ev.emitted_at_s = received_s();
  ev.frames.assign(result_.frames.begin() + emitted_frames_, result_.frames.begin() + up_to);
  emitted_frames_ = up_to;
  out->push_back(std::move(ev));
}

void StreamingAnalyzer::Finish(std::vector<StreamEvent>* out) {
  if (finished_) return;
  finished_ = true;
  const double duration = received_s();
  result_.duration_s = duration;
  const int64_t count =
      std::max<int64_t>(0, static_cast<int64_t>(std::ceil(duration / step_ - 1e-9)));
  while (next_frame_ < count) {
    AnalyzeFrame(out);
    HandleSegments(out);
    ResolvePauseStatus();
    DecideAccents(false, out);
  }
  // The rest of the path is final now.
  MakeProvisional();
  decided_ = next_frame_;
  tracker_.Finish(static_cast<int>(next_frame_), &segs_);
  HandleSegments(out);
  if (!result_.syllables.empty()) result_.syllables.back().before_pause = true;
  std::fill(resolved_.begin(), resolved_.end(), true);
  unresolved_ = resolved_.size();
  DecideAccents(true, out);
  FlushFrames(decided_, out);
}

}  // namespace kinemo::prosody
