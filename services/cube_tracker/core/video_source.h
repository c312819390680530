// What the cube tracker server reads on a client's behalf (TrackSource,
// TrackConfig.intrinsics_file): files under the server's file_root, and
// camera frames from a video file there or from an allowed V4L2 device, with
// the frame indices and times the API gives them. Errors name the request's
// field ("source.video_file: ...").
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

#include "common/status/status.h"
#include "kinemo/cube_tracker/v1/cube_tracker.pb.h"
#include "kinemo/cube_tracker/v1/options.pb.h"
#include "services/cube_tracker/core/camera.h"

namespace kinemo::cube {

// `relative` resolved under `root` (symlinks and ".." resolved); refused when
// it leaves the root. NOT_FOUND when it does not exist.
StatusOr<std::string> ResolveUnderRoot(const std::string& root, const std::string& relative,
                                       std::string_view field);

// Frames of a TrackSource request's source, one after another.
class VideoSource {
 public:
  // Opens `source` (a video file under options.file_root, or one of
  // options.allowed_devices) and checks its frame size against `camera`.
  static StatusOr<std::unique_ptr<VideoSource>> Open(const cube_tracker::v1::VideoSource& source,
                                                     const cube_tracker::v1::CubeTrackerOptions& options,
                                                     const CameraModel& camera);
  ~VideoSource();
  VideoSource(const VideoSource&) = delete;
  VideoSource& operator=(const VideoSource&) = delete;

  struct Frame {
    std::uint64_t index = 0;  // the file's frame number (from start_frame); a device counts from 0
    double time_s = 0;        // a file: index / fps; a device: since the first read
    // A realtime file: when the frame is due (paced at the file's rate).
    std::optional<std::chrono::steady_clock::time_point> due;
  };
  // Reads the next frame into `image`: false at the end of a file or after
  // max_frames; UNAVAILABLE when a device stops delivering.
  StatusOr<bool> Next(cv::Mat* image, Frame* frame);

 private:
  explicit VideoSource(const cube_tracker::v1::VideoSource& source) : source_(source) {}

  const cube_tracker::v1::VideoSource source_;
  cv::VideoCapture capture_;
  bool device_ = false;
  double fps_ = 30;
  std::optional<std::chrono::steady_clock::time_point> start_;
  std::uint64_t next_index_ = 0;
  std::uint64_t read_ = 0;
};

}  // namespace kinemo::cube
