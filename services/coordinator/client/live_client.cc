#include "services/coordinator/client/live_client.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <functional>
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

namespace {

using Request = v1::StreamAnimateRequest;
using Response = v1::StreamAnimateResponse;

// The messages every stream sends: built once, shared read-only by the
// streams (concurrent serialisation of a const message is safe).
struct Script {
  Request config;
  std::vector<Request> chunks;
  std::size_t samples_per_chunk = 0;
  int rate_hz = 0;
  double audio_s = 0;
  // When chunk k is due after a stream's start (its audio captured).
  Clock::duration Due(std::size_t k) const {
    return std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(static_cast<double>(k * samples_per_chunk) / rate_hz));
  }
};

// Signals the caller when every stream is over.
struct Countdown {
  std::mutex mu;
  std::condition_variable cv;
  int left = 0;
  void Done() {
    std::lock_guard<std::mutex> l(mu);
    if (--left == 0) cv.notify_all();
  }
};

// One stream: a callback reactor. The chunks are queued by the pacing
// thread (real time) or by the reactor itself as each write completes (as
// fast as the stream takes them); reads and the measures run in gRPC's
// callbacks. Every field is guarded by mu_.
class LiveCall final : public grpc::ClientBidiReactor<Request, Response> {
 public:
  // `countdown`: every call's end; `setup`: every call's header (or end).
  LiveCall(const Script* script, const LiveStreamOptions* options, Countdown* countdown, Countdown* setup,
           double timeout_s)
      : script_(script), options_(options), countdown_(countdown), setup_(setup), sent_(script->chunks.size()) {
    context_.set_deadline(std::chrono::system_clock::now() +
                          std::chrono::milliseconds(static_cast<std::int64_t>(timeout_s * 1000)));
    out_.audio_s = script->audio_s;
    out_.chunks = script->chunks.size();
    const std::size_t expected = static_cast<std::size_t>(script->audio_s * 60) + 64;  // frames, generously
    out_.motion_lag_ms.reserve(expected);
    out_.motion_lag_received_s.reserve(expected);
    out_.audio_to_frame_ms.reserve(expected);
    if (options->keep_frames) out_.frames.reserve(expected);
  }

  void Start(v1::CoordinatorService::Stub* stub) {
    stub->async()->StreamAnimate(&context_, this);
    std::lock_guard<std::mutex> l(mu_);
    opened_ = Clock::now();
    StartRead(&in_);
    AddHold();  // writes come from the pacing thread too
    writing_ = true;
    StartWrite(&script_->config);
    StartCall();
  }

  // Real time: queues chunk `k` (the next), due at `due`. False once the
  // stream takes no more (the server ended it).
  bool Offer(std::size_t k, Clock::time_point due) {
    std::lock_guard<std::mutex> l(mu_);
    if (stopped_) return false;
    const Clock::time_point now = Clock::now();
    Queue(k, now);
    if (k > 0) max_late_ms_ = std::max(max_late_ms_, Ms(now - due));
    Pump();
    return true;
  }

  // As fast as taken, after the set-up: the chunks may go.
  void Go() {
    std::lock_guard<std::mutex> l(mu_);
    go_ = true;
    Pump();
  }

  // After OnDone.
  StatusOr<LiveStreamResult> Result() {
    std::lock_guard<std::mutex> l(mu_);
    if (!status_.ok()) return Status(static_cast<absl::StatusCode>(status_.error_code()), status_.error_message());
    if (!have_header_ || out_.frame_count == 0) return absl::InternalError("StreamAnimate: no header or no frames");
    out_.max_chunk_late_ms = max_late_ms_;
    out_.motion_lag_p50_ms = Percentile(out_.motion_lag_ms, 0.5);
    out_.motion_lag_p99_ms = Percentile(out_.motion_lag_ms, 0.99);
    out_.face_lag_p95_ms = Percentile(out_.face_lag_ms, 0.95);
    out_.audio_to_frame_p50_ms = Percentile(out_.audio_to_frame_ms, 0.5);
    out_.audio_to_frame_p99_ms = Percentile(out_.audio_to_frame_ms, 0.99);
    out_.wall_s = sent_count_ == 0 ? 0 : std::chrono::duration<double>(end_ - sent_[0]).count();
    return std::move(out_);
  }

