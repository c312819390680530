// One tracking stream of the cube tracker service (track_session.h).
#include "services/cube_tracker/core/track_session.h"

#include <chrono>
#include <cmath>
#include <span>
#include <string>
#include <utility>

#include <opencv2/imgproc.hpp>

#include "common/metrics/metrics.h"
#include "services/cube_tracker/core/track_messages.h"

namespace kinemo::cube {
namespace {
namespace v1 = ::kinemo::cube_tracker::v1;
}  // namespace

TrackSession::TrackSession(CubeTracker tracker, bool include_details, std::uint32_t max_frame_bytes,
                           std::uint32_t max_frame_side_px)
    : tracker_(std::move(tracker)),
      include_details_(include_details),
      max_frame_bytes_(max_frame_bytes),
      max_frame_side_px_(max_frame_side_px) {}

Status TrackSession::Decode(const v1::TrackFrame& frame, const cv::Mat** image) {
  const v1::Image& img = frame.image();
  const std::string& data = img.data();
  if (data.empty()) return InvalidField("frame.image.data", "empty");
  if (data.size() > max_frame_bytes_) {
    return InvalidField("frame.image.data", data.size(), " bytes is over the limit of ", max_frame_bytes_);
  }
  if (img.width_px() > max_frame_side_px_ || img.height_px() > max_frame_side_px_) {
    return InvalidField("frame.image.width_px", img.width_px(), "x", img.height_px(), " is over the limit of ",
                        max_frame_side_px_, " px");
  }
  const CameraModel& cam = tracker_.camera();
  if ((img.width_px() != 0 && static_cast<int>(img.width_px()) != cam.width) ||
      (img.height_px() != 0 && static_cast<int>(img.height_px()) != cam.height)) {
    return InvalidField("frame.image.width_px", img.width_px(), "x", img.height_px(),
                        " does not match the intrinsics' ", cam.width, "x", cam.height);
  }
  int channels = 0;
  switch (img.encoding()) {
    case v1::IMAGE_ENCODING_JPEG:
    case v1::IMAGE_ENCODING_PNG:
      *image = nullptr;  // decoded by the core
      return absl::OkStatus();
    case v1::IMAGE_ENCODING_GRAY8:
      channels = 1;
      break;
    case v1::IMAGE_ENCODING_BGR8:
    case v1::IMAGE_ENCODING_RGB8:
      channels = 3;
      break;
    default:
      return InvalidField("frame.image.encoding", "unspecified or unknown (", static_cast<int>(img.encoding()), ")");
  }
  if (img.width_px() == 0 || img.height_px() == 0) {
    return InvalidField("frame.image.width_px", "required for a raw encoding");
  }
  const std::size_t w = img.width_px(), h = img.height_px(), row = w * static_cast<std::size_t>(channels);
  const std::size_t stride = img.stride_bytes() == 0 ? row : img.stride_bytes();
  if (stride < row) return InvalidField("frame.image.stride_bytes", stride, " is less than a row (", row, ")");
  if (data.size() < stride * (h - 1) + row) {
    return InvalidField("frame.image.data", data.size(), " bytes do not make a ", w, "x", h, "x", channels,
                        " image with rows of ", stride, " bytes");
  }
  try {
    view_ = cv::Mat(static_cast<int>(h), static_cast<int>(w), channels == 1 ? CV_8UC1 : CV_8UC3,
                    const_cast<char*>(data.data()), stride);
    if (img.encoding() == v1::IMAGE_ENCODING_RGB8) {
      cv::cvtColor(view_, scratch_, cv::COLOR_RGB2GRAY);
      *image = &scratch_;
    } else {
      *image = &view_;
    }
  } catch (const cv::Exception& e) {
    return InvalidField("frame.image", "OpenCV: ", e.what());
  }
  return absl::OkStatus();
}

namespace {

// Frames tracked and their processing time, over every stream of the process
// (rate(kinemo_tracker_frames_total[1m]) = frames/s).
struct TrackerMetrics {
  prometheus::Counter& frames = metrics::Counter(
      "kinemo_tracker_frames_total", "Camera frames the cube tracker processed successfully.");
  prometheus::Histogram& seconds = metrics::Histogram(
      "kinemo_tracker_frame_seconds", "Processing time of one camera frame.",
      {0.001, 0.0025, 0.005, 0.01, 0.02, 0.033, 0.05, 0.1, 0.25});
};
TrackerMetrics& Tracked() {
  static auto* m = new TrackerMetrics();
  return *m;
}

}  // namespace

void TrackSession::Fill(std::uint64_t frame, double process_us, v1::TrackResponse* response) {
  Tracked().frames.Increment();
  Tracked().seconds.Observe(process_us * 1e-6);
  StateToProto(state_, tracker_.model(), tracker_.surface(), include_details_, frame, response->mutable_state());
  for (const CubeEvent& e : state_.events) EventToProto(e, frame, response->add_events());
  response->set_process_us(process_us);
}

void TrackSession::ProcessFrame(const v1::TrackFrame& frame, v1::TrackResponse* response) {
  const auto start = std::chrono::steady_clock::now();
  Status s;
  if (have_frame_ && frame.frame() <= last_frame_) {
    s = InvalidField("frame.frame", frame.frame(), " is not after the previous frame ", last_frame_);
  } else if (!std::isfinite(frame.time_s()) || (have_frame_ && frame.time_s() < last_time_s_)) {
    s = InvalidField("frame.time_s", frame.time_s(), " is not finite or goes back in time");
  }
  const cv::Mat* image = nullptr;
  if (s.ok()) s = Decode(frame, &image);
  if (s.ok()) {
    if (image == nullptr) {
      const std::string& data = frame.image().data();
      s = tracker_.ProcessEncoded(
          std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(data.data()), data.size()),
          frame.time_s(), &state_);
    } else {
      s = tracker_.Process(*image, frame.time_s(), &state_);
    }
  }
  const double us =
      std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - start).count();
  if (!s.ok()) {
    response->mutable_frame_error()->set_frame(frame.frame());
    response->mutable_frame_error()->set_message(std::string(s.message()));
    response->set_process_us(us);
    return;
  }
  have_frame_ = true;
  last_frame_ = frame.frame();
  last_time_s_ = frame.time_s();
  Fill(frame.frame(), us, response);
}

void TrackSession::ProcessImage(const cv::Mat& image, std::uint64_t frame, double time_s,
                                v1::TrackResponse* response) {
  const auto start = std::chrono::steady_clock::now();
  const Status s = tracker_.Process(image, time_s, &state_);
  const double us =
      std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - start).count();
  if (!s.ok()) {
    response->mutable_frame_error()->set_frame(frame);
    response->mutable_frame_error()->set_message(std::string(s.message()));
    response->set_process_us(us);
    return;
  }
  Fill(frame, us, response);
}

}  // namespace kinemo::cube
