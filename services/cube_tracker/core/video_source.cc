// What the cube tracker server reads on a client's behalf (video_source.h).
#include "services/cube_tracker/core/video_source.h"

#include <filesystem>

namespace kinemo::cube {

StatusOr<std::string> ResolveUnderRoot(const std::string& root, const std::string& relative,
                                       std::string_view field) {
  namespace fs = std::filesystem;
  if (root.empty()) return InvalidField(field, "server-side files are disabled (file_root is not set)");
  if (relative.empty()) return InvalidField(field, "empty path");
  if (relative.find('\0') != std::string::npos) return InvalidField(field, "path holds a NUL byte");
  std::error_code ec;
  const fs::path canonical_root = fs::canonical(root, ec);
  if (ec) return absl::UnavailableError(StrCat("file_root ", root, ": ", ec.message()));
  const fs::path joined = fs::path(relative).is_absolute() ? fs::path(relative) : canonical_root / relative;
  const fs::path resolved = fs::weakly_canonical(joined, ec);
  if (ec) return InvalidField(field, "'", relative, "': ", ec.message());
  const std::string r = resolved.string(), base = canonical_root.string() + "/";
  if (r.compare(0, base.size(), base) != 0) {
    return InvalidField(field, "'", relative, "' is outside the server's file_root");
  }
  if (!fs::is_regular_file(resolved, ec)) return absl::NotFoundError(StrCat(field, ": '", relative, "' not found"));
  return r;
}

StatusOr<std::unique_ptr<VideoSource>> VideoSource::Open(const cube_tracker::v1::VideoSource& src,
                                                         const cube_tracker::v1::CubeTrackerOptions& options,
                                                         const CameraModel& cam) {
  std::unique_ptr<VideoSource> source(new VideoSource(src));
  cv::VideoCapture& capture = source->capture_;
  try {
    switch (src.source_case()) {
      case cube_tracker::v1::VideoSource::kVideoFile: {
        KINEMO_ASSIGN_OR_RETURN(std::string path,
                                ResolveUnderRoot(options.file_root(), src.video_file(), "source.video_file"));
        if (!capture.open(path)) {
          return absl::FailedPreconditionError(
              StrCat("source.video_file: '", src.video_file(), "' cannot be read as video"));
        }
        if (src.start_frame() > 0) capture.set(cv::CAP_PROP_POS_FRAMES, static_cast<double>(src.start_frame()));
        break;
      }
      case cube_tracker::v1::VideoSource::kDevice: {
        bool allowed = false;
        for (const auto& d : options.allowed_devices()) allowed = allowed || d == src.device();
        if (!allowed) return InvalidField("source.device", "'", src.device(), "' is not an allowed device");
        if (!capture.open(src.device(), cv::CAP_V4L2)) {
          return absl::UnavailableError(StrCat("source.device: '", src.device(), "' cannot be opened"));
        }
        source->device_ = true;
        if (src.width_px() > 0) capture.set(cv::CAP_PROP_FRAME_WIDTH, src.width_px());
        if (src.height_px() > 0) capture.set(cv::CAP_PROP_FRAME_HEIGHT, src.height_px());
        if (src.fps() > 0) capture.set(cv::CAP_PROP_FPS, src.fps());
        break;
      }
      default:
        return InvalidField("source", "neither video_file nor device");
    }
    const int w = static_cast<int>(capture.get(cv::CAP_PROP_FRAME_WIDTH));
    const int h = static_cast<int>(capture.get(cv::CAP_PROP_FRAME_HEIGHT));
    if (w > 0 && h > 0 && (w != cam.width || h != cam.height)) {
      return InvalidField(source->device_ ? "source.device" : "source.video_file", "frames are ", w, "x", h,
                          ", the intrinsics are for ", cam.width, "x", cam.height);
    }
    source->fps_ = capture.get(cv::CAP_PROP_FPS);
  } catch (const cv::Exception& e) {
    return absl::UnavailableError(StrCat("source: OpenCV: ", e.what()));
  }
  if (!(source->fps_ > 0 && source->fps_ < 1000)) source->fps_ = 30;
  source->next_index_ = source->device_ ? 0 : src.start_frame();
  return source;
}

VideoSource::~VideoSource() { capture_.release(); }

StatusOr<bool> VideoSource::Next(cv::Mat* image, Frame* frame) {
  if (source_.max_frames() != 0 && read_ >= source_.max_frames()) return false;
  const auto now = std::chrono::steady_clock::now();
  if (!start_) start_ = now;
  bool ok = false;
  try {
    ok = capture_.read(*image);
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok) {
    if (device_) return absl::UnavailableError("source.device: capture failed");
    return false;
  }
  frame->index = next_index_;
  frame->time_s = device_ ? std::chrono::duration<double>(std::chrono::steady_clock::now() - *start_).count()
                          : static_cast<double>(next_index_) / fps_;
  frame->due.reset();
  if (!device_ && source_.realtime()) {
    frame->due = *start_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                               std::chrono::duration<double>(frame->time_s - source_.start_frame() / fps_));
  }
  ++next_index_;
  ++read_;
  return true;
}

}  // namespace kinemo::cube
