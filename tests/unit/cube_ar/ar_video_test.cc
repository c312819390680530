// The AR video of a whole cube video (services/cube_tracker/ar/ar_video.h),
// as the studio writes it: a rendered cube video (a real photograph behind)
// tracked and written as WebM (VP8) within its bounds (frames, size), the
// character drawn; a stop before a frame ends it with that status; bad
// inputs are named.
#include "services/cube_tracker/ar/ar_video.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <opencv2/core.hpp>

#include <opencv2/videoio.hpp>

#include "services/cube_tracker/render/renderer.h"

namespace kinemo::cube::ar {
namespace {

namespace fs = std::filesystem;
const std::string kTestData = KINEMO_TEST_DATA_DIR;

struct Dir {
  fs::path path = fs::temp_directory_path() / ("ar_video_test." + std::to_string(::getpid()));
  Dir() { fs::create_directories(path); }
  ~Dir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  std::string File(const std::string& name) const { return (path / name).string(); }
};

// The first half second of the bundled tone scenario (640x480, 30 fps, the
// cube over a photograph), rendered and written as MJPG AVI.
struct Rendered {
  Dir dir;
  CubeModel model;
  CameraModel camera;
  Rendered() {
    auto m = LoadCubeModel(kTestData + "/cube/vleo.cube");
    EXPECT_TRUE(m.ok()) << m.status();
    model = *m;
    auto script = LoadRenderScript(kTestData + "/cube/tone_scenario.json");
    EXPECT_TRUE(script.ok()) << script.status();
    auto renderer = SequenceRenderer::Create(model, *script);
    EXPECT_TRUE(renderer.ok()) << renderer.status();
    camera = renderer->camera();
    cv::VideoWriter avi(dir.File("turn.avi"), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 30,
                        cv::Size(camera.width, camera.height));
    cv::Mat frame;
    TruthFrame truth;
    for (int i = 0; i < 15; ++i) {
      EXPECT_TRUE(renderer->Next(&frame, &truth).ok());
      avi.write(frame);
    }
  }
};

StatusOr<ArOverlay> ManOverlay() {
  return MakeArOverlay({.character = kTestData + "/characters/quaternius_man_casual.glb",
                        .action_clips = DefaultActionClips(kTestData + "/planner_gesture"),
                        .options = {},
                        .character_field = "character",
                        .action_clip_field = "action_clip"});
}

TEST(ArVideo, WritesABoundedWebmWithTheCharacterAndStopsWhenAsked) {
  Rendered r;
  auto overlay = ManOverlay();
  ASSERT_TRUE(overlay.ok()) << overlay.status();
  const std::string out = r.dir.File("ar.webm");
  auto written = WriteArVideo(r.dir.File("turn.avi"), r.model, r.camera, *overlay, out,
                              {.max_frames = 10, .max_side_px = 320, .before_frame = {}});
  ASSERT_TRUE(written.ok()) << written.status();
  EXPECT_EQ(written->frames, 10);
  EXPECT_EQ(written->drawn, 10);  // the cube stands in view from the first frame
  EXPECT_EQ(written->width, 320);
  EXPECT_EQ(written->height, 240);
  EXPECT_DOUBLE_EQ(written->fps, 30);
  cv::VideoCapture back(out);
  ASSERT_TRUE(back.isOpened());
  cv::Mat f;
  int n = 0;
  while (back.read(f)) {
    EXPECT_EQ(f.cols, 320);
    EXPECT_EQ(f.rows, 240);
    ++n;
  }
  EXPECT_EQ(n, 10);

  // Stopped before the 4th frame: the stop's status, 3 frames handed on.
  auto again = ManOverlay();
  ASSERT_TRUE(again.ok());
  int asked = 0;
  auto stopped = WriteArVideo(r.dir.File("turn.avi"), r.model, r.camera, *again, r.dir.File("stopped.webm"),
                              {.max_frames = 0, .max_side_px = 0, .before_frame = [&]() -> Status {
                                 return ++asked > 3 ? absl::CancelledError("stop") : absl::OkStatus();
                               }});
  EXPECT_EQ(stopped.status().code(), absl::StatusCode::kCancelled);
  EXPECT_EQ(asked, 4);
}

TEST(ArVideo, BadInputsAreNamed) {
  Rendered r;
  auto overlay = ManOverlay();
  ASSERT_TRUE(overlay.ok());
  // Not a video; frames not of the camera's size; an unwritable output.
  std::ofstream(r.dir.File("not.avi")) << "not a video";
  auto bad = WriteArVideo(r.dir.File("not.avi"), r.model, r.camera, *overlay, r.dir.File("a.webm"), {});
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(bad.status().message()).rfind("video: ", 0), 0u) << bad.status();
  CameraModel small = PinholeCamera(320, 240, 60);
  bad = WriteArVideo(r.dir.File("turn.avi"), r.model, small, *overlay, r.dir.File("b.webm"), {});
  EXPECT_EQ(std::string(bad.status().message()).rfind("video: ", 0), 0u) << bad.status();
  bad = WriteArVideo(r.dir.File("turn.avi"), r.model, r.camera, *overlay, r.dir.File("no/such/dir/c.webm"), {});
  EXPECT_EQ(std::string(bad.status().message()).rfind("output: ", 0), 0u) << bad.status();
  // The character and the clips, named as the caller names them.
  auto no_rig = MakeArOverlay({.character = r.dir.File("none.glb"),
                               .action_clips = {},
                               .options = {},
                               .character_field = "--character",
                               .action_clip_field = "--action-clip"});
  EXPECT_EQ(std::string(no_rig.status().message()).rfind("--character: ", 0), 0u) << no_rig.status();
  auto no_action = MakeArOverlay({.character = kTestData + "/characters/quaternius_man_casual.glb",
                                  .action_clips = {"dancing=x.bvh"},
                                  .options = {},
                                  .character_field = "character",
                                  .action_clip_field = "action_clip"});
  EXPECT_EQ(std::string(no_action.status().message()).rfind("action_clip[0]: ", 0), 0u) << no_action.status();
}

}  // namespace
}  // namespace kinemo::cube::ar
