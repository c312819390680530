// Live prosody analysis: PCM chunks of any size in, events out as soon as
// each is certain.
//
// Algorithmic latency (audio time between the last sample an event depends
// on and the event; compute time excluded), for the defaults at 75 Hz:
//  - frame k (centred at t_k): needs audio up to t_k + reach_s, where reach_s
//    = half the intensity window (3.2 / floor = 42.7 ms) and covers the pitch
//    window (1.5 / floor); its F0/voicing is final viterbi_lag_s later
//    (default 0.1 s). frame_latency_s() = reach_s + viterbi_lag_s.
//  - syllable: its end is an intensity trough, certain once intensity has
//    risen min_dip_db above it (or silence starts); the event is emitted with
//    the frame that makes it certain, i.e. reach_s after that frame's centre.
//    Its F0 uses the Viterbi path as known then (frames younger than the lag
//    are provisional). syllable_latency_s() = reach_s.
//  - accent: decided min_distance_s after its PAPT, once every syllable
//    within min_distance_s has ended and its pre-pause status is known (a
//    pause needs min_pause_s of silence). accent_latency_s() bounds the time
//    after the syllable's end: max(min_distance_s, min_pause_s) + reach_s +
//    time_step. Strength is normalised by the strongest indicator so far.
//  - pause: start reported once min_pause_s of silence has passed (+ reach_s),
//    end when speech resumes (+ reach_s).
// The silence reference is the running maximum intensity (offline: the
// recording's maximum); the unvoiced strength uses the running peak amplitude.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "common/status/status.h"
#include "services/prosody/core/intensity.h"
#include "services/prosody/core/options.h"
#include "services/prosody/core/pitch.h"
#include "services/prosody/core/segmentation.h"
#include "services/prosody/core/types.h"

namespace kinemo::prosody {

struct StreamEvent {
  enum class Kind { kFrames, kSyllable, kAccent, kPauseStart, kPauseEnd };
  Kind kind = Kind::kFrames;
  // Seconds of audio received when the event was emitted.
  double emitted_at_s = 0;
  std::vector<Frame> frames;  // kFrames: final frames in time order
  Syllable syllable;          // kSyllable (accent_index -1)
  Accent accent;              // kAccent
  Pause pause;                // kPauseStart (end_s 0) / kPauseEnd
};

class StreamingAnalyzer {
 public:
  static StatusOr<std::unique_ptr<StreamingAnalyzer>> Create(double sample_rate_hz,
                                                             const AnalysisOptions& options,
                                                             bool emit_frames);
  // Appends mono samples (any count) and the events they make certain.
  // INVALID_ARGUMENT (nothing appended) for a non-finite sample or after
  // Finish.
  Status Push(std::span<const float> samples, std::vector<StreamEvent>* out);
  // End of the stream: flushes everything still pending.
  void Finish(std::vector<StreamEvent>* out);

  double received_s() const { return static_cast<double>(received_) / rate_; }
  double reach_s() const { return static_cast<double>(reach_) / rate_; }
  double frame_latency_s() const { return reach_s() + lag_frames_ * step_; }
  double syllable_latency_s() const { return reach_s(); }
  double accent_latency_s() const;
  // Everything analysed so far (final frames, syllables, accents, pauses).
  const ProsodyResult& result() const { return result_; }

 private:
  StreamingAnalyzer(double rate, const AnalysisOptions& options, bool emit_frames);
  int64_t NeededEnd(int64_t frame) const;  // samples needed for frame `frame`
  void AnalyzeFrame(std::vector<StreamEvent>* out);
  void HandleSegments(std::vector<StreamEvent>* out);
  void ResolvePauseStatus();
  void DecideAccents(bool final, std::vector<StreamEvent>* out);
  void FlushFrames(int64_t up_to, std::vector<StreamEvent>* out);
  void MakeProvisional();
  double FrameTime(int64_t k) const { return static_cast<double>(k) * step_; }

  double rate_;
  AnalysisOptions o_;
  bool emit_frames_;
  double step_;
  int64_t lag_frames_;
  PitchFrameAnalyzer pitch_;
  PitchPath path_;
  IntensityAnalyzer intensity_;
  SyllableTracker tracker_;
  int64_t reach_;
  std::vector<float> buffer_;
  int64_t base_ = 0;      // absolute index of buffer_[0]
  int64_t received_ = 0;  // samples received
  float peak_ = 0;        // running peak amplitude
  double max_db_ = kSilenceDb;
  int64_t next_frame_ = 0;     // next frame to analyse
  int64_t decided_ = 0;        // frames [0, decided_) are final
  int64_t emitted_frames_ = 0;
  PitchCandidates cands_;
  std::vector<float> trace_;
  std::vector<SegmentEvent> segs_;
  ProsodyResult result_;
  // Per syllable: nucleus, pre-pause status known, accent decided.
  std::vector<Nucleus> nuclei_;
  std::vector<bool> resolved_;
  std::size_t next_accent_ = 0;  // first syllable whose accent is undecided
  std::size_t unresolved_ = 0;   // first syllable whose pause status is unknown
  IndicatorScale scale_;
  double max_si_ = 0;
  bool finished_ = false;
};

}  // namespace kinemo::prosody
