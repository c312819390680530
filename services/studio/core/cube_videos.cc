// The cube videos of `attach_cube` (cube_videos.h).
#include "services/studio/core/cube_videos.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

#include <opencv2/videoio.hpp>

#include "common/logging/log.h"
#include "services/cube_tracker/core/camera.h"
#include "services/cube_tracker/core/cube_model.h"
#include "services/cube_tracker/render/renderer.h"
#include "services/studio/core/token.h"

namespace kinemo::studio {
namespace {

namespace fs = std::filesystem;

bool WriteFile(const fs::path& path, std::string_view bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return static_cast<bool>(out);
}

// The container a video's first bytes announce: ".avi", ".mp4", ".mkv", or "".
std::string ContainerOf(std::string_view b) {
  if (b.size() >= 12 && b.substr(0, 4) == "RIFF" && b.substr(8, 4) == "AVI ") return ".avi";
  if (b.size() >= 12 && b.substr(4, 4) == "ftyp") return ".mp4";
  if (b.size() >= 4 && b.substr(0, 4) == std::string_view("\x1a\x45\xdf\xa3", 4)) return ".mkv";
  return "";
}

}  // namespace

CubeVideos::CubeVideos(const v1::StudioOptions& options)
    : cube_dir_(options.cube_dir()), data_dir_(options.cube_data_dir()), ar_(options) {
  max_video_bytes_ = options.max_cube_video_bytes();
  std::error_code ec;
  if (!data_dir_.empty()) {
    std::ifstream in(fs::path(data_dir_) / "vleo.cube");
    std::ostringstream text;
    text << in.rdbuf();
    if (in) cube_model_text_ = text.str();
    for (const auto& entry : fs::directory_iterator(data_dir_, ec)) {
      if (entry.path().extension() == ".json" && entry.is_regular_file(ec)) {
        scenarios_.push_back(entry.path().stem().string());
      }
    }
    std::sort(scenarios_.begin(), scenarios_.end());
  }
  if (!cube_dir_.empty()) {
    fs::remove_all(fs::path(cube_dir_) / "uploads", ec);
    fs::create_directories(fs::path(cube_dir_) / "uploads", ec);
    fs::create_directories(fs::path(cube_dir_) / "bundled", ec);
  }
}

StatusOr<CubeVideo> CubeVideos::Prepare(const v1::AttachCubeVideo& request) {
  if (!enabled()) {
    return absl::FailedPreconditionError(
        "cube_dir: the studio has no folder for cube videos (StudioOptions.cube_dir, inside the cube "
        "tracker's file_root); attaching a cube is off");
  }
  if (request.session_id().empty()) return InvalidField("attach_cube.session_id", "is empty: open a session first");
  switch (request.video_case()) {
    case v1::AttachCubeVideo::kBundled:
      return Bundled(request.bundled());
    case v1::AttachCubeVideo::kUpload:
      return Upload(request);
    case v1::AttachCubeVideo::VIDEO_NOT_SET:
      break;
  }
  return InvalidField("attach_cube", "names no video: give `bundled` (a scenario) or `upload` (a video file)");
}

StatusOr<CubeVideo> CubeVideos::Bundled(const std::string& name) {
  if (std::find(scenarios_.begin(), scenarios_.end(), name) == scenarios_.end()) {
    return absl::NotFoundError(kinemo::StrCat("attach_cube.bundled: no scenario \"", name.substr(0, 64),
                                              "\" (the studio has ", scenarios_.size(), ")"));
  }
  const fs::path dir = fs::path(cube_dir_) / "bundled";
  CubeVideo out{(dir / (name + ".avi")).string(), (dir / (name + ".camera.yaml")).string(), false, {}};
  out.ar = {"bundled", name, out.video, out.camera};
  std::lock_guard<std::mutex> l(render_mu_);
  std::error_code ec;
  if (fs::is_regular_file(out.video, ec) && fs::is_regular_file(out.camera, ec)) return out;
  // Drawn once: to partial names, renamed when whole.
  auto model = cube::LoadCubeModel((fs::path(data_dir_) / "vleo.cube").string());
  if (!model.ok()) return Annotate(model.status(), "cube_data_dir");
  auto script = cube::LoadRenderScript((fs::path(data_dir_) / (name + ".json")).string());
  if (!script.ok()) return Annotate(script.status(), "cube_data_dir");
  const std::string video = (dir / (name + ".partial.avi")).string();
  const std::string camera = (dir / (name + ".partial.camera.yaml")).string();
  const auto started = std::chrono::steady_clock::now();
  KINEMO_RETURN_IF_ERROR(Annotate(
      cube::SequenceRenderer::RenderToFiles(*model, *script, video, (dir / (name + ".truth.json")).string(), camera),
      kinemo::StrCat("attach_cube.bundled: rendering ", name)));
  fs::rename(camera, out.camera, ec);
  if (!ec) fs::rename(video, out.video, ec);
  if (ec) return absl::InternalError(kinemo::StrCat("cube_dir: cannot keep the rendered ", name, ": ", ec.message()));
  log::Info("cube_scenario_rendered",
            {{"scenario", name},
             {"frames", script->frame_count()},
             {"seconds", std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count()}});
  return out;
}

StatusOr<CubeVideo> CubeVideos::Upload(const v1::AttachCubeVideo& request) {
  const std::string& bytes = request.upload();
  const std::string& name = request.name();
  if (name.size() > kMaxCubeNameBytes) {
    return InvalidField("attach_cube.name", "is ", name.size(), " bytes, at most ", kMaxCubeNameBytes);
  }
  if (bytes.empty()) return InvalidField("attach_cube.upload", "is empty");
  if (bytes.size() > max_video_bytes_) {
    return InvalidField("attach_cube.upload", name, " is ", bytes.size(), " bytes, the studio takes at most ",
                        max_video_bytes_, " (max_cube_video_bytes)");
  }
  if (request.camera_yaml().size() > kMaxCubeCameraBytes) {
    return InvalidField("attach_cube.camera_yaml", "is ", request.camera_yaml().size(), " bytes, at most ",
                        kMaxCubeCameraBytes);
  }
  const std::string container = ContainerOf(bytes);
  if (container.empty()) {
    return InvalidField("attach_cube.upload", name, " is not a video file (AVI, MP4, MKV / WebM)");
  }
  const std::string id = NewToken();
  const fs::path base = fs::path(cube_dir_) / "uploads" / id;
  CubeVideo out{base.string() + container, "", true, {}};
  if (!WriteFile(out.video, bytes)) {
    Remove(out);
    return absl::InternalError(kinemo::StrCat("cube_dir: cannot write ", out.video));
  }
  {
    cv::VideoCapture capture(out.video);
    cv::Mat frame;
    if (!capture.isOpened() || !capture.read(frame) || frame.empty()) {
      Remove(out);
      return InvalidField("attach_cube.upload", name, " has no frame OpenCV can read");
    }
    if (frame.cols > kMaxCubeVideoSidePx || frame.rows > kMaxCubeVideoSidePx) {
      Remove(out);
      return InvalidField("attach_cube.upload", name, " has ", frame.cols, "x", frame.rows,
                          " frames, at most ", kMaxCubeVideoSidePx, " px a side");
    }
  }
  if (!request.camera_yaml().empty()) {
    out.camera = base.string() + ".camera.yaml";
    if (!WriteFile(out.camera, request.camera_yaml())) {
      Remove(out);
      return absl::InternalError(kinemo::StrCat("cube_dir: cannot write ", out.camera));
    }
    if (auto camera = cube::LoadCameraModel(out.camera); !camera.ok()) {
      Remove(out);
      return InvalidField("attach_cube.camera_yaml", "not camera intrinsics: ", camera.status().message());
    }
  }
  out.ar = {"uploads", id, out.video, out.camera};
  return out;
}

void CubeVideos::SetArCharacter(CubeVideo* video, std::shared_ptr<const Character> character) const {
  if (!character) return;
  const bool bundled_character = !character->info.url().empty();
  if (bundled_character && character->info.name() == kCubeArCharacter) return;  // today's AR view
  video->ar.character = std::move(character);
  if (video->uploaded) return;  // the upload's AR view, removed with it
  if (bundled_character) {
    std::string tag;  // the file name in A-Z a-z 0-9 _ -
    for (unsigned char c : video->ar.character->info.name()) tag += std::isalnum(c) || c == '-' ? char(c) : '_';
    const std::string name = kinemo::StrCat(video->ar.name, "--", tag);
    if (IsCubeArName(name)) {
      video->ar.name = name;
      return;
    }
  }
  video->ar.kind = "uploads";
  video->ar.name = NewToken();
  video->own_ar = true;
}

void CubeVideos::Remove(const CubeVideo& video) {
  if (video.own_ar) ar_.Forget(video.ar);
  if (!video.uploaded) return;
  ar_.Forget(video.ar);
  std::error_code ec;
  fs::remove(video.video, ec);
  if (!video.camera.empty()) fs::remove(video.camera, ec);
}

}  // namespace kinemo::studio
