// Client side of StreamAnimate, shared by `kinemo animate --stream`,
// `kinemo bench e2e` and `kinemo bench load`: streams a recording as 20 ms
// PCM chunks (at real-time pace, or as fast as the stream takes them),
// collects the motion, the visemes and the summary, and measures the live
// timing as a user feels it, on the client's wall clock. Many streams at once
// cost the client no thread each: every stream is a callback reactor, and
// one pacing thread sends the chunks that are due (RunLiveStreams).
// Measured per stream:
//   - motion lag of a frame with time t = (wall time the frame is received)
//     − (wall time the chunk that contains audio time t was sent) (a frame
//     within 1/1000 of a frame of a chunk's end belongs to the next chunk:
//     BVH frame times are rounded, 1/30 s is written 0.0333333);
//   - first frame = first frame received − first chunk sent;
//   - max frame gap = longest wall-time gap between consecutive frame
//     batches received, from the first frame to the last chunk's frames
//     (pauses included);
//   - face lag (docs/face.md) = the motion lag of the frames where the mouth
//     changes (the dominant OVR viseme of MotionFrame.face differs from the
//     previous frame's): the face of audio time t travels in the frame of
//     t, so this is when the mouth's change for the audio at t is seen,
//     after that audio was sent;
//   - audio → frame (server time, `kinemo bench e2e`'s older figure) = a
//     frame batch received − the chunk named by its last_chunk_sequence sent.
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <vector>

#include <grpcpp/channel.h>

#include "common/motion/skeleton.h"
#include "common/status/status.h"
#include "kinemo/coordinator/v1/coordinator.pb.h"

namespace kinemo::coordinator {

struct LiveStreamOptions {
  // Chunks at real-time pace (each sent when its audio would have been
  // captured), else as fast as the stream takes them.
  bool realtime = true;
  double chunk_s = 0.02;
  // Whole-call deadline; 0 = 60 s + 3 s per second of audio.
  double timeout_s = 0;
  // Models, visemes, keywords, style, ...; `format` is set from the audio
  // (PCM F32LE mono).
  v1::StreamAnimateConfig config;
  // Keep the frames (LiveStreamResult.frames); false keeps only the counts
  // and the timing (`kinemo bench load`).
  bool keep_frames = true;
  // RunLiveStreams: the audio starts once every stream is set up (its
  // header received, or it ended), so that the lag figures are those of
  // running streams, not of N streams opening in the same instant (the
  // set-up is measured apart: LiveStreamResult.setup_ms).
  bool start_after_setup = false;
  // Sees each frame as it arrives (before it is kept), with the stream's
  // header and when the chunk holding the frame's audio was sent: on gRPC's
  // callback thread, under the stream's lock, so keep it short (`kinemo
  // animate --vmc` sends the frame's VMC packets from here). RunLiveStream
  // only (one stream).
  std::function<void(const common::v1::MotionStreamHeader& header, const common::v1::MotionFrame& frame,
                     std::chrono::steady_clock::time_point audio_sent)>
      on_frame;
};

struct LiveStreamResult {
  common::v1::MotionStreamHeader header;
  std::vector<common::v1::MotionFrame> frames;  // with keep_frames
  std::uint64_t frame_count = 0;
  std::optional<planner::v1::VisemeTrack> visemes;
  v1::StreamAnimateSummary summary;
  double audio_s = 0;
  std::uint64_t chunks = 0;
  // Per frame (motion lag) and per frame batch (audio → frame), in ms.
  std::vector<double> motion_lag_ms, audio_to_frame_ms;
  // When the frame of each motion_lag_ms sample arrived: steady_clock time
  // since its epoch, in s (`kinemo bench chaos` leaves out fault windows).
  std::vector<double> motion_lag_received_s;
  double motion_lag_p50_ms = 0, motion_lag_p99_ms = 0;
  double audio_to_frame_p50_ms = 0, audio_to_frame_p99_ms = 0;
  double first_frame_ms = 0, max_frame_gap_ms = 0;
  // Frames that carried a face; face lag per change of the mouth, in ms.
  std::uint64_t face_frames = 0;
  std::vector<double> face_lag_ms;
  double face_lag_p95_ms = 0;
  double setup_ms = 0;  // config sent -> header received
  // Real-time pace: how late the client sent its latest chunk behind its
  // schedule (a late chunk delays its frames; a frame gap that long is the
  // client's, not the server's).
  double max_chunk_late_ms = 0;
  double wall_s = 0;  // first chunk sent -> summary received
  // Tone changes of the session's Vleo (config.session_id), as received:
  // latency_ms = the client's wall clock when the tone_change arrived (with
  // the first frames made in the tone) − its seen_time (when the cube
  // tracker's event reached the coordinator; one host, or synchronised
  // clocks).
  struct ReceivedTone {
    v1::ToneChange change;
    double latency_ms = 0;
  };
  std::vector<ReceivedTone> tone_changes;
};

// Streams `samples` (mono, `rate_hz`) through the coordinator's
// StreamAnimate on `channel`. The server's error (with its code) if the
// stream fails; INTERNAL if it ends without a header or frames.
StatusOr<LiveStreamResult> RunLiveStream(const std::shared_ptr<grpc::Channel>& channel,
                                         const std::vector<float>& samples, int rate_hz,
                                         const LiveStreamOptions& options);

// `streams` such streams at once, all on `channel`, each with the same
// recording; with real-time pace, stream i's chunks are due `i / streams`
// of a chunk after stream 0's (streams start spread over one chunk, as
// independent speakers do). One result per stream, in order (a refused
// stream: RESOURCE_EXHAUSTED, ...). INVALID_ARGUMENT (as the only result)
// for bad arguments.
std::vector<StatusOr<LiveStreamResult>> RunLiveStreams(const std::shared_ptr<grpc::Channel>& channel,
                                                       const std::vector<float>& samples, int rate_hz,
                                                       const LiveStreamOptions& options, int streams);

// The streamed motion as a clip (for BVH output). INVALID_ARGUMENT if the
// header's skeleton is not valid or a frame's value count does not match it.
StatusOr<motion::Clip> ClipFromStream(const common::v1::MotionStreamHeader& header,
                                      const std::vector<common::v1::MotionFrame>& frames);

// The value at quantile q in [0, 1] (nearest rank); 0 for an empty set.
double Percentile(std::vector<double> values, double q);

}  // namespace kinemo::coordinator
