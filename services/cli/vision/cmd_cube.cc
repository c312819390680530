// kinemo cube net       --model CUBE --out net.png [--dpi 300]
// kinemo cube render    --model CUBE --script SCRIPT --out VIDEO.avi --truth TRUTH.json [--camera CAM.yaml]
// kinemo cube track     VIDEO --model CUBE --intrinsics CAM [--json] [--max-frames N]
//                       [--overlay OUT.mp4 [--character RIG.glb] [--height-m H] [--beside-m D]
//                        [--action-clip ACTION=CLIP.bvh ...]]
// kinemo cube board     --out board.png [board options]
// kinemo cube calibrate IMAGES... --out CAM.yaml [--surface IMAGE] [board options]
// kinemo cube push      CUBE --id ID [--server ADDR] [--overwrite] [--description T] [--json]
// kinemo cube ls        [--server ADDR] [--all] [--json]
// kinemo cube rm        ID[@VERSION] [--server ADDR]
#include "services/cli/commands.h"

#include <cstdio>
#include <iostream>
#include <cmath>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "services/cli/artifact_commands.h"
#include "services/cube_tracker/ar/ar_video.h"
#include "services/cube_tracker/core/calibration.h"
#include "services/cube_tracker/core/camera.h"
#include "services/cube_tracker/core/cube_model.h"
#include "services/cube_tracker/core/tracker.h"
#include "services/cube_tracker/render/renderer.h"

