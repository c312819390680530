// Client side of AnimateChunked (`kinemo animate`, `kinemo bench long`): a
// recording of any length read from its file block by block, mixed to mono
// and resampled to 16 kHz (what the prosody analysis runs at) on the client,
// sent as 1 s PCM F32LE chunks; the motion written to a stream as its pieces
// arrive, the face pieces kept only when asked for. Memory: one block of the
// file, one chunk, one piece of motion (and the face when kept).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <ostream>

#include <grpcpp/channel.h>

#include "common/audio/recording_reader.h"
#include "common/status/status.h"
#include "kinemo/coordinator/v1/coordinator.pb.h"

namespace kinemo::coordinator {

// The rate recordings are sent at: the prosody analysis' (ProsodyOptions
// analysis_rate_hz default).
inline constexpr int kChunkedAudioRateHz = 16000;

// Where a call is, for progress lines.
struct ChunkedProgress {
  // Seconds of the recording sent so far, and its length (the file
  // header's).
  double sent_s = 0, audio_s = 0;
  // A stage that started (after the upload); ANIMATE_STAGE_UNSPECIFIED
  // while uploading.
  v1::AnimateStage stage = v1::ANIMATE_STAGE_UNSPECIFIED;
  // Motion bytes received so far.
  std::uint64_t motion_bytes = 0;
};

struct ChunkedAnimateOptions {
  // The request (models, method, style, visemes, format, ...); its audio's
  // format is set here (F32LE, 16 kHz, mono) and its name kept.
  v1::AnimateRequest request;
  // Whole-call deadline; 0 = ChunkedTimeoutS(the recording's length).
  double timeout_s = 0;
  // Called while uploading (about every 1 % of the recording, and once the
  // last chunk is sent), at each stage, and every 16 MiB of motion received.
  std::function<void(const ChunkedProgress&)> on_progress;
};

struct ChunkedAnimateResult {
  // Animate's response without the motion and visemes.
  v1::AnimateResponse result;
  // Seconds of audio sent; frames and bytes of motion received; face frames
  // received (one per motion frame when the stack has a face model).
  double audio_s = 0;
  std::int64_t frames = 0;
  std::uint64_t motion_bytes = 0;
  std::int64_t face_frames = 0;
};

// The default deadline of a recording of `audio_s` seconds: 60 s + 0.25 s
// per second of audio (an hour took 65 s with the slowest method, the
// Gesture Controller, on 2 cores: docs/coordinator.md, "Long recordings").
inline double ChunkedTimeoutS(double audio_s) { return 60.0 + 0.25 * audio_s; }

// Animates the recording `reader` reads (its out_rate_hz must be
// kChunkedAudioRateHz). BVH text (or, with request.format CLIP, the clip
// pieces' frames are counted but not written) goes to `motion` as it
// arrives; viseme pieces are appended to `visemes` and face pieces (the
// AnimateResponse.face of the whole motion, 150 bytes a frame) to `face`
// when not null (the face frames are counted either way). Errors are the
// server's status (FromGrpcStatus: its code and message) or the reader's.
StatusOr<ChunkedAnimateResult> AnimateRecording(const std::shared_ptr<grpc::Channel>& channel,
                                                audio::RecordingReader& reader, const ChunkedAnimateOptions& options,
                                                std::ostream& motion, planner::v1::VisemeTrack* visemes,
                                                common::v1::FaceTrack* face = nullptr);

}  // namespace kinemo::coordinator
