// The cube videos a page attaches to its session (`attach_cube`): the
// bundled scenarios (render scripts in StudioOptions.cube_data_dir, drawn
// once by the cube renderer and kept in cube_dir/bundled/) and the videos
// pages upload (validated, written to cube_dir/uploads/). The cube tracker
// reads them by path (cube_dir lies inside its file_root). Each attached
// video also gets its AR view (cube_ar.h: the character drawn over it). No
// gRPC here.
#pragma once

#include <cstdint>
#include <mutex>
#include <string>
#include <vector>

#include "common/status/status.h"
#include "kinemo/studio/v1/options.pb.h"
#include "services/studio/core/cube_ar.h"
#include "kinemo/studio/v1/studio.pb.h"

namespace kinemo::studio {

// Largest upload file name and camera file.
inline constexpr std::size_t kMaxCubeNameBytes = 256;
inline constexpr std::size_t kMaxCubeCameraBytes = 64 << 10;
// Largest side of an uploaded video's frames, in pixels (the tracker's own
// default bound).
inline constexpr int kMaxCubeVideoSidePx = 4096;

// A video ready for AttachCube: absolute paths inside cube_dir.
struct CubeVideo {
  std::string video;
  std::string camera;  // "" = the tracker's default intrinsics
  bool uploaded = false;  // the caller removes it (Remove) when done
  bool own_ar = false;    // its AR view is the socket's own: the caller removes it (Remove) when done
  CubeArTarget ar;        // its AR view (RenderAr)
};

class CubeVideos {
 public:
  // `options` resolved. Empties cube_dir/uploads (left by an earlier run).
  explicit CubeVideos(const v1::StudioOptions& options);

  bool enabled() const { return !cube_dir_.empty(); }
  // Names of the bundled scenarios (sorted; "tone_scenario", ...).
  const std::vector<std::string>& scenarios() const { return scenarios_; }
  // The cube model (text proto of kinemo.cube_tracker.v1.CubeModel), or ""
  // if cube_data_dir has no vleo.cube.
  const std::string& cube_model_text() const { return cube_model_text_; }

  // The video an attach_cube asks for. Errors name the field as the page
  // spells it: FAILED_PRECONDITION "cube_dir: ..." when attaching is off;
  // NOT_FOUND "attach_cube.bundled: ..." for an unknown scenario;
  // INVALID_ARGUMENT "attach_cube.upload / .name / .camera_yaml: ..." for an
  // empty, oversized or unreadable video or camera, and no video. Renders a
  // bundled scenario on its first use (seconds; call off the I/O threads).
  StatusOr<CubeVideo> Prepare(const v1::AttachCubeVideo& request);

  // The AR view of `video` draws `character` (the socket's choice; null or
  // the default man: kCubeArCharacter, as before). A bundled video with a
  // bundled character keeps its AR view per character
  // (bundled/<scenario>--<character>); with an uploaded character the AR view
  // is the socket's own (uploads/<id>, removed with Remove like an upload's).
  void SetArCharacter(CubeVideo* video, std::shared_ptr<const Character> character) const;

  // Removes an uploaded video, its camera file and its AR view (a drawing
  // of it is stopped), or the socket's own AR view of a bundled video; no-op
  // for bundled ones otherwise.
  void Remove(const CubeVideo& video);

  // Draws (or reuses) the AR view of a prepared video off the caller's
  // thread (CubeArRenderer::Request); `done` may run at once.
  void RenderAr(const CubeVideo& video, CubeArRenderer::Done done) { ar_.Request(video.ar, std::move(done)); }
  // Live streams start and end (the AR drawing waits while one runs).
  void LiveStreamStarted() { ar_.LiveStreamStarted(); }
  void LiveStreamEnded() { ar_.LiveStreamEnded(); }
  // Stops the AR drawing (shutdown).
  void Shutdown() { ar_.Shutdown(); }

 private:
  StatusOr<CubeVideo> Bundled(const std::string& name);
  StatusOr<CubeVideo> Upload(const v1::AttachCubeVideo& request);

  std::string cube_dir_, data_dir_, cube_model_text_;
  std::uint64_t max_video_bytes_ = 0;
  std::vector<std::string> scenarios_;
  std::mutex render_mu_;  // one render at a time; a scenario is drawn once
  CubeArRenderer ar_;     // last: its worker stops first
};

}  // namespace kinemo::studio
