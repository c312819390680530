// The AR view of the cube videos pages attach (studio.proto CubeArVideo;
// issue 24, thesis §5.2): each video tracked again and written with the
// character drawn standing on the table beside the cube, as WebM (VP8) for
// the page's <video>, by services/cube_tracker/ar (WriteArVideo, as `kinemo
// cube track --overlay` draws it). One worker thread at a low CPU priority
// (nice 10) draws one video at a time and waits while a live stream runs, so
// the live path keeps its CPU; a
// bundled scenario's AR video is drawn once and kept, an upload's is removed
// with the upload. No gRPC here.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "common/status/status.h"
#include "kinemo/studio/v1/options.pb.h"
#include "services/studio/core/character.h"

namespace kinemo::studio {

// The bounds of one AR video: its first 3600 frames (2 min at 30 fps), at
// most 960 px a side (larger frames are scaled down).
inline constexpr std::int64_t kMaxCubeArFrames = 3600;
inline constexpr int kMaxCubeArSidePx = 960;
// The worker thread's nice value.
inline constexpr int kCubeArNice = 10;
// The character the AR view draws when the socket chose none (in
// character_dir).
inline constexpr char kCubeArCharacter[] = "quaternius_man_casual.glb";

// True if `name` may name an AR video in a URL and a file: 1 to 128 of
// A-Z a-z 0-9 _ -.
bool IsCubeArName(std::string_view name);

// Where an AR video lives: `kind` is "bundled" (a scenario's, kept) or
// "uploads" (an upload's), `name` the scenario or the upload's id.
struct CubeArTarget {
  std::string kind, name;
  std::string path() const;  // <kind>/<name>.ar.webm, in cube_dir
  std::string url() const;   // /cube/ar/<kind>/<name>.webm
  std::string input_video;   // the cube video to draw over
  std::string camera;        // its intrinsics; "" = a 60° pinhole of the video's size
  // The character drawn (the socket's choice); null = kCubeArCharacter.
  std::shared_ptr<const Character> character;
};

// A drawn AR video.
struct CubeArResult {
  std::string url, path;
  std::int64_t frames = 0, drawn = 0;
  int width = 0, height = 0;
  double fps = 0;
  double render_s = 0;  // 0: drawn before and kept
};

class CubeArRenderer {
 public:
  using Done = std::function<void(StatusOr<CubeArResult>)>;

  // `options` resolved. Empties cube_dir/rendering (partial videos of an
  // earlier run). Off (every request answers FAILED_PRECONDITION "cube_ar:
  // ...") without cube_dir, the character or the clips.
  explicit CubeArRenderer(const v1::StudioOptions& options);
  ~CubeArRenderer();  // Shutdown()

  // Draws `target`'s AR video on the worker and calls `done` there; a
  // bundled one drawn before is answered at once, on the caller's thread; a
  // second request for one being drawn waits for the same drawing.
  void Request(const CubeArTarget& target, Done done);
  // Cancels the drawing of `target` (queued: dropped; running: stopped
  // before its next frame; its `done` gets CANCELLED) and removes its AR
  // video. Once this returns no file of it is left in `target`'s folder.
  void Forget(const CubeArTarget& target);
  // Live streams running in the studio (any socket): while there is one the
  // drawing waits before its next frame, so the live path keeps the CPU.
  void LiveStreamStarted();
  void LiveStreamEnded();
  // Stops the worker: the drawing in progress stops before its next frame,
  // queued ones are answered CANCELLED. Idempotent.
  void Shutdown();

 private:
  struct Job {
    CubeArTarget target;
    std::vector<Done> waiting;
    std::atomic<bool> stop{false};
  };
  void Work();
  StatusOr<CubeArResult> Draw(Job& job);

  std::string cube_dir_, cube_model_path_, character_, clip_dir_, off_reason_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<std::shared_ptr<Job>> queue_;  // guarded by mu_
  std::shared_ptr<Job> running_;            // guarded by mu_
  bool stopping_ = false;                   // guarded by mu_
  int live_streams_ = 0;                    // guarded by mu_
  std::thread worker_;
};

}  // namespace kinemo::studio
