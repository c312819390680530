// One tracking stream of the cube tracker service: a CubeTracker plus what it
// takes to answer the API's frames (kinemo.cube_tracker.v1.TrackFrame in,
// TrackResponse out): the frame checks (order, time, size, encoding), raw
// frames viewed or converted without copies, JPEG/PNG decoded by the
// tracker, and the frame metrics (kinemo_tracker_frames_total,
// kinemo_tracker_frame_seconds). A frame that cannot be used gives a
// TrackResponse.frame_error for that frame only. Not thread-safe (one per
// stream).
#pragma once

#include <cstdint>

#include <opencv2/core.hpp>

#include "common/status/status.h"
#include "kinemo/cube_tracker/v1/cube_tracker.pb.h"
#include "services/cube_tracker/core/tracker.h"

namespace kinemo::cube {

class TrackSession {
 public:
  TrackSession(CubeTracker tracker, bool include_details, std::uint32_t max_frame_bytes,
               std::uint32_t max_frame_side_px);

  // Tracks one client frame; on a bad frame fills `response->frame_error`.
  void ProcessFrame(const cube_tracker::v1::TrackFrame& frame, cube_tracker::v1::TrackResponse* response);
  // Tracks one decoded image (server-side capture).
  void ProcessImage(const cv::Mat& image, std::uint64_t frame, double time_s,
                    cube_tracker::v1::TrackResponse* response);

  const CubeTracker& tracker() const { return tracker_; }

 private:
  Status Decode(const cube_tracker::v1::TrackFrame& frame, const cv::Mat** image);
  void Fill(std::uint64_t frame, double process_us, cube_tracker::v1::TrackResponse* response);

  CubeTracker tracker_;
  bool include_details_;
  std::uint32_t max_frame_bytes_;
  std::uint32_t max_frame_side_px_;
  bool have_frame_ = false;
  std::uint64_t last_frame_ = 0;
  double last_time_s_ = 0;
  CubeState state_;
  cv::Mat scratch_, view_;
};

}  // namespace kinemo::cube
