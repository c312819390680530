// The cube videos of `attach_cube` (services/studio/core/cube_videos.h): a
// bundled scenario is drawn once by the cube renderer (the Vleo cube,
// tests/data/cube/vleo.cube, over a real photograph) and kept; uploads are
// checked (a video OpenCV reads, its camera intrinsics) and refused naming
// the field, leaving nothing behind; the options are bounded. The AR view of
// the bundled tone scenario (the character drawn beside the cube) is drawn
// once, decodes with OpenCV and shows the character; an upload's AR view is
// removed with the upload.
#include "services/studio/core/cube_videos.h"

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <future>
#include <string>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "services/cube_tracker/render/renderer.h"

#include "common/testing/process.h"
#include "services/studio/core/options.h"
#include "tests/unit/studio/read_all.h"

namespace kinemo::studio {
namespace {

namespace fs = std::filesystem;
const std::string kData = std::string(KINEMO_SOURCE_DIR) + "/tests/data";

using test::ReadAll;

std::size_t FilesIn(const fs::path& dir) {
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++n;
  return n;
}

// A cube data folder with the Vleo cube and one short scenario (1 s, 160x120:
// the cube turned onto a side face).
struct CubeData {
  kinemo::testing::TempDir dir;
  v1::StudioOptions options;
  CubeData() {
    fs::create_directories(dir.File("data"));
    fs::copy_file(kData + "/cube/vleo.cube", dir.File("data/vleo.cube"));
    std::ofstream(dir.File("data/short_turn.json"))
        << R"({"name": "short_turn", "fps": 15, "width": 160, "height": 120, "hfov_deg": 60,
              "camera": {"distance_m": 0.4, "elevation_deg": 45, "azimuth_deg": -90, "look_at_m": [0, 0, 0.03]},
              "background": ")"
        << kData << R"(/images/home.jpg", "seed": 3,
              "keys": [{"t_s": 0.0}, {"t_s": 1.0, "roll_y_deg": 90}]})";
    options.set_cube_dir(dir.File("cube"));
    options.set_cube_data_dir(dir.File("data"));
    options.set_max_cube_video_bytes(1 << 20);
    fs::create_directories(dir.File("cube"));
  }
};

v1::AttachCubeVideo Upload(const std::string& bytes, const std::string& name = "mine.avi") {
  v1::AttachCubeVideo r;
  r.set_session_id("s1");
  r.set_upload(bytes);
  r.set_name(name);
  return r;
}

TEST(CubeVideos, ABundledScenarioIsDrawnOnceAndKept) {
  CubeData d;
  CubeVideos videos(d.options);
  ASSERT_TRUE(videos.enabled());
  EXPECT_EQ(videos.scenarios(), std::vector<std::string>{"short_turn"});
  EXPECT_NE(videos.cube_model_text().find("DICT_4X4_50"), std::string::npos);
  v1::AttachCubeVideo r;
  r.set_session_id("s1");
  r.set_bundled("short_turn");
  auto first = videos.Prepare(r);
  ASSERT_TRUE(first.ok()) << first.status();
  EXPECT_FALSE(first->uploaded);
  EXPECT_EQ(first->video, d.dir.File("cube/bundled/short_turn.avi"));
  ASSERT_TRUE(fs::is_regular_file(first->camera));
  const auto drawn = fs::last_write_time(first->video);
  auto again = videos.Prepare(r);
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_EQ(again->video, first->video);
  EXPECT_EQ(fs::last_write_time(again->video), drawn);  // kept, not drawn again

  // The same video uploaded as the user's own, with its camera: a copy in
  // uploads/, removed by Remove.
  auto mine = Upload(ReadAll(first->video));
  mine.set_camera_yaml(ReadAll(first->camera));
  auto up = videos.Prepare(mine);
  ASSERT_TRUE(up.ok()) << up.status();
  EXPECT_TRUE(up->uploaded);
  EXPECT_EQ(fs::path(up->video).parent_path(), fs::path(d.dir.File("cube/uploads")));
  EXPECT_EQ(FilesIn(d.dir.File("cube/uploads")), 2u);
  videos.Remove(*up);
  EXPECT_EQ(FilesIn(d.dir.File("cube/uploads")), 0u);
}

