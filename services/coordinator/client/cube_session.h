// Client side of "the cube sets the tone": opens a cube session on a
// coordinator and attaches a cube video to it (AttachCube), for a
// StreamAnimate that follows it (StreamAnimateConfig.session_id). Shared by
// `kinemo animate --stream --cube-video`, `kinemo bench tones` and the tests.
#pragma once

#include <memory>
#include <string>

#include <grpcpp/channel.h>

#include "common/status/status.h"
#include "kinemo/coordinator/v1/coordinator.pb.h"

namespace kinemo::coordinator {

struct CubeSessionOptions {
  std::string session_id;         // "" = the coordinator makes one
  std::string robot_id = "pleo";  // the bridge may not know it (robot_connected false)
  std::string video;              // video file, as the cube tracker sees it (file_root)
  std::string camera;             // intrinsics file (OpenCV YAML), likewise
  std::string cube_model_file;    // text proto of a CubeModel; "" = the tracker's default cube
  bool realtime = true;           // play the video at its frame rate
  common::v1::Emotion initial = common::v1::EMOTION_NEUTRAL;
  double timeout_s = 10;
};

// Opens the session and attaches the cube; returns the session id. The
// coordinator's errors with their codes (e.g. NOT_FOUND naming
// source.video_file); INVALID_ARGUMENT naming cube_model_file for a model
// that does not parse.
StatusOr<std::string> OpenCubeSession(const std::shared_ptr<grpc::Channel>& channel, const CubeSessionOptions& o);

// The session's state (GetSession).
StatusOr<v1::Session> GetCubeSession(const std::shared_ptr<grpc::Channel>& channel, const std::string& session_id);

// Closes it (the cube detaches).
Status CloseCubeSession(const std::shared_ptr<grpc::Channel>& channel, const std::string& session_id);

}  // namespace kinemo::coordinator