 private:
  // The chunk holding audio time `time_s` (as the motion lag counts it below).
  std::size_t ChunkOf(double time_s) const {
    const double t = time_s + 1e-3 * out_.header.frame_time_s();
    const double sample = std::max(0.0, t * script_->rate_hz);
    return std::min(sent_count_ - 1, static_cast<std::size_t>(sample) / script_->samples_per_chunk);
  }
  void Queue(std::size_t k, Clock::time_point now) {
    sent_[k] = now;
    sent_count_ = k + 1;
    pending_.push_back(&script_->chunks[k]);
  }
  // Starts the next write (or the half-close after the last chunk).
  void Pump() {
    if (stopped_ || writing_) return;
    if (!options_->realtime && go_ && pending_.empty() && sent_count_ < sent_.size()) Queue(sent_count_, Clock::now());
    if (!pending_.empty()) {
      writing_ = true;
      const Request* r = pending_.front();
      pending_.pop_front();
      StartWrite(r);
    } else if (sent_count_ == sent_.size() && !writes_done_) {
      writes_done_ = true;
      StartWritesDone();
      ReleaseHold();
    }
  }
  void ReleaseHold() {
    if (hold_released_) return;
    hold_released_ = true;
    RemoveHold();
  }
  void Stop() {
    stopped_ = true;
    pending_.clear();
    ReleaseHold();
  }

  void OnWriteDone(bool ok) override {
    std::lock_guard<std::mutex> l(mu_);
    writing_ = false;
    if (!ok) return Stop();  // the call is over; OnDone says why
    Pump();
  }
  void OnReadDone(bool ok) override {
    std::lock_guard<std::mutex> l(mu_);
    if (!ok) return Stop();
    OnResponse(Clock::now());
    StartRead(&in_);
  }
  void OnDone(const grpc::Status& s) override {
    bool count_setup = false;  // ended before its header
    {
      std::lock_guard<std::mutex> l(mu_);
      status_ = s;
      if (end_ == Clock::time_point()) end_ = Clock::now();
      count_setup = !counted_setup_;
      counted_setup_ = true;
    }
    if (count_setup) setup_->Done();
    countdown_->Done();
  }