TEST(CubeVideos, BadRequestsAreRefusedNamingTheFieldAndLeaveNothing) {
  CubeData d;
  CubeVideos videos(d.options);
  const auto expect = [&](const v1::AttachCubeVideo& r, absl::StatusCode code, const std::string& prefix) {
    auto got = videos.Prepare(r);
    ASSERT_FALSE(got.ok()) << prefix;
    EXPECT_EQ(got.status().code(), code) << got.status();
    EXPECT_EQ(std::string(got.status().message()).rfind(prefix, 0), 0u) << got.status();
    EXPECT_EQ(FilesIn(d.dir.File("cube/uploads")), 0u) << got.status();
  };
  v1::AttachCubeVideo bundled;
  bundled.set_session_id("s1");
  bundled.set_bundled("../data/short_turn");
  expect(bundled, absl::StatusCode::kNotFound, "attach_cube.bundled: ");
  bundled.set_session_id("");
  bundled.set_bundled("short_turn");
  expect(bundled, absl::StatusCode::kInvalidArgument, "attach_cube.session_id: ");
  v1::AttachCubeVideo none;
  none.set_session_id("s1");
  expect(none, absl::StatusCode::kInvalidArgument, "attach_cube: ");
  expect(Upload(""), absl::StatusCode::kInvalidArgument, "attach_cube.upload: ");
  expect(Upload(std::string((1 << 20) + 1, 'x')), absl::StatusCode::kInvalidArgument, "attach_cube.upload: ");
  // A real WAV is not a video; an AVI header over nothing has no frame.
  expect(Upload(ReadAll(kData + "/speech/sense_and_sensibility_01_austen_64kb-0880.wav")),
         absl::StatusCode::kInvalidArgument, "attach_cube.upload: ");
  std::string fake_avi = "RIFF\x10\x00\x00\x00" "AVI LIST";
  fake_avi += std::string(4096, '\0');
  expect(Upload(fake_avi), absl::StatusCode::kInvalidArgument, "attach_cube.upload: ");
  expect(Upload("RIFF....AVI x", std::string(257, 'n')), absl::StatusCode::kInvalidArgument, "attach_cube.name: ");
  // A readable video with a camera that is not intrinsics.
  v1::AttachCubeVideo r;
  r.set_session_id("s1");
  r.set_bundled("short_turn");
  auto drawn = videos.Prepare(r);
  ASSERT_TRUE(drawn.ok()) << drawn.status();
  auto bad_camera = Upload(ReadAll(drawn->video));
  bad_camera.set_camera_yaml("%YAML:1.0\nnot_a_camera: 1\n");
  expect(bad_camera, absl::StatusCode::kInvalidArgument, "attach_cube.camera_yaml: ");
  bad_camera.set_camera_yaml(std::string(kMaxCubeCameraBytes + 1, ' '));
  expect(bad_camera, absl::StatusCode::kInvalidArgument, "attach_cube.camera_yaml: ");
}

