// The AR view of a whole cube video (thesis §5.2), as `kinemo cube track
// --overlay` and the studio write it: the character and its action clips
// loaded into an ArOverlay (ar_view.h), the video tracked frame by frame with
// the character drawn over each frame, and the frames written as MPEG-4
// (`.mp4`, mp4v) or as WebM (`.webm`, VP8: what a browser's <video> plays).
// Plain C++/OpenCV, no gRPC.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

#include "common/status/status.h"
#include "services/cube_tracker/ar/ar_view.h"
#include "services/cube_tracker/core/camera.h"
#include "services/cube_tracker/core/cube_model.h"
#include "services/cube_tracker/core/tracker.h"

namespace kinemo::cube::ar {

// The character and the clip of each action an overlay draws.
struct OverlaySpec {
  std::string character;                  // .glb / .vrm with a skin
  // A rig already loaded (e.g. the studio's chosen character): drawn instead
  // of reading `character` when set.
  std::shared_ptr<const retarget::Rig> rig;
  std::vector<std::string> action_clips;  // ACTION=CLIP.bvh (idle, throwing_kisses, shouting)
  ArOptions options;
  // How errors name the two inputs (the CLI's flags, a service's fields):
  // "<character_field>: ...", "<action_clip_field>[i]: ...".
  std::string character_field = "character";
  std::string action_clip_field = "action_clip";
};

// The bundled clips of the actions in `clip_dir` (Bandai-Namco,
// tests/data/planner_gesture; the nearest the dataset has: a quiet response
// for idle, a two-handed bye-bye for throwing kisses, an angry bye for
// shouting), as ACTION=FILE.bvh.
std::vector<std::string> DefaultActionClips(const std::string& clip_dir);

// Loads the character (its skinned mesh) and retargets each clip onto it.
StatusOr<ArOverlay> MakeArOverlay(const OverlaySpec& spec);

// The frame rate a capture announces, or 30 when it announces none.
double CaptureFps(cv::VideoCapture& capture);

// One frame of a tracked video, as TrackVideo hands it on.
struct TrackedFrame {
  int64_t index = 0;
  double time_s = 0;
  Status tracked;                    // the tracker's status on this frame
  const CubeState* state = nullptr;  // the tracker's state after it (meaningful when tracked.ok())
  cv::Mat* bgr = nullptr;            // the frame; with an overlay and tracked: 8-bit BGR, the character drawn
  const DrawInfo* drawn = nullptr;   // with an overlay and tracked: what was drawn; else null
};
// Called per frame; a non-OK status stops the video and is returned.
using FrameSink = std::function<Status(const TrackedFrame&)>;

// Reads `capture` to its end (or `max_frames`, 0 = all; a read that throws
// ends it too), tracks each frame at index / `fps` seconds and, with
// `overlay`, draws the character into each tracked frame. A frame the tracker
// refuses is handed on with its status (not drawn); an overlay that cannot
// draw stops with its error. Returns the frames read.
StatusOr<int64_t> TrackVideo(cv::VideoCapture& capture, double fps, CubeTracker& tracker, const CameraModel& camera,
                             ArOverlay* overlay, int64_t max_frames, const FrameSink& sink);

// Opens `writer` for `path` by its extension: ".webm" VP8 in WebM (FFmpeg),
// anything else MPEG-4 part 2 (mp4v). `field` names the path in errors.
Status OpenArWriter(const std::string& path, double fps, cv::Size size, const std::string& field,
                    cv::VideoWriter* writer);

// The bounds of an AR video written in one go.
struct ArVideoLimits {
  int64_t max_frames = 0;  // 0 = the whole video
  int max_side_px = 0;     // frames larger than this a side are written scaled down; 0 = as they are
  // Called before each frame (may wait, e.g. to yield the CPU); a non-OK
  // status stops the video and is returned. Empty = none.
  std::function<Status()> before_frame;
};
struct ArVideoSummary {
  int64_t frames = 0;  // written
  int64_t drawn = 0;   // of them, with the character drawn
  int width = 0, height = 0;
  double fps = 0;
};

// The AR view of the video file `video` (frames of the camera's size)
// written to `output` (see OpenArWriter): every frame read is written, the
// ones the tracker refuses as they are. INVALID_ARGUMENT naming `video` for a
// file OpenCV cannot read or whose frames are not the camera's size.
StatusOr<ArVideoSummary> WriteArVideo(const std::string& video, const CubeModel& model, const CameraModel& camera,
                                      ArOverlay& overlay, const std::string& output, const ArVideoLimits& limits);

}  // namespace kinemo::cube::ar