  void OnResponse(Clock::time_point now) {
    Response& r = in_;
    if (r.has_header()) {
      out_.header = std::move(*r.mutable_header());
      have_header_ = true;
      out_.setup_ms = Ms(now - opened_);
      if (!counted_setup_) {
        counted_setup_ = true;
        setup_->Done();  // (only counts down: takes no lock of ours)
      }
    } else if (r.has_frames() && r.frames().frames_size() > 0) {
      if (sent_count_ == 0) return;  // (frames follow chunks)
      if (out_.frame_count == 0) {
        out_.first_frame_ms = Ms(now - sent_[0]);
      } else {
        out_.max_frame_gap_ms = std::max(out_.max_frame_gap_ms, Ms(now - last_batch_));
      }
      last_batch_ = now;
      if (options_->on_frame) {
        for (const auto& f : r.frames().frames()) options_->on_frame(out_.header, f, sent_[ChunkOf(f.time_s())]);
      }
      const std::size_t n = script_->samples_per_chunk;
      for (auto& f : *r.mutable_frames()->mutable_frames()) {
        // The chunk holding audio time t. Frame times are BVH-rounded (1/30 s
        // is 0.0333333), so, as the planner does, a frame within 1/1000 of a
        // frame before a chunk boundary counts in the next chunk. (Frames
        // never run ahead of the audio sent; one that did would count
        // against the newest chunk.)
        const double t = f.time_s() + 1e-3 * out_.header.frame_time_s();
        const double sample = std::max(0.0, t * script_->rate_hz);
        const std::size_t k = std::min(sent_count_ - 1, static_cast<std::size_t>(sample) / n);
        out_.motion_lag_ms.push_back(Ms(now - sent_[k]));
        out_.motion_lag_received_s.push_back(std::chrono::duration<double>(now.time_since_epoch()).count());
        // The face came with the frame: its lag at each change of the mouth
        // (the dominant OVR viseme differs from the previous frame's).
        if (f.has_face() && f.face().ovr_visemes_size() > 0) {
          ++out_.face_frames;
          const auto& w = f.face().ovr_visemes();
          const int dominant = static_cast<int>(std::max_element(w.begin(), w.end()) - w.begin());
          if (last_viseme_ >= 0 && dominant != last_viseme_) out_.face_lag_ms.push_back(Ms(now - sent_[k]));
          last_viseme_ = dominant;
        }
        ++out_.frame_count;
        if (options_->keep_frames) out_.frames.push_back(std::move(f));
      }
      if (r.last_chunk_sequence() < sent_count_) {
        out_.audio_to_frame_ms.push_back(Ms(now - sent_[r.last_chunk_sequence()]));
      }
    } else if (r.has_tone_change()) {
      const auto& seen = r.tone_change().seen_time();
      const double seen_ms = static_cast<double>(seen.seconds()) * 1e3 + seen.nanos() * 1e-6;
      const double now_ms =
          std::chrono::duration<double, std::milli>(std::chrono::system_clock::now().time_since_epoch()).count();
      out_.tone_changes.push_back({std::move(*r.mutable_tone_change()), now_ms - seen_ms});
    } else if (r.has_visemes()) {
      out_.visemes = std::move(*r.mutable_visemes());
    } else if (r.has_summary()) {
      out_.summary = r.summary();
      end_ = now;
    }
  }

  const Script* const script_;
  const LiveStreamOptions* const options_;
  Countdown* const countdown_;
  Countdown* const setup_;
  bool counted_setup_ = false;
  bool go_ = !options_->start_after_setup;  // (as fast as taken) the chunks may go
  Clock::time_point opened_;
  grpc::ClientContext context_;
  std::mutex mu_;
  Response in_;
  std::deque<const Request*> pending_;  // queued, not yet written
  bool writing_ = false, writes_done_ = false, stopped_ = false, hold_released_ = false;
  std::vector<Clock::time_point> sent_;  // when each chunk was queued (captured)
  std::size_t sent_count_ = 0;
  double max_late_ms_ = 0;
  bool have_header_ = false;
  Clock::time_point last_batch_, end_;
  int last_viseme_ = -1;  // dominant OVR viseme of the last frame with a face
  grpc::Status status_;
  LiveStreamResult out_;
};

// Real time: one thread sends every stream's due chunks, earliest first.
void Pace(const Script& script, const std::vector<std::unique_ptr<LiveCall>>& calls,
          const std::vector<Clock::time_point>& starts) {
  struct Next {
    Clock::time_point due;
    std::size_t call, chunk;
    bool operator>(const Next& o) const { return due > o.due; }
  };
  std::vector<Next> heap;
  heap.reserve(calls.size());
  for (std::size_t i = 0; i < calls.size(); ++i) heap.push_back({starts[i], i, 0});
  std::make_heap(heap.begin(), heap.end(), std::greater<>());
  while (!heap.empty()) {
    std::pop_heap(heap.begin(), heap.end(), std::greater<>());
    Next next = heap.back();
    heap.pop_back();
    std::this_thread::sleep_until(next.due);
    if (!calls[next.call]->Offer(next.chunk, next.due)) continue;  // ended by the server
    if (++next.chunk == script.chunks.size()) continue;
    next.due = starts[next.call] + script.Due(next.chunk);
    heap.push_back(next);
    std::push_heap(heap.begin(), heap.end(), std::greater<>());
  }
}

}  // namespace