TEST(CubeVideos, OffWithoutACubeDir) {
  v1::StudioOptions o;
  o.set_cube_data_dir(kData + "/cube");
  CubeVideos videos(o);
  EXPECT_FALSE(videos.enabled());
  v1::AttachCubeVideo r;
  r.set_session_id("s1");
  r.set_bundled("tone_scenario");
  auto got = videos.Prepare(r);
  ASSERT_FALSE(got.ok());
  EXPECT_EQ(got.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(std::string(got.status().message()).rfind("cube_dir: ", 0), 0u) << got.status();
}

TEST(CubeVideos, OptionsAreBounded) {
  CubeData d;
  v1::StudioOptions o = d.options;
  o.mutable_auth()->set_token("0123456789abcdef0123");
  o.set_static_dir(kData);
  o.set_libs_dir(kData);
  o.set_max_upload_bytes(1 << 20);
  o.set_max_cube_video_bytes((1 << 20) + 1);
  Status s = ResolveStudioOptions("/nowhere/bin/studio", "", &o);
  EXPECT_EQ(std::string(s.message()).rfind("max_cube_video_bytes: ", 0), 0u) << s;
  o = d.options;
  o.mutable_auth()->set_token("0123456789abcdef0123");
  o.set_static_dir(kData);
  o.set_libs_dir(kData);
  o.set_cube_data_dir(d.dir.File("no-such-folder"));
  s = ResolveStudioOptions("/nowhere/bin/studio", "", &o);
  EXPECT_EQ(std::string(s.message()).rfind("cube_data_dir: ", 0), 0u) << s;
  // Defaults: 32 MiB at most max_upload_bytes; the source tree's cube.
  o = v1::StudioOptions();
  o.mutable_auth()->set_token("0123456789abcdef0123");
  o.set_static_dir(kData);
  o.set_libs_dir(kData);
  o.set_max_upload_bytes(8 << 20);
  o.set_cube_dir(d.dir.File("cube2"));
  ASSERT_TRUE(ResolveStudioOptions("/nowhere/bin/studio", KINEMO_SOURCE_DIR, &o).ok());
  EXPECT_EQ(o.max_cube_video_bytes(), 8u << 20);
  EXPECT_EQ(fs::path(o.cube_data_dir()), fs::path(kData + "/cube"));
  EXPECT_TRUE(fs::is_directory(d.dir.File("cube2")));
}

// The AR view of a prepared video: waits for the renderer's answer (a
// guard, not a timing assertion: the worker runs at nice 10).
StatusOr<CubeArResult> DrawAr(CubeVideos& videos, const CubeVideo& video) {
  auto promise = std::make_shared<std::promise<StatusOr<CubeArResult>>>();
  auto answer = promise->get_future();
  videos.RenderAr(video, [promise](StatusOr<CubeArResult> r) { promise->set_value(std::move(r)); });
  if (answer.wait_for(std::chrono::minutes(15)) != std::future_status::ready) {
    return absl::DeadlineExceededError("no AR video after 15 minutes");
  }
  return answer.get();
}

// The studio's real bundled scenario (tests/data/cube/tone_scenario.json:
// 12 s, 640x480, the cube turned twice over a photograph), the bundled man
// and the Bandai clips.
v1::StudioOptions ToneScenarioOptions(const std::string& cube_dir) {
  v1::StudioOptions o;
  o.set_cube_dir(cube_dir);
  o.set_cube_data_dir(kData + "/cube");
  o.set_character_dir(kData + "/characters");
  o.set_cube_ar_clip_dir(kData + "/planner_gesture");
  o.set_max_cube_video_bytes(32 << 20);
  return o;
}

// Per frame of an AR video against its cube video: whether a blob of the
// character (> 1500 pixels differing by > 60 grey levels, < 320 px across)
// stands 30-300 px right of the cube's true centre (the renderer's truth);
// and the mean difference elsewhere (the codecs' noise).
struct ArFrames {
  int64_t frames = 0, with_character = 0;
  double noise = 0;
};
ArFrames CountCharacterFrames(const std::string& ar_path, const std::string& video_path, const std::string& truth_path) {
  ArFrames out;
  std::ifstream truth_file(truth_path);
  const auto truth = nlohmann::json::parse(truth_file, nullptr, false);
  if (truth.is_discarded()) return out;
  const auto& k = truth["camera_matrix"];
  std::vector<double> cube_u;  // the cube's centre, image column, per frame
  for (const auto& f : truth["frames"]) {
    const auto& t = f["camera_from_cube_tvec"];
    cube_u.push_back(k[0].get<double>() * t[0].get<double>() / t[2].get<double>() + k[2].get<double>());
  }
  cv::VideoCapture ar(ar_path), source(video_path);
  cv::Mat a, b, diff;
  while (ar.read(a) && source.read(b) && a.size() == b.size()) {
    cv::absdiff(a, b, diff);
    cv::cvtColor(diff, diff, cv::COLOR_BGR2GRAY);
    cv::Mat changed = diff > 60;
    // The character, 15 cm tall at ~0.45 m: a few thousand pixels, in one place.
    const int n = cv::countNonZero(changed);
    if (n > 1500 && out.frames < static_cast<int64_t>(cube_u.size())) {
      const cv::Rect box = cv::boundingRect(changed);
      const double beside_px = box.x + box.width / 2.0 - cube_u[static_cast<std::size_t>(out.frames)];
      if (box.width < 320 && box.height < 320 && beside_px > 30 && beside_px < 300) ++out.with_character;
    }
    out.noise += cv::mean(diff, ~changed)[0];
    ++out.frames;
  }
  if (out.frames > 0) out.noise /= static_cast<double>(out.frames);
  return out;
}

TEST(CubeAr, TheBundledScenariosArVideoIsDrawnOnceDecodesAndShowsTheCharacter) {
  kinemo::testing::TempDir dir;
  CubeVideos videos(ToneScenarioOptions(dir.File("cube")));
  v1::AttachCubeVideo r;
  r.set_session_id("s1");
  r.set_bundled("tone_scenario");
  auto video = videos.Prepare(r);
  ASSERT_TRUE(video.ok()) << video.status();
  auto script = cube::LoadRenderScript(kData + "/cube/tone_scenario.json");
  ASSERT_TRUE(script.ok()) << script.status();

  auto drawn = DrawAr(videos, *video);
  ASSERT_TRUE(drawn.ok()) << drawn.status();
  EXPECT_EQ(drawn->url, "/cube/ar/bundled/tone_scenario.webm");
  EXPECT_EQ(drawn->path, dir.File("cube/bundled/tone_scenario.ar.webm"));
  EXPECT_EQ(drawn->frames, script->frame_count());
  EXPECT_EQ(drawn->width, 640);
  EXPECT_EQ(drawn->height, 480);
  EXPECT_GT(drawn->render_s, 0);
  // The cube stands in view from the first frame: the man is drawn in (nearly) all.
  EXPECT_GE(drawn->drawn, drawn->frames * 9 / 10);
  std::printf("tone_scenario AR video: %lld frames (%lld with the character) %dx%d, drawn in %.1f s, %.0f KiB\n",
              static_cast<long long>(drawn->frames), static_cast<long long>(drawn->drawn), drawn->width,
              drawn->height, drawn->render_s, static_cast<double>(fs::file_size(drawn->path)) / 1024);
  EXPECT_EQ(FilesIn(dir.File("cube/rendering")), 0u);

  // It decodes (VP8 in WebM) frame for frame with the scenario; where the
  // character stands — beside the cube, on the camera's right of where the
  // renderer's truth puts the cube in the image — the frames differ from the
  // cube video's, elsewhere only by the codecs' noise.
  const ArFrames seen = CountCharacterFrames(drawn->path, video->video, dir.File("cube/bundled/tone_scenario.truth.json"));
  const int64_t frames = seen.frames, with_character = seen.with_character;
  std::printf("the character beside the cube in %lld of %lld frames; mean difference elsewhere %.2f\n",
              static_cast<long long>(with_character), static_cast<long long>(frames), seen.noise);
  EXPECT_EQ(frames, drawn->frames);
  EXPECT_GE(with_character, frames * 9 / 10) << "frames showing the character beside the cube, of " << frames;
  EXPECT_LT(seen.noise, 6.0) << "mean difference away from the character";

  // Kept: a second request reuses the file, at once.
  const auto written = fs::last_write_time(drawn->path);
  CubeVideos again(ToneScenarioOptions(dir.File("cube")));
  auto kept = DrawAr(again, *video);
  ASSERT_TRUE(kept.ok()) << kept.status();
  EXPECT_EQ(kept->render_s, 0);
  EXPECT_EQ(kept->frames, drawn->frames);
  EXPECT_EQ(fs::last_write_time(kept->path), written);

  // The same video uploaded without its camera (a 60° pinhole, as the
  // scenario's): its AR view goes with the upload, drawn or not. A live
  // stream runs meanwhile: the drawing waits for it, and its removal wakes it.
  auto up = videos.Prepare(Upload(ReadAll(video->video)));
  ASSERT_TRUE(up.ok()) << up.status();
  EXPECT_EQ(up->ar.kind, "uploads");
  auto promise = std::make_shared<std::promise<StatusOr<CubeArResult>>>();
  auto answer = promise->get_future();
  videos.LiveStreamStarted();
  videos.RenderAr(*up, [promise](StatusOr<CubeArResult> r) { promise->set_value(std::move(r)); });
  videos.Remove(*up);
  EXPECT_EQ(FilesIn(dir.File("cube/uploads")), 0u);
  ASSERT_EQ(answer.wait_for(std::chrono::minutes(5)), std::future_status::ready);
  EXPECT_EQ(answer.get().status().code(), absl::StatusCode::kCancelled);
  videos.LiveStreamEnded();
  EXPECT_EQ(FilesIn(dir.File("cube/uploads")), 0u);
  EXPECT_EQ(FilesIn(dir.File("cube/rendering")), 0u);
}

// The AR view draws the socket's chosen character: a bundled one gets its
// own kept video beside the man's (bundled/<scenario>--<character>), an
// uploaded one the socket's own, removed with Remove.
TEST(CubeAr, TheChosenCharacterIsDrawn) {
  kinemo::testing::TempDir dir;
  v1::StudioOptions options = ToneScenarioOptions(dir.File("cube"));
  options.set_max_character_bytes(8 << 20);
  CubeVideos videos(options);
  CharacterLibrary characters(options);
  v1::AttachCubeVideo r;
  r.set_session_id("s1");
  r.set_bundled("tone_scenario");
  auto video = videos.Prepare(r);
  ASSERT_TRUE(video.ok()) << video.status();
  v1::SelectCharacter pick;
  pick.set_bundled("godette.vrm");
  auto godette = characters.Select(pick);
  ASSERT_TRUE(godette.ok()) << godette.status();
  CubeVideo with_godette = *video;
  videos.SetArCharacter(&with_godette, *godette);
  EXPECT_EQ(with_godette.ar.kind, "bundled");
  EXPECT_EQ(with_godette.ar.name, "tone_scenario--godette_vrm");
  EXPECT_FALSE(with_godette.own_ar);
  // The default man keeps today's video.
  pick.set_bundled("quaternius_man_casual.glb");
  auto man = characters.Select(pick);
  ASSERT_TRUE(man.ok()) << man.status();
  CubeVideo with_man = *video;
  videos.SetArCharacter(&with_man, *man);
  EXPECT_EQ(with_man.ar.name, "tone_scenario");
  EXPECT_EQ(with_man.ar.character, nullptr);

  auto drawn = DrawAr(videos, with_godette);
  ASSERT_TRUE(drawn.ok()) << drawn.status();
  EXPECT_EQ(drawn->url, "/cube/ar/bundled/tone_scenario--godette_vrm.webm");
  const ArFrames seen =
      CountCharacterFrames(drawn->path, video->video, dir.File("cube/bundled/tone_scenario.truth.json"));
  std::printf("Godette beside the cube in %lld of %lld frames (drawn in %.1f s); mean difference elsewhere %.2f\n",
              static_cast<long long>(seen.with_character), static_cast<long long>(seen.frames), drawn->render_s,
              seen.noise);
  EXPECT_EQ(seen.frames, drawn->frames);
  EXPECT_GE(seen.with_character, seen.frames * 9 / 10);
  EXPECT_LT(seen.noise, 6.0);

  // An uploaded character (the woman's file): the socket's own AR view of
  // the bundled video, in uploads/, gone with Remove.
  pick.Clear();
  pick.set_glb(ReadAll(kData + "/characters/quaternius_woman_casual.glb"));
  pick.set_name("me.glb");
  auto woman = characters.Select(pick);
  ASSERT_TRUE(woman.ok()) << woman.status();
  CubeVideo with_woman = *video;
  videos.SetArCharacter(&with_woman, *woman);
  EXPECT_EQ(with_woman.ar.kind, "uploads");
  EXPECT_TRUE(with_woman.own_ar);
  auto own = DrawAr(videos, with_woman);
  ASSERT_TRUE(own.ok()) << own.status();
  EXPECT_TRUE(fs::is_regular_file(own->path));
  EXPECT_GE(own->drawn, own->frames * 9 / 10);
  videos.Remove(with_woman);
  EXPECT_FALSE(fs::exists(own->path));
  EXPECT_TRUE(fs::is_regular_file(video->video)) << "Remove took the bundled video with the socket's AR view";
}

TEST(CubeAr, NamesThatCannotReachOtherFiles) {
  EXPECT_TRUE(IsCubeArName("tone_scenario"));
  EXPECT_TRUE(IsCubeArName("0123abcd-EF_9"));
  for (const char* bad : {"", "..", "a/b", "a.b", "a%2f", "a b", "a\\b"}) EXPECT_FALSE(IsCubeArName(bad)) << bad;
  EXPECT_FALSE(IsCubeArName(std::string(129, 'a')));
  // Off without cube_dir: answered at once, naming why.
  v1::StudioOptions o;
  CubeArRenderer off(o);
  StatusOr<CubeArResult> got = absl::UnknownError("not answered");
  off.Request({"bundled", "tone_scenario", "", ""}, [&](StatusOr<CubeArResult> r) { got = std::move(r); });
  EXPECT_EQ(got.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(std::string(got.status().message()).rfind("cube_ar: ", 0), 0u) << got.status();
}

}  // namespace
}  // namespace kinemo::studio
