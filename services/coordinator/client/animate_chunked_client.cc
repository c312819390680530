#include "services/coordinator/client/animate_chunked_client.h"

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cstring>
#include <string>
#include <vector>

#include "common/grpc/status_mapping.h"

namespace kinemo::coordinator {
namespace {

// "Frames: N" of a BVH header, or -1.
std::int64_t BvhFrames(const std::string& text) {
  const auto at = text.find("\nFrames:");
  if (at == std::string::npos) return -1;
  return std::strtoll(text.c_str() + at + 8, nullptr, 10);
}

}  // namespace

StatusOr<ChunkedAnimateResult> AnimateRecording(const std::shared_ptr<grpc::Channel>& channel,
                                                audio::RecordingReader& reader, const ChunkedAnimateOptions& options,
                                                std::ostream& motion, planner::v1::VisemeTrack* visemes,
                                                common::v1::FaceTrack* face) {
  if (reader.out_rate_hz() != kChunkedAudioRateHz) {
    return InvalidField("reader", "reads at ", reader.out_rate_hz(), " Hz, not ", kChunkedAudioRateHz);
  }
  auto stub = v1::CoordinatorService::NewStub(channel);
  const double audio_s = reader.info().duration_s;
  const double timeout_s = options.timeout_s > 0 ? options.timeout_s : ChunkedTimeoutS(audio_s);
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() +
                   std::chrono::milliseconds(static_cast<std::int64_t>(timeout_s * 1000)));
  ctx.set_wait_for_ready(true);
  auto stream = stub->AnimateChunked(&ctx);
  ChunkedProgress progress;
  progress.audio_s = audio_s;
  auto report = [&] {
    if (options.on_progress) options.on_progress(progress);
  };
  // The server answers only after the last chunk (or with an error, which
  // ends the writes): one thread can write everything, then read.
  v1::AnimateChunkedRequest msg;
  auto* config = msg.mutable_config();
  *config->mutable_request() = options.request;
  auto* format = config->mutable_request()->mutable_audio()->mutable_format();
  format->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
  format->set_sample_rate_hz(kChunkedAudioRateHz);
  format->set_channels(1);
  config->mutable_request()->mutable_audio()->clear_data();
  config->set_expected_duration_s(audio_s);
  bool open = stream->Write(msg);
  // 1 s chunks at 16 kHz.
  std::vector<float> pending, block;
  std::uint64_t sequence = 0;
  double sent_s = 0, next_report_s = 0;
  Status read_error;
  auto send = [&](std::size_t n) {
    v1::AnimateChunkedRequest c;
    auto* chunk = c.mutable_chunk();
    chunk->set_sequence_number(sequence++);
    chunk->set_start_time_s(sent_s);
    chunk->mutable_data()->assign(reinterpret_cast<const char*>(pending.data()), n * sizeof(float));
    pending.erase(pending.begin(), pending.begin() + static_cast<std::ptrdiff_t>(n));
    sent_s += static_cast<double>(n) / kChunkedAudioRateHz;
    return stream->Write(c);
  };
  bool more = true;
  while (open && more) {
    block.clear();
    auto r = reader.Read(kChunkedAudioRateHz * 4, &block);  // a quarter second at 16 kHz, more at 44.1 kHz
    if (!r.ok()) {
      read_error = r.status();
      break;
    }
    more = *r;
    pending.insert(pending.end(), block.begin(), block.end());
    while (open && pending.size() >= static_cast<std::size_t>(kChunkedAudioRateHz)) open = send(kChunkedAudioRateHz);
    if (!more && open && !pending.empty()) open = send(pending.size());
    if (sent_s >= next_report_s || !more) {  // and once the whole recording is sent
      progress.sent_s = sent_s;
      report();
      next_report_s = sent_s + std::max(1.0, audio_s / 100);
    }
  }
  if (!read_error.ok()) {
    ctx.TryCancel();
    (void)stream->Finish();
    return read_error;
  }
  if (open) stream->WritesDone();
  progress.sent_s = sent_s;
  ChunkedAnimateResult out;
  out.audio_s = sent_s;
  v1::AnimateChunkedResponse r;
  std::uint64_t next_motion_report = 16u << 20;
  while (stream->Read(&r)) {
    switch (r.message_case()) {
      case v1::AnimateChunkedResponse::kProgress:
        progress.stage = r.progress().stage();
        report();
        break;
      case v1::AnimateChunkedResponse::kMotion: {
        const auto& piece = r.motion();
        if (piece.has_bvh()) {
          if (out.motion_bytes == 0) out.frames = BvhFrames(piece.bvh());
          motion.write(piece.bvh().data(), static_cast<std::streamsize>(piece.bvh().size()));
          out.motion_bytes += piece.bvh().size();
        } else if (piece.has_frames()) {
          out.frames += piece.frames().frames_size();
          out.motion_bytes += piece.ByteSizeLong();
        }
        progress.motion_bytes = out.motion_bytes;
        if (out.motion_bytes >= next_motion_report) {
          report();
          next_motion_report += 16u << 20;
        }
        break;
      }
      case v1::AnimateChunkedResponse::kVisemes:
        if (visemes != nullptr) {
          if (r.visemes().categories_size() > 0) {
            visemes->set_frame_time_s(r.visemes().frame_time_s());
            *visemes->mutable_categories() = r.visemes().categories();
          }
          for (const auto& f : r.visemes().frames()) *visemes->add_frames() = f;
        }
        break;
      case v1::AnimateChunkedResponse::kFace:
        out.face_frames += r.face().frames_size();
        if (face != nullptr) {
          face->set_frame_time_s(r.face().frame_time_s());
          face->mutable_frames()->Reserve(face->frames_size() + r.face().frames_size());
          for (auto& f : *r.mutable_face()->mutable_frames()) *face->add_frames() = std::move(f);
        }
        break;
      case v1::AnimateChunkedResponse::kResult:
        out.result = std::move(*r.mutable_result());
        break;
      default:
        break;
    }
  }
  const grpc::Status s = stream->Finish();
  if (!s.ok()) return FromGrpcStatus(s);
  if (!motion) return absl::UnavailableError("the motion could not be written");
  return out;
}

}  // namespace kinemo::coordinator
