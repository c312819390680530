#include "services/coordinator/client/live_client.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"

namespace kinemo::coordinator {
namespace {

using Clock = std::chrono::steady_clock;

double Ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

}  // namespace

double Percentile(std::vector<double> values, double q) {
  if (values.empty()) return 0;
  std::sort(values.begin(), values.end());
  const double rank = std::clamp(q, 0.0, 1.0) * static_cast<double>(values.size() - 1);
  return values[static_cast<std::size_t>(std::lround(rank))];
}

StatusOr<LiveStreamResult> RunLiveStream(const std::shared_ptr<grpc::Channel>& channel,
                                         const std::vector<float>& samples, int rate_hz,
                                         const LiveStreamOptions& options) {
  if (rate_hz <= 0) return InvalidField("rate_hz", "must be > 0");
  if (!(options.chunk_s > 0 && options.chunk_s <= 1)) return InvalidField("chunk_s", "must be in (0, 1]");
  const std::size_t n = std::max<std::size_t>(1, static_cast<std::size_t>(std::lround(options.chunk_s * rate_hz)));
  const std::size_t chunks = (samples.size() + n - 1) / n;
  if (chunks == 0) return InvalidField("samples", "empty");
  LiveStreamResult out;
  out.audio_s = static_cast<double>(samples.size()) / rate_hz;
  out.chunks = chunks;

  auto stub = v1::CoordinatorService::NewStub(channel);
  grpc::ClientContext ctx;
  const double timeout_s = options.timeout_s > 0 ? options.timeout_s : 60 + 3 * out.audio_s;
  ctx.set_deadline(std::chrono::system_clock::now() +
                   std::chrono::milliseconds(static_cast<std::int64_t>(timeout_s * 1000)));
  auto stream = stub->StreamAnimate(&ctx);
  v1::StreamAnimateRequest first;
  *first.mutable_config() = options.config;
  auto* format = first.mutable_config()->mutable_format();
  format->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
  format->set_sample_rate_hz(static_cast<std::uint32_t>(rate_hz));
  format->set_channels(1);
  if (!stream->Write(first)) {
    const grpc::Status s = stream->Finish();
    return Status(static_cast<absl::StatusCode>(s.error_code()), s.error_message());
  }

  // Send times of the chunks, written by the writer thread.
  std::mutex mu;
  std::condition_variable stop_cv;
  bool stop = false;  // the server ended the call: send no more
  std::vector<Clock::time_point> sent(chunks);
  std::size_t sent_count = 0;
  double max_late_ms = 0;
  std::thread writer([&] {
    Clock::time_point t0;
    for (std::size_t k = 0; k < chunks; ++k) {
      const std::size_t first_sample = k * n;
      const std::size_t m = std::min(n, samples.size() - first_sample);
      v1::StreamAnimateRequest q;
      q.mutable_chunk()->set_sequence_number(k);
      q.mutable_chunk()->set_start_time_s(static_cast<double>(first_sample) / rate_hz);
      q.mutable_chunk()->set_data(reinterpret_cast<const char*>(samples.data() + first_sample), m * sizeof(float));
      {
        std::unique_lock<std::mutex> l(mu);
        if (options.realtime && k > 0) {
          const auto due = t0 + std::chrono::microseconds(
                                    static_cast<std::int64_t>(1e6 * static_cast<double>(first_sample) / rate_hz));
          stop_cv.wait_until(l, due, [&] { return stop; });
        }
        if (stop) return;
        sent[k] = Clock::now();
        if (options.realtime && k > 0) {
          const double due_ms = 1e3 * static_cast<double>(first_sample) / rate_hz;
          max_late_ms = std::max(max_late_ms, Ms(sent[k] - t0) - due_ms);
        }
        if (k == 0) t0 = sent[0];
        sent_count = k + 1;
      }
      if (!stream->Write(q)) return;
    }
    stream->WritesDone();
  });

  // The reader: this thread.
  bool have_header = false;
  Clock::time_point first_frame, last_batch, end;
  v1::StreamAnimateResponse r;
  while (stream->Read(&r)) {
    const Clock::time_point now = Clock::now();
    if (r.has_header()) {
      out.header = std::move(*r.mutable_header());
      have_header = true;
    } else if (r.has_frames() && r.frames().frames_size() > 0) {
      std::lock_guard<std::mutex> l(mu);
      if (sent_count == 0) continue;  // (frames follow chunks)
      if (out.frames.empty()) {
        first_frame = now;
        out.first_frame_ms = Ms(now - sent[0]);
      } else {
        out.max_frame_gap_ms = std::max(out.max_frame_gap_ms, Ms(now - last_batch));
      }
      last_batch = now;
      for (auto& f : *r.mutable_frames()->mutable_frames()) {
        // The chunk holding audio time t. Frame times are BVH-rounded (1/30 s
        // is 0.0333333), so, as the planner does, a frame within 1/1000 of a
        // frame before a chunk boundary counts in the next chunk. (Frames
        // never run ahead of the audio sent; one that did would count
        // against the newest chunk.)
        const double t = f.time_s() + 1e-3 * out.header.frame_time_s();
        const double sample = std::max(0.0, t * rate_hz);
        const std::size_t k = std::min(sent_count - 1, static_cast<std::size_t>(sample) / n);
        out.motion_lag_ms.push_back(Ms(now - sent[k]));
        out.frames.push_back(std::move(f));
      }
      if (r.last_chunk_sequence() < sent_count) {
        out.audio_to_frame_ms.push_back(Ms(now - sent[r.last_chunk_sequence()]));
      }
    } else if (r.has_visemes()) {
      out.visemes = std::move(*r.mutable_visemes());
    } else if (r.has_summary()) {
      out.summary = r.summary();
      end = now;
    }
  }
  {
    std::lock_guard<std::mutex> l(mu);
    stop = true;
  }
  stop_cv.notify_all();
  writer.join();
  const grpc::Status s = stream->Finish();
  if (!s.ok()) return Status(static_cast<absl::StatusCode>(s.error_code()), s.error_message());
  if (!have_header || out.frames.empty()) return absl::InternalError("StreamAnimate: no header or no frames");
  out.max_chunk_late_ms = max_late_ms;
  out.motion_lag_p50_ms = Percentile(out.motion_lag_ms, 0.5);
  out.motion_lag_p99_ms = Percentile(out.motion_lag_ms, 0.99);
  out.audio_to_frame_p50_ms = Percentile(out.audio_to_frame_ms, 0.5);
  out.audio_to_frame_p99_ms = Percentile(out.audio_to_frame_ms, 0.99);
  out.wall_s = std::chrono::duration<double>((end == Clock::time_point() ? Clock::now() : end) - sent[0]).count();
  return out;
}

StatusOr<motion::Clip> ClipFromStream(const common::v1::MotionStreamHeader& header,
                                      const std::vector<common::v1::MotionFrame>& frames) {
  std::vector<motion::Joint> joints;
  for (const auto& pj : header.skeleton().joints()) {
    motion::Joint j;
    j.name = pj.name();
    j.parent = pj.parent_index();
    j.offset = {pj.offset().x(), pj.offset().y(), pj.offset().z()};
    for (int c : pj.channels()) {
      if (c < common::v1::CHANNEL_X_POSITION || c > common::v1::CHANNEL_Z_ROTATION) {
        return InvalidField("header.skeleton.joints.channels", "channel ", c, " of ", pj.name(), " is not valid");
      }
      j.channels.push_back(static_cast<motion::ChannelType>(c - common::v1::CHANNEL_X_POSITION));
    }
    if (pj.has_end_site()) {
      j.end_site = Eigen::Vector3d(pj.end_site_offset().x(), pj.end_site_offset().y(), pj.end_site_offset().z());
    }
    joints.push_back(std::move(j));
  }
  motion::Clip clip;
  KINEMO_ASSIGN_OR_RETURN(clip.skeleton, motion::Skeleton::Create(std::move(joints)));
  if (!(header.frame_time_s() > 0)) return InvalidField("header.frame_time_s", "must be > 0");
  clip.frame_time_s = header.frame_time_s();
  const int channels = clip.skeleton.num_channels();
  clip.frames.resize(static_cast<Eigen::Index>(frames.size()), channels);
  for (std::size_t f = 0; f < frames.size(); ++f) {
    if (frames[f].values_size() != channels) {
      return InvalidField("frames", "frame ", f, " has ", frames[f].values_size(), " values, the skeleton ", channels,
                          " channels");
    }
    for (int c = 0; c < channels; ++c) clip.frames(static_cast<Eigen::Index>(f), c) = frames[f].values(c);
  }
  KINEMO_RETURN_IF_ERROR(clip.Validate());
  return clip;
}

}  // namespace kinemo::coordinator
