// The cube tracker core's types as the API's messages and back
// (kinemo.cube_tracker.v1): cube state and events out, tracking parameters,
// camera intrinsics and surface poses in. Values a request carries are
// checked here; errors name the request's field under `field`.
#pragma once

#include <cstdint>
#include <optional>
#include <string_view>

#include "common/status/status.h"
#include "kinemo/common/v1/geometry.pb.h"
#include "kinemo/cube_tracker/v1/cube_tracker.pb.h"
#include "services/cube_tracker/core/camera.h"
#include "services/cube_tracker/core/cube_model.h"
#include "services/cube_tracker/core/tracker.h"

namespace kinemo::cube {

// The core state and events as the API's messages (frame indices from `frame`).
void StateToProto(const CubeState& state, const CubeModel& model, const std::optional<Pose>& camera_from_surface,
                  bool include_details, std::uint64_t frame, cube_tracker::v1::CubeState* out);
void EventToProto(const CubeEvent& event, std::uint64_t frame, cube_tracker::v1::CubeEvent* out);
// API params over `defaults` (zeros keep the default) -> core options.
StatusOr<TrackerOptions> TrackerOptionsFromProto(const cube_tracker::v1::TrackingParams& params, const TrackerOptions& defaults,
                                                 std::string_view field);
StatusOr<CameraModel> CameraFromProto(const cube_tracker::v1::CameraIntrinsics& intrinsics, std::string_view field);
// A pose message (unit quaternion, normalised here; position in m).
StatusOr<Pose> PoseFromProto(const common::v1::Pose& pose, std::string_view field);

}  // namespace kinemo::cube
