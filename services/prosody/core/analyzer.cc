#include "services/prosody/core/analyzer.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "common/parallel/parallel.h"
#include "services/prosody/core/intensity.h"
#include "services/prosody/core/pitch.h"
#include "services/prosody/core/segmentation.h"

namespace kinemo::prosody {

Status ValidateOptions(const AnalysisOptions& o, double sample_rate_hz) {
  if (!(sample_rate_hz >= 4000 && sample_rate_hz <= 192000)) {
    return InvalidField("sample_rate_hz", sample_rate_hz, " is not supported (4000..192000)");
  }
  const PitchOptions& p = o.pitch;
  if (!(p.time_step_s >= 0.001 && p.time_step_s <= 0.1)) {
    return InvalidField("pitch.time_step_s", p.time_step_s, " is outside 0.001..0.1");
  }
  if (!(p.floor_hz >= 20 && p.floor_hz <= 1000)) {
    return InvalidField("pitch.floor_hz", p.floor_hz, " is outside 20..1000");
  }
  if (!(p.ceiling_hz > p.floor_hz)) {
    return InvalidField("pitch.ceiling_hz", p.ceiling_hz, " must exceed pitch.floor_hz (",
                        p.floor_hz, ")");
  }
  if (!(p.ceiling_hz < 0.5 * sample_rate_hz)) {
    return InvalidField("pitch.ceiling_hz", p.ceiling_hz, " must be below half the sample rate (",
                        0.5 * sample_rate_hz, " Hz)");
  }
  if (!(p.periods_per_window >= 1 && p.periods_per_window <= 10)) {
    return InvalidField("pitch.periods_per_window", p.periods_per_window, " is outside 1..10");
  }
  if (p.max_candidates < 2 || p.max_candidates > 32) {
    return InvalidField("pitch.max_candidates", p.max_candidates, " is outside 2..32");
  }
  if (!(p.voicing_threshold >= 0 && p.voicing_threshold <= 1)) {
    return InvalidField("pitch.voicing_threshold", p.voicing_threshold, " is outside 0..1");
  }
  if (!(p.silence_threshold >= 0 && p.silence_threshold <= 1)) {
    return InvalidField("pitch.silence_threshold", p.silence_threshold, " is outside 0..1");
  }
  if (!(p.octave_cost >= 0 && p.octave_jump_cost >= 0 && p.voiced_unvoiced_cost >= 0)) {
    return InvalidField("pitch.octave_cost", "costs must be >= 0");
  }
  if (!(o.intensity.min_pitch_hz == 0 || (o.intensity.min_pitch_hz >= 20 &&
                                          o.intensity.min_pitch_hz <= 1000))) {
    return InvalidField("intensity.min_pitch_hz", o.intensity.min_pitch_hz,
                        " is outside 20..1000 (0 = pitch floor)");
  }
  const SegmentationOptions& s = o.segmentation;
  if (!(s.silence_threshold_db > 0 && s.silence_threshold_db <= 100)) {
    return InvalidField("segmentation.silence_threshold_db", s.silence_threshold_db,
                        " is outside (0, 100]");
  }
  if (!(s.min_dip_db > 0 && s.min_dip_db <= 40)) {
    return InvalidField("segmentation.min_dip_db", s.min_dip_db, " is outside (0, 40]");
  }
  if (!(s.min_pause_s >= p.time_step_s && s.min_pause_s <= 10)) {
    return InvalidField("segmentation.min_pause_s", s.min_pause_s, " is outside [time step, 10]");
  }
  if (!(s.min_syllable_s >= 0 && s.min_syllable_s <= 1)) {
    return InvalidField("segmentation.min_syllable_s", s.min_syllable_s, " is outside 0..1");
  }
  if (!(s.nucleus_drop_db > 0 && s.nucleus_drop_db <= 40)) {
    return InvalidField("segmentation.nucleus_drop_db", s.nucleus_drop_db, " is outside (0, 40]");
  }
  const AccentOptions& a = o.accent;
  if (!(a.threshold >= 0 && a.threshold <= 1)) {
    return InvalidField("accent.threshold", a.threshold, " is outside 0..1");
  }
  if (!(a.min_distance_s >= 0 && a.min_distance_s <= 10)) {
    return InvalidField("accent.min_distance_s", a.min_distance_s, " is outside 0..10");
  }
  if (!(a.pre_pause_bonus >= 1 && a.pre_pause_bonus <= 10)) {
    return InvalidField("accent.pre_pause_bonus", a.pre_pause_bonus, " is outside 1..10");
  }
  if (!(a.falling_range_penalty >= 0 && a.falling_range_penalty <= 1)) {
    return InvalidField("accent.falling_range_penalty", a.falling_range_penalty,
                        " is outside 0..1");
  }
  if (!(o.viterbi_lag_s > 0 && o.viterbi_lag_s <= 0.5)) {
    return InvalidField("viterbi_lag_s", o.viterbi_lag_s, " is outside (0, 0.5]");
  }
  if (o.threads < 0 || o.threads > kMaxAnalysisThreads) {
    return InvalidField("threads", o.threads, " is outside 0..", kMaxAnalysisThreads);
  }
  return absl::OkStatus();
}

namespace {

// Frames per work item of the offline analysis (2.56 s at 10 ms): large
// enough that handing items out costs nothing, small enough to balance.
constexpr int kBlockFrames = 256;
// Samples per work item of the whole-signal passes (finite check, mean, peak).
constexpr std::size_t kBlockSamples = std::size_t{1} << 16;

struct SignalStats {
  std::size_t first_bad = 0;  // index of the first non-finite sample, or size()
  float mean = 0;
  float peak = 0;  // largest |x - mean|
};

// Whole-signal statistics in fixed blocks, so that the sums (and so the
// results) are the same for any number of threads.
SignalStats Stats(std::span<const float> samples, int threads) {
  const std::size_t n = samples.size();
  const int blocks = static_cast<int>((n + kBlockSamples - 1) / kBlockSamples);
  std::vector<double> sums(static_cast<std::size_t>(blocks), 0.0);
  std::vector<std::size_t> bad(static_cast<std::size_t>(blocks), n);
  parallel::ParallelFor(blocks, threads, [&](int b, int) {
    const std::size_t lo = static_cast<std::size_t>(b) * kBlockSamples;
    const std::size_t hi = std::min(n, lo + kBlockSamples);
    double sum = 0;
    for (std::size_t i = lo; i < hi; ++i) sum += samples[i];
    sums[static_cast<std::size_t>(b)] = sum;
    if (!std::isfinite(sum)) {
      for (std::size_t i = lo; i < hi; ++i) {
        if (!std::isfinite(samples[i])) {
          bad[static_cast<std::size_t>(b)] = i;
          break;
        }
      }
    }
  });
  SignalStats stats;
  stats.first_bad = n;
  double total = 0;
  for (int b = 0; b < blocks; ++b) {
    total += sums[static_cast<std::size_t>(b)];
    stats.first_bad = std::min(stats.first_bad, bad[static_cast<std::size_t>(b)]);
  }
  if (stats.first_bad < n) return stats;
  stats.mean = static_cast<float>(total / static_cast<double>(std::max<std::size_t>(1, n)));
  std::vector<float> peaks(static_cast<std::size_t>(blocks), 0.0f);
  parallel::ParallelFor(blocks, threads, [&](int b, int) {
    const std::size_t lo = static_cast<std::size_t>(b) * kBlockSamples;
    const std::size_t hi = std::min(n, lo + kBlockSamples);
    float peak = 0;
    for (std::size_t i = lo; i < hi; ++i) peak = std::max(peak, std::fabs(samples[i] - stats.mean));
    peaks[static_cast<std::size_t>(b)] = peak;
  });
  for (float p : peaks) stats.peak = std::max(stats.peak, p);
  return stats;
}

}  // namespace

StatusOr<std::vector<Frame>> AnalyzeFrames(std::span<const float> samples, double sample_rate_hz,
                                           const AnalysisOptions& options, const FrameGrid& grid) {
  KINEMO_RETURN_IF_ERROR(ValidateOptions(options, sample_rate_hz));
  const int threads = parallel::ResolveThreads(options.threads);
  const SignalStats stats = Stats(samples, threads);
  if (stats.first_bad < samples.size()) {
    return InvalidField(kinemo::StrCat("samples[", stats.first_bad, "]"), "not a finite number");
  }
  const double step = options.pitch.time_step_s;
  const double duration = static_cast<double>(samples.size()) / sample_rate_hz;
  int count = grid.count;
  if (count < 0) {
    count = std::max(0, static_cast<int>(std::ceil((duration - grid.first_time_s) / step - 1e-9)));
  }
  std::vector<Frame> frames(count);
  if (count == 0) return frames;

  // Pitch candidates and intensity of each frame depend only on the samples
  // (and the global peak): blocks of frames run on all threads. The Viterbi
  // path needs the frames in order: the calling thread extends it block by
  // block as the blocks complete, while the other threads go on.
  const int blocks = (count + kBlockFrames - 1) / kBlockFrames;
  const int workers = std::max(1, std::min(threads, blocks));
  std::vector<PitchFrameAnalyzer> pitch;
  pitch.reserve(static_cast<std::size_t>(workers));
  for (int w = 0; w < workers; ++w) pitch.emplace_back(options.pitch, sample_rate_hz);
  const double min_pitch =
      options.intensity.min_pitch_hz > 0 ? options.intensity.min_pitch_hz : options.pitch.floor_hz;
  const IntensityAnalyzer intensity(min_pitch, options.intensity.subtract_mean, sample_rate_hz);
  std::vector<PitchCandidates> cands(static_cast<std::size_t>(count));
  PitchPath path(options.pitch, count);
  const int64_t end = static_cast<int64_t>(samples.size());
  parallel::OrderedParallelFor(
      blocks, workers,
      [&](int b, int worker) {
        PitchFrameAnalyzer& analyzer = pitch[static_cast<std::size_t>(worker)];
        const int k1 = std::min(count, (b + 1) * kBlockFrames);
        for (int k = b * kBlockFrames; k < k1; ++k) {
          Frame& f = frames[static_cast<std::size_t>(k)];
          PitchCandidates& c = cands[static_cast<std::size_t>(k)];
          f.time_s = grid.first_time_s + k * step;
          analyzer.Analyze(samples, 0, f.time_s, stats.peak, &c);
          f.voicing_probability = c.voicing_probability;
          f.intensity_db = intensity.Analyze(samples, 0, end, f.time_s);
        }
      },
      [&](int b) {
        const int k1 = std::min(count, (b + 1) * kBlockFrames);
        for (int k = b * kBlockFrames; k < k1; ++k) path.Push(cands[static_cast<std::size_t>(k)]);
      });
  std::vector<float> f0(count);
  path.TraceBack(0, f0);
  for (int k = 0; k < count; ++k) {
    frames[k].f0_hz = f0[k];
    frames[k].voiced = f0[k] > 0;
  }
  return frames;
}

void Segment(const AnalysisOptions& options, ProsodyResult* result) {
  std::vector<Frame>& frames = result->frames;
  double reference = kSilenceDb;
  for (const Frame& f : frames) reference = std::max(reference, f.intensity_db);
  SyllableTracker tracker(options.segmentation, result->frame_step_s);
  std::vector<SegmentEvent> events;
  for (int k = 0; k < static_cast<int>(frames.size()); ++k) {
    tracker.Push(k, frames[k].intensity_db, reference, &events);
  }
  tracker.Finish(static_cast<int>(frames.size()), &events);
  const auto time_of = [&](int index) {
    return index < static_cast<int>(frames.size())
               ? frames[index].time_s
               : frames.back().time_s + (index - static_cast<int>(frames.size()) + 1) *
                                            result->frame_step_s;
  };
  for (const SegmentEvent& e : events) {
    switch (e.kind) {
      case SegmentEvent::Kind::kSyllable: {
        Syllable s;
        s.first_frame = e.first_frame;
        s.end_frame = e.end_frame;
        s.peak_frame = e.peak_frame;
        FillSyllableFeatures(frames, result->frame_step_s, &s);
        result->syllables.push_back(s);
        break;
      }
      case SegmentEvent::Kind::kPauseStart:
        result->pauses.push_back({time_of(e.first_frame), 0});
        // The syllable that ended where this silence began precedes a pause.
        if (!result->syllables.empty() && result->syllables.back().end_frame <= e.first_frame) {
          result->syllables.back().before_pause = true;
        }
        break;
      case SegmentEvent::Kind::kPauseEnd:
        if (!result->pauses.empty()) result->pauses.back().end_s = time_of(e.end_frame);
        break;
    }
  }
  // The last syllable precedes the end of the speech.
  if (!result->syllables.empty()) result->syllables.back().before_pause = true;
  result->accents = SelectAccents(frames, &result->syllables, options, reference);
}

StatusOr<ProsodyResult> AnalyzeSamples(std::span<const float> samples, double sample_rate_hz,
                                       const AnalysisOptions& options, const FrameGrid& grid) {
  KINEMO_ASSIGN_OR_RETURN(std::vector<Frame> frames,
                          AnalyzeFrames(samples, sample_rate_hz, options, grid));
  ProsodyResult result;
  result.duration_s = static_cast<double>(samples.size()) / sample_rate_hz;
  result.sample_rate_hz = sample_rate_hz;
  result.frame_step_s = options.pitch.time_step_s;
  result.frames = std::move(frames);
  if (!result.frames.empty()) Segment(options, &result);
  return result;
}

}  // namespace kinemo::prosody