std::vector<StatusOr<LiveStreamResult>> RunLiveStreams(const std::shared_ptr<grpc::Channel>& channel,
                                                       const std::vector<float>& samples, int rate_hz,
                                                       const LiveStreamOptions& options, int streams) {
  std::vector<StatusOr<LiveStreamResult>> results;
  auto refuse = [&](Status s) {
    results.push_back(std::move(s));
    return std::move(results);
  };
  if (rate_hz <= 0) return refuse(InvalidField("rate_hz", "must be > 0"));
  if (!(options.chunk_s > 0 && options.chunk_s <= 1)) return refuse(InvalidField("chunk_s", "must be in (0, 1]"));
  if (streams < 1 || streams > 4096) return refuse(InvalidField("streams", "must be in [1, 4096]"));
  if (samples.empty()) return refuse(InvalidField("samples", "empty"));
  if (options.on_frame && streams != 1) return refuse(InvalidField("on_frame", "takes one stream"));
  Script script;
  script.rate_hz = rate_hz;
  script.samples_per_chunk = std::max<std::size_t>(1, static_cast<std::size_t>(std::lround(options.chunk_s * rate_hz)));
  script.audio_s = static_cast<double>(samples.size()) / rate_hz;
  *script.config.mutable_config() = options.config;
  auto* format = script.config.mutable_config()->mutable_format();
  format->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
  format->set_sample_rate_hz(static_cast<std::uint32_t>(rate_hz));
  format->set_channels(1);
  const std::size_t n = script.samples_per_chunk;
  script.chunks.resize((samples.size() + n - 1) / n);
  for (std::size_t k = 0; k < script.chunks.size(); ++k) {
    const std::size_t first_sample = k * n;
    const std::size_t m = std::min(n, samples.size() - first_sample);
    auto* c = script.chunks[k].mutable_chunk();
    c->set_sequence_number(k);
    c->set_start_time_s(static_cast<double>(first_sample) / rate_hz);
    c->set_data(reinterpret_cast<const char*>(samples.data() + first_sample), m * sizeof(float));
  }

  auto stub = v1::CoordinatorService::NewStub(channel);
  const double timeout_s = options.timeout_s > 0 ? options.timeout_s : 60 + 3 * script.audio_s;
  Countdown countdown, setup;
  countdown.left = setup.left = streams;
  std::vector<std::unique_ptr<LiveCall>> calls;
  for (int i = 0; i < streams; ++i) {
    calls.push_back(std::make_unique<LiveCall>(&script, &options, &countdown, &setup, timeout_s));
  }
  for (auto& c : calls) c->Start(stub.get());
  if (options.start_after_setup) {
    std::unique_lock<std::mutex> l(setup.mu);
    setup.cv.wait(l, [&] { return setup.left == 0; });
  }
  // Stream i starts i/streams of a chunk after stream 0.
  const Clock::time_point t0 = Clock::now();
  std::vector<Clock::time_point> starts;
  for (int i = 0; i < streams; ++i) {
    starts.push_back(t0 + std::chrono::duration_cast<Clock::duration>(
                              std::chrono::duration<double>(options.chunk_s * i / streams)));
  }
  std::thread pacer;
  if (options.realtime) {
    pacer = std::thread([&] { Pace(script, calls, starts); });
  } else if (options.start_after_setup) {
    for (auto& c : calls) c->Go();
  }
  {
    std::unique_lock<std::mutex> l(countdown.mu);
    countdown.cv.wait(l, [&] { return countdown.left == 0; });
  }
  if (pacer.joinable()) pacer.join();
  for (auto& c : calls) results.push_back(c->Result());
  return results;
}

StatusOr<LiveStreamResult> RunLiveStream(const std::shared_ptr<grpc::Channel>& channel,
                                         const std::vector<float>& samples, int rate_hz,
                                         const LiveStreamOptions& options) {
  return std::move(RunLiveStreams(channel, samples, rate_hz, options, 1).front());
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
