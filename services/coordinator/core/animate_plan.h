// Pure pieces of the speech -> animation pipeline (no gRPC): prosody track ->
// inference steps, prosody summary, method choice, and viseme / motion
// helpers the coordinator's Animate and StreamAnimate use.
#pragma once

#include <vector>

#include "common/status/status.h"
#include "kinemo/coordinator/v1/coordinator.pb.h"
#include "kinemo/inference/v1/inference.pb.h"
#include "kinemo/planner/v1/planner.pb.h"
#include "kinemo/prosody/v1/prosody.pb.h"

namespace kinemo::coordinator {

// Longest unvoiced step made of a pause or a gap between syllables, in
// seconds (longer gaps become several steps), as the inference corpus does.
inline constexpr double kMaxGapStepS = 0.5;
// Gaps shorter than this are not turned into steps, in seconds.
inline constexpr double kMinGapStepS = 0.02;

// Steps of the Gesture Controller's input (x_t): one per syllable, plus
// unvoiced steps of at most kMaxGapStepS tiling pauses and gaps from 0 to
// the end of the recording.
std::vector<inference::v1::ProsodyFeatures> StepsFromProsody(
    const prosody::v1::ProsodyTrack& track);

// Unvoiced gap steps between `from_s` and `to_s` (empty if shorter than
// kMinGapStepS).
std::vector<inference::v1::ProsodyFeatures> GapSteps(double from_s, double to_s);

// One syllable as a step.
inference::v1::ProsodyFeatures SyllableStep(const prosody::v1::Syllable& syllable);

// Summary of a track (duration, voiced fraction and mean F0 from the
// frames, syllable count, accents, pauses, words).
v1::ProsodySummary SummarizeProsody(const prosody::v1::ProsodyTrack& track);

// The frames' part of the summary, counted as they arrive in batches (a long
// recording's frames are not kept).
struct FrameTally {
  std::uint64_t frames = 0, voiced = 0;
  double f0_sum_hz = 0;
  void Add(const google::protobuf::RepeatedPtrField<prosody::v1::Frame>& frames);
};
// The same summary, with the frames counted in `tally` (the track's own
// frames are not looked at).
v1::ProsodySummary SummarizeProsody(const prosody::v1::ProsodyTrack& track, const FrameTally& tally);

// The method that runs: the request's, else `default_method`, else the
// Gesture Controller. INVALID_ARGUMENT naming `field` for unknown values.
StatusOr<v1::Method> ResolveMethod(v1::Method requested, v1::Method default_method,
                                   const char* field);

// Beliefs (inference) as planner belief steps (same fields).
planner::v1::BeliefStep ToBeliefStep(const inference::v1::Belief& belief);

// The audio clock of a live stream (StreamAnimate): checks the PCM format
// and each chunk, and counts the audio received, which is the media time
// the motion is driven to.
class AudioClock {
 public:
  // INVALID_ARGUMENT naming `field` (e.g. "config.format") for a format that
  // is not PCM S16LE / F32LE at 8000..96000 Hz with 1 or 2 channels;
  // max_audio_s bounds the stream's audio (the option `limit_option` sets).
  static StatusOr<AudioClock> Create(const common::v1::AudioFormat& format, double max_audio_s,
                                     const char* field, const char* limit_option = "animate.max_audio_s");
  // Counts a chunk. INVALID_ARGUMENT naming chunk.sequence_number (not the
  // next one: 0, then +1), chunk.data (not whole sample frames, or more
  // than 1 s) or chunk (the stream would pass max_audio_s); nothing is
  // counted then.
  Status Add(const common::v1::AudioChunk& chunk);
  // Seconds of audio received.
  double audio_s() const { return static_cast<double>(frames_) / rate_hz_; }
  // Chunks received, and the sequence number of the last one.
  std::uint64_t chunks() const { return chunks_; }
  std::uint64_t last_sequence() const { return chunks_ > 0 ? chunks_ - 1 : 0; }

 private:
  AudioClock(double rate_hz, std::uint64_t frame_bytes, double max_audio_s, const char* limit_option)
      : rate_hz_(rate_hz), frame_bytes_(frame_bytes), max_audio_s_(max_audio_s), limit_option_(limit_option) {}
  double rate_hz_;
  std::uint64_t frame_bytes_;  // bytes per sample frame (all channels)
  double max_audio_s_;
  const char* limit_option_;
  std::uint64_t frames_ = 0, chunks_ = 0;
};

}  // namespace kinemo::coordinator