namespace kinemo::cli {
namespace {

using namespace kinemo::cube;  // NOLINT: the command file speaks the cube's language

// Prints the error; returns the exit code: 2 for bad input, 1 otherwise.
int Fail(const Status& s) {
  std::cerr << "kinemo cube: " << std::string(s.message()) << "\n";
  const bool bad_input =
      s.code() == absl::StatusCode::kInvalidArgument || s.code() == absl::StatusCode::kNotFound;
  return bad_input ? 2 : 1;
}

nlohmann::json StateJson(const CubeState& s) {
  nlohmann::json j;
  j["frame"] = s.frame;
  j["time_s"] = s.time_s;
  j["visible"] = s.visible;
  j["top_face"] = s.top_face;
  j["action"] = ActionName(s.action);
  j["yaw_deg"] = s.yaw_deg;
  j["intensity"] = s.intensity;
  j["position_m"] = {s.position_m[0], s.position_m[1]};
  j["height_m"] = s.height_m;
  j["lifted"] = s.lifted;
  j["markers"] = s.markers;
  nlohmann::json ev = nlohmann::json::array();
  for (const CubeEvent& e : s.events) {
    nlohmann::json x;
    x["type"] = EventTypeName(e.type);
    x["frame"] = s.frame;
    x["time_s"] = e.time_s;
    x["top_face"] = e.top_face;
    x["action"] = ActionName(e.action);
    x["intensity"] = e.intensity;
    if (e.type == EventType::kFaceChanged) x["previous_face"] = e.previous_face;
    if (e.type == EventType::kIntensityChanged) x["previous_intensity"] = e.previous_intensity;
    if (e.type == EventType::kLost) x["last_seen_time_s"] = e.last_seen_time_s;
    ev.push_back(x);
  }
  j["events"] = ev;
  return j;
}

// The AR view's inputs (`--overlay`): the character and the clip of each
// action (default: the bundled Bandai-Namco clips).
struct OverlayArgs {
  std::string output;  // empty: no overlay
  ar::OverlaySpec spec{.character = std::string(KINEMO_VISION_DATA_DIR) + "/characters/quaternius_man_casual.glb",
                       .action_clips = {},
                       .options = {},
                       .character_field = "--character",
                       .action_clip_field = "--action-clip"};
};

int Track(const std::string& video, const std::string& model_path, const std::string& cam_path, bool json,
          int64_t max_frames, const OverlayArgs& overlay_args) {
  auto model = LoadCubeModel(model_path);
  if (!model.ok()) return Fail(model.status());
  auto camera = LoadCameraModel(cam_path);
  if (!camera.ok()) return Fail(camera.status());
  auto tracker = CubeTracker::Create(*model, *camera);
  if (!tracker.ok()) return Fail(tracker.status());
  cv::VideoCapture cap;
  try {
    const bool is_index = !video.empty() && video.find_first_not_of("0123456789") == std::string::npos;
    if (is_index ? !cap.open(std::stoi(video), cv::CAP_V4L2) : !cap.open(video)) {
      return Fail(absl::NotFoundError(video + ": cannot open video file or camera"));
    }
  } catch (const cv::Exception& e) {
    return Fail(absl::InternalError(video + ": " + e.what()));
  }
  const double fps = ar::CaptureFps(cap);
  std::optional<ar::ArOverlay> overlay;
  cv::VideoWriter writer;
  if (!overlay_args.output.empty()) {
    ar::OverlaySpec spec = overlay_args.spec;
    if (spec.action_clips.empty()) {
      spec.action_clips = ar::DefaultActionClips(std::string(KINEMO_VISION_DATA_DIR) + "/planner_gesture");
    }
    auto made = ar::MakeArOverlay(spec);
    if (!made.ok()) return Fail(made.status());
    overlay.emplace(*std::move(made));
    const Status opened =
        ar::OpenArWriter(overlay_args.output, fps, cv::Size(camera->width, camera->height), "--overlay", &writer);
    if (!opened.ok()) return Fail(opened);
  }
  int errors = 0;
  auto read = ar::TrackVideo(cap, fps, *tracker, *camera, overlay ? &*overlay : nullptr, max_frames,
                             [&](const ar::TrackedFrame& f) -> Status {
    if (!f.tracked.ok()) {
      ++errors;
      std::cerr << "frame " << f.index << ": " << std::string(f.tracked.message()) << "\n";
      return absl::OkStatus();
    }
    const CubeState& state = *f.state;
    if (overlay) writer.write(*f.bgr);
    if (json) {
      nlohmann::json j = StateJson(state);
      if (overlay) {
        j["character"] = {{"drawn", false}};
        if (f.drawn != nullptr && f.drawn->drawn) {
          const ar::DrawInfo& info = *f.drawn;
          const ar::Placement& p = overlay->placement();
          j["character"] = {{"drawn", true},
                            {"action", ActionName(overlay->action())},
                            {"position_m", {p.position_m[0], p.position_m[1]}},
                            {"yaw_deg", p.yaw_rad * 180 / M_PI},
                            {"pixels", info.pixels},
                            {"soles_px", {{info.soles_px[0].x, info.soles_px[0].y}, {info.soles_px[1].x, info.soles_px[1].y}}}};
        }
      }
      std::cout << j.dump() << "\n";
    } else {
      std::printf("%6lld %8.3f %s face %d %-16s yaw %8.2f intensity %6.3f pos %7.4f %7.4f%s\n",
                  static_cast<long long>(state.frame), state.time_s, state.visible ? "seen" : "----",
                  state.top_face, ActionName(state.action), state.yaw_deg, state.intensity, state.position_m[0],
                  state.position_m[1], state.lifted ? " lifted" : "");
      for (const auto& e : state.events) {
        std::printf("       event %s face %d %s intensity %.3f\n", EventTypeName(e.type), e.top_face,
                    ActionName(e.action), e.intensity);
      }
    }
    return absl::OkStatus();
  });
  if (!read.ok()) return Fail(read.status());
  std::cout.flush();
  return errors == 0 ? 0 : 2;
}

void AddBoardOptions(CLI::App* cmd, CharucoBoardSpec* b) {
  cmd->add_option("--squares-x", b->squares_x, "board squares along x")->capture_default_str();
  cmd->add_option("--squares-y", b->squares_y, "board squares along y")->capture_default_str();
  cmd->add_option("--square-m", b->square_size_m, "square side in metres")->capture_default_str();
  cmd->add_option("--marker-m", b->marker_size_m, "marker side in metres")->capture_default_str();
  cmd->add_option("--board-dictionary", b->dictionary, "ArUco dictionary")->capture_default_str();
}

}  // namespace

void RegisterCubeCommands(CLI::App& app) {
  CLI::App* cube =
      app.add_subcommand("cube", "the AvatAR marker cube: net, render, track, calibrate; push, ls, rm (the tracker's store)");
  cube->require_subcommand(1);
  AddArtifactCommands(cube, {.noun = "cube",
                             .kind = "cubes",
                             .file_name = "cube.textproto",
                             .file_help = "cube model (text proto, e.g. tests/data/cube/vleo.cube); its cube_id "
                                          "is replaced by --id"});

  {
    auto model = std::make_shared<std::string>();
    auto out = std::make_shared<std::string>();
    auto dpi = std::make_shared<double>(300);
    CLI::App* cmd = cube->add_subcommand("net", "print the cube's net as PNG to cut and fold");
    cmd->add_option("--model", *model, "cube model (text proto)")->required();
    cmd->add_option("-o,--out", *out, "output PNG")->required();
    cmd->add_option("--dpi", *dpi, "print resolution")->capture_default_str();
    cmd->callback([=]() {
      auto m = LoadCubeModel(*model);
      if (!m.ok()) throw CliExit{Fail(m.status())};
      auto net = RenderNet(*m, *dpi);
      if (!net.ok()) throw CliExit{Fail(net.status())};
      bool ok = false;
      try {
        ok = cv::imwrite(*out, *net);
      } catch (const cv::Exception&) {
        ok = false;
      }
      if (!ok) throw CliExit{Fail(absl::PermissionDeniedError(*out + ": cannot write PNG"))};
      std::cout << *out << ": " << net->cols << "x" << net->rows << " px at " << *dpi << " dpi\n";
    });
  }
  {
    auto model = std::make_shared<std::string>();
    auto script = std::make_shared<std::string>();
    auto out = std::make_shared<std::string>();
    auto truth = std::make_shared<std::string>();
    auto camera = std::make_shared<std::string>();
    CLI::App* cmd = cube->add_subcommand("render", "render a scripted cube sequence (MJPG AVI) with its ground truth");
    cmd->add_option("--model", *model, "cube model (text proto)")->required();
    cmd->add_option("--script", *script, "render script (JSON)")->required();
    cmd->add_option("-o,--out", *out, "output video (.avi, MJPG)")->required();
    cmd->add_option("--truth", *truth, "output truth JSON");
    cmd->add_option("--camera", *camera, "output camera YAML (intrinsics + surface)");
    cmd->callback([=]() {
      auto m = LoadCubeModel(*model);
      if (!m.ok()) throw CliExit{Fail(m.status())};
      auto s = LoadRenderScript(*script);
      if (!s.ok()) throw CliExit{Fail(s.status())};
      std::string cam = *camera;
      if (cam.empty()) cam = *out + ".camera.yaml";
      Status st = SequenceRenderer::RenderToFiles(*m, *s, *out, *truth, cam);
      if (!st.ok()) throw CliExit{Fail(st)};
      std::cout << *out << ": " << s->frame_count() << " frames; camera " << cam << "\n";
    });
  }
  {
    auto video = std::make_shared<std::string>();
    auto model = std::make_shared<std::string>();
    auto cam = std::make_shared<std::string>();
    auto json = std::make_shared<bool>(false);
    auto max_frames = std::make_shared<int64_t>(0);
    auto overlay = std::make_shared<OverlayArgs>();
    CLI::App* cmd = cube->add_subcommand("track", "track the cube in a video file or camera (V4L2 index)");
    cmd->add_option("--overlay", overlay->output,
                    "write the AR view: the frames with the character drawn on the table beside the cube (MPEG-4; "
                    "WebM / VP8 for a name ending in .webm)");
    cmd->add_option("--character", overlay->spec.character, "with --overlay: the character (.glb/.vrm with a skin)")
        ->capture_default_str();
    cmd->add_option("--height-m", overlay->spec.options.character_height_m,
                    "with --overlay: the character's standing height on the table, metres")
        ->capture_default_str();
    cmd->add_option("--beside-m", overlay->spec.options.beside_m,
                    "with --overlay: its distance from the cube, along the camera's right on the table")
        ->capture_default_str();
    cmd->add_option("--action-clip", overlay->spec.action_clips,
                    "with --overlay: ACTION=CLIP.bvh, the motion of an action (idle, throwing_kisses, shouting; "
                    "any kinemo skeleton); default: bundled Bandai-Namco clips");
    cmd->add_option("video", *video, "video file, or a V4L2 camera index such as 0")->required();
    cmd->add_option("--model", *model, "cube model (text proto)")->required();
    cmd->add_option("--intrinsics", *cam, "camera YAML (OpenCV FileStorage)")->required();
    cmd->add_flag("--json", *json, "one JSON object per frame");
    cmd->add_option("--max-frames", *max_frames, "stop after N frames (0: all)");
    cmd->callback([=]() {
      const int rc = Track(*video, *model, *cam, *json, *max_frames, *overlay);
      if (rc != 0) throw CliExit{rc};
    });
  }
  {
    auto board = std::make_shared<CharucoBoardSpec>();
    auto out = std::make_shared<std::string>();
    auto px = std::make_shared<int>(200);
    CLI::App* cmd = cube->add_subcommand("board", "print a ChArUco calibration board as PNG");
    cmd->add_option("-o,--out", *out, "output PNG")->required();
    cmd->add_option("--pixels-per-square", *px, "resolution")->capture_default_str();
    AddBoardOptions(cmd, board.get());
    cmd->callback([=]() {
      auto img = RenderCharucoBoard(*board, *px);
      if (!img.ok()) throw CliExit{Fail(img.status())};
      if (!cv::imwrite(*out, *img)) {
        throw CliExit{Fail(absl::PermissionDeniedError(*out + ": cannot write PNG"))};
      }
      std::cout << *out << "\n";
    });
  }
  {
    auto board = std::make_shared<CharucoBoardSpec>();
    auto images = std::make_shared<std::vector<std::string>>();
    auto out = std::make_shared<std::string>();
    auto surface = std::make_shared<std::string>();
    auto existing = std::make_shared<std::string>();
    CLI::App* cmd = cube->add_subcommand(
        "calibrate", "calibrate the camera from ChArUco board images; with --surface, also the table's pose");
    cmd->add_option("images", *images, "board images (4 or more views)");
    cmd->add_option("--intrinsics", *existing, "start from these intrinsics (only --surface is computed)");
    cmd->add_option("--surface", *surface, "an image of the board lying flat on the table");
    cmd->add_option("-o,--out", *out, "output camera YAML")->required();
    AddBoardOptions(cmd, board.get());
    cmd->callback([=]() {
      CameraModel camera;
      if (!existing->empty()) {
        auto c = LoadCameraModel(*existing);
        if (!c.ok()) throw CliExit{Fail(c.status())};
        camera = *c;
      } else {
        std::vector<cv::Mat> views;
        for (const auto& p : *images) {
          cv::Mat m = cv::imread(p, cv::IMREAD_GRAYSCALE);
          if (m.empty()) throw CliExit{Fail(absl::NotFoundError(p + ": cannot read image"))};
          views.push_back(m);
        }
        auto r = CalibrateCharuco(views, *board);
        if (!r.ok()) throw CliExit{Fail(r.status())};
        camera = r->camera;
        std::cout << "calibrated from " << r->images_used << " views, RMS " << r->rms_px << " px\n";
      }
      if (!surface->empty()) {
        cv::Mat img = cv::imread(*surface, cv::IMREAD_GRAYSCALE);
        if (img.empty()) throw CliExit{Fail(absl::NotFoundError(*surface + ": cannot read image"))};
        auto s = SurfaceFromCharuco(img, camera, *board);
        if (!s.ok()) throw CliExit{Fail(s.status())};
        camera.surface = *s;
      }
      Status st = SaveCameraModel(camera, *out);
      if (!st.ok()) throw CliExit{Fail(st)};
      std::cout << *out << "\n";
    });
  }
}

}  // namespace kinemo::cli
