#include "services/coordinator/core/animate_plan.h"

#include <algorithm>
#include <cmath>

namespace kinemo::coordinator {

std::vector<inference::v1::ProsodyFeatures> GapSteps(double from_s, double to_s) {
  std::vector<inference::v1::ProsodyFeatures> out;
  const double gap = to_s - from_s;
  if (!(gap >= kMinGapStepS)) return out;
  const int n = static_cast<int>(std::ceil(gap / kMaxGapStepS - 1e-9));
  const double step = gap / n;
  for (int i = 0; i < n; ++i) {
    inference::v1::ProsodyFeatures f;
    f.set_start_s(from_s + i * step);
    f.set_end_s(i + 1 == n ? to_s : from_s + (i + 1) * step);
    f.set_length_s(f.end_s() - f.start_s());
    f.set_voiced(false);
    out.push_back(f);
  }
  return out;
}

inference::v1::ProsodyFeatures SyllableStep(const prosody::v1::Syllable& s) {
  inference::v1::ProsodyFeatures f;
  f.set_start_s(s.start_s());
  f.set_end_s(s.end_s());
  f.set_f0_mean_hz(s.f0_mean_hz());
  f.set_intensity_mean_db(s.intensity_mean_db());
  f.set_length_s(s.length_s() > 0 ? s.length_s() : s.end_s() - s.start_s());
  f.set_voiced(s.voiced());
  return f;
}

std::vector<inference::v1::ProsodyFeatures> StepsFromProsody(
    const prosody::v1::ProsodyTrack& track) {
  std::vector<inference::v1::ProsodyFeatures> out;
  double t = 0.0;
  for (const prosody::v1::Syllable& s : track.syllables()) {
    for (auto& g : GapSteps(t, s.start_s())) out.push_back(std::move(g));
    out.push_back(SyllableStep(s));
    t = std::max(t, s.end_s());
  }
  for (auto& g : GapSteps(t, track.duration_s())) out.push_back(std::move(g));
  return out;
}

void FrameTally::Add(const google::protobuf::RepeatedPtrField<prosody::v1::Frame>& frames) {
  for (const prosody::v1::Frame& f : frames) {
    if (f.voiced()) {
      ++voiced;
      f0_sum_hz += f.f0_hz();
    }
  }
  this->frames += static_cast<std::uint64_t>(frames.size());
}

v1::ProsodySummary SummarizeProsody(const prosody::v1::ProsodyTrack& track) {
  FrameTally tally;
  tally.Add(track.frames());
  return SummarizeProsody(track, tally);
}

v1::ProsodySummary SummarizeProsody(const prosody::v1::ProsodyTrack& track, const FrameTally& tally) {
  v1::ProsodySummary out;
  out.set_duration_s(track.duration_s());
  if (tally.frames > 0) {
    out.set_voiced_fraction(static_cast<double>(tally.voiced) / static_cast<double>(tally.frames));
  } else if (!track.syllables().empty()) {
    // Without frames: the voiced share of the syllables' time.
    double voiced_s = 0.0, f0_weighted = 0.0;
    for (const auto& s : track.syllables()) {
      if (!s.voiced()) continue;
      voiced_s += s.end_s() - s.start_s();
      f0_weighted += s.f0_mean_hz() * (s.end_s() - s.start_s());
    }
    if (track.duration_s() > 0) out.set_voiced_fraction(voiced_s / track.duration_s());
    if (voiced_s > 0) out.set_f0_mean_hz(f0_weighted / voiced_s);
  }
  if (tally.voiced > 0) out.set_f0_mean_hz(tally.f0_sum_hz / static_cast<double>(tally.voiced));
  out.set_syllables(static_cast<std::uint32_t>(track.syllables_size()));
  *out.mutable_accents() = track.accents();
  *out.mutable_pauses() = track.pauses();
  *out.mutable_words() = track.words();
  return out;
}

StatusOr<v1::Method> ResolveMethod(v1::Method requested, v1::Method default_method,
                                   const char* field) {
  if (!v1::Method_IsValid(requested)) {
    return absl::InvalidArgumentError(absl::StrCat(field, ": unknown method ", requested));
  }
  if (requested != v1::METHOD_UNSPECIFIED) return requested;
  if (default_method != v1::METHOD_UNSPECIFIED && v1::Method_IsValid(default_method)) {
    return default_method;
  }
  return v1::METHOD_GESTURE_CONTROLLER;
}

planner::v1::BeliefStep ToBeliefStep(const inference::v1::Belief& b) {
  planner::v1::BeliefStep out;
  out.set_step(b.step());
  out.set_start_s(b.start_s());
  out.set_end_s(b.end_s());
  *out.mutable_probabilities() = b.probabilities();
  return out;
}

StatusOr<AudioClock> AudioClock::Create(const common::v1::AudioFormat& format, double max_audio_s,
                                       const char* field, const char* limit_option) {
  std::uint64_t sample_bytes = 0;
  if (format.encoding() == common::v1::AUDIO_ENCODING_PCM_S16LE) {
    sample_bytes = 2;
  } else if (format.encoding() == common::v1::AUDIO_ENCODING_PCM_F32LE) {
    sample_bytes = 4;
  } else {
    return InvalidField(kinemo::StrCat(field, ".encoding"), "must be a PCM encoding");
  }
  if (format.sample_rate_hz() < 8000 || format.sample_rate_hz() > 96000) {
    return InvalidField(kinemo::StrCat(field, ".sample_rate_hz"), format.sample_rate_hz(),
                        " is not supported (8000..96000)");
  }
  if (format.channels() > 2) {
    return InvalidField(kinemo::StrCat(field, ".channels"), format.channels(), " is not supported (1 or 2)");
  }
  const std::uint64_t channels = std::max<std::uint32_t>(1, format.channels());
  return AudioClock(format.sample_rate_hz(), sample_bytes * channels, max_audio_s, limit_option);
}

Status AudioClock::Add(const common::v1::AudioChunk& chunk) {
  if (chunk.sequence_number() != chunks_) {
    return InvalidField("chunk.sequence_number", chunk.sequence_number(), " out of sequence (", chunks_,
                        " expected)");
  }
  const std::uint64_t bytes = chunk.data().size();
  if (bytes % frame_bytes_ != 0) {
    return InvalidField("chunk.data", bytes, " bytes is not a whole number of sample frames (", frame_bytes_,
                        " bytes each)");
  }
  const std::uint64_t frames = bytes / frame_bytes_;
  if (static_cast<double>(frames) > rate_hz_) {
    return InvalidField("chunk.data", static_cast<double>(frames) / rate_hz_, " s of audio; at most 1 s per chunk");
  }
  if (static_cast<double>(frames_ + frames) / rate_hz_ > max_audio_s_) {
    return InvalidField("chunk", "the stream's audio would pass ", max_audio_s_, " s (", limit_option_, ")");
  }
  frames_ += frames;
  ++chunks_;
  return absl::OkStatus();
}

}  // namespace kinemo::coordinator
