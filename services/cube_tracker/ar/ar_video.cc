// The AR view of a whole cube video (ar_video.h).
#include "services/cube_tracker/ar/ar_video.h"

#include <algorithm>
#include <memory>
#include <utility>

#include <opencv2/imgproc.hpp>

#include "common/motion/bvh.h"
#include "common/retarget/rig.h"

namespace kinemo::cube::ar {

std::vector<std::string> DefaultActionClips(const std::string& clip_dir) {
  const std::string dir = clip_dir.empty() || clip_dir.back() == '/' ? clip_dir : clip_dir + "/";
  return {"idle=" + dir + "dataset-1_respond_normal_001.bvh", "throwing_kisses=" + dir + "dataset-1_byebye_normal_001.bvh",
          "shouting=" + dir + "dataset-1_bye_angry_001.bvh"};
}

StatusOr<ArOverlay> MakeArOverlay(const OverlaySpec& spec) {
  KINEMO_RETURN_IF_ERROR(ValidateArOptions(spec.options));
  std::shared_ptr<const retarget::Rig> shared = spec.rig;
  if (!shared) {
    auto rig = retarget::LoadGltfRig(spec.character);
    if (!rig.ok()) return Annotate(rig.status(), spec.character_field);
    shared = std::make_shared<const retarget::Rig>(*std::move(rig));
  }
  auto view = CharacterView::Create(shared, spec.options.shadow_opacity);
  if (!view.ok()) return Annotate(view.status(), spec.character_field);
  std::vector<ActionPlayer::Source> sources;
  for (size_t i = 0; i < spec.action_clips.size(); ++i) {
    const std::string& clip_spec = spec.action_clips[i];
    const std::string field = kinemo::StrCat(spec.action_clip_field, "[", i, "]");
    const auto eq = clip_spec.find('=');
    if (eq == std::string::npos) return InvalidField(field, "'", clip_spec, "' is not ACTION=FILE.bvh");
    const std::string name = clip_spec.substr(0, eq);
    Action action = Action::kUnknown;
    for (Action x : {Action::kIdle, Action::kThrowingKisses, Action::kShouting}) {
      if (name == ActionName(x)) action = x;
    }
    if (action == Action::kUnknown) {
      return InvalidField(field, "'", name, "' is not an action (idle, throwing_kisses, shouting)");
    }
    auto clip = motion::ReadBvhFile(clip_spec.substr(eq + 1));
    if (!clip.ok()) return Annotate(clip.status(), field);
    sources.push_back({action, *std::move(clip), 0});
  }
  auto player = ActionPlayer::Create(*shared, std::move(sources));
  if (!player.ok()) return Annotate(player.status(), spec.action_clip_field);
  return ArOverlay(*std::move(view), *std::move(player), spec.options);
}

double CaptureFps(cv::VideoCapture& capture) {
  const double fps = capture.get(cv::CAP_PROP_FPS);
  return fps > 0 && fps < 1000 ? fps : 30;
}

StatusOr<int64_t> TrackVideo(cv::VideoCapture& capture, double fps, CubeTracker& tracker, const CameraModel& camera,
                             ArOverlay* overlay, int64_t max_frames, const FrameSink& sink) {
  cv::Mat frame;
  CubeState state;
  int64_t i = 0;
  for (; max_frames <= 0 || i < max_frames; ++i) {
    bool ok = false;
    try {
      ok = capture.read(frame);
    } catch (const cv::Exception&) {
      ok = false;
    }
    if (!ok || frame.empty()) break;
    TrackedFrame out;
    DrawInfo info;
    out.index = i;
    out.time_s = static_cast<double>(i) / fps;
    out.tracked = tracker.Process(frame, out.time_s, &state);
    out.state = &state;
    out.bgr = &frame;
    if (overlay != nullptr && out.tracked.ok()) {
      if (frame.channels() == 1) cv::cvtColor(frame, frame, cv::COLOR_GRAY2BGR);
      KINEMO_RETURN_IF_ERROR(overlay->Compose(state, tracker.surface(), camera, out.time_s, &frame, &info));
      out.drawn = &info;
    }
    KINEMO_RETURN_IF_ERROR(sink(out));
  }
  return i;
}

Status OpenArWriter(const std::string& path, double fps, cv::Size size, const std::string& field,
                    cv::VideoWriter* writer) {
  const bool webm = path.size() >= 5 && path.compare(path.size() - 5, 5, ".webm") == 0;
  bool opened = false;
  try {
    opened = webm ? writer->open(path, cv::CAP_FFMPEG, cv::VideoWriter::fourcc('V', 'P', '8', '0'), fps, size)
                  : writer->open(path, cv::VideoWriter::fourcc('m', 'p', '4', 'v'), fps, size);
  } catch (const cv::Exception&) {
    opened = false;
  }
  if (!opened) {
    return InvalidField(field, path, webm ? ": cannot write a WebM (VP8) video there" : ": cannot write an MPEG-4 video there");
  }
  return absl::OkStatus();
}

StatusOr<ArVideoSummary> WriteArVideo(const std::string& video, const CubeModel& model, const CameraModel& camera,
                                      ArOverlay& overlay, const std::string& output, const ArVideoLimits& limits) {
  KINEMO_ASSIGN_OR_RETURN(CubeTracker tracker, CubeTracker::Create(model, camera));
  cv::VideoCapture capture;
  bool opened = false;
  try {
    opened = capture.open(video);
  } catch (const cv::Exception&) {
    opened = false;
  }
  if (!opened) return InvalidField("video", video, ": OpenCV cannot read it");
  ArVideoSummary summary;
  summary.fps = CaptureFps(capture);
  cv::Size size(camera.width, camera.height);
  const int side = std::max(camera.width, camera.height);
  if (limits.max_side_px > 0 && side > limits.max_side_px) {
    const double scale = static_cast<double>(limits.max_side_px) / side;
    // Even sides (the VP8 encoder's chroma planes).
    size = cv::Size(std::max(2, static_cast<int>(camera.width * scale) & ~1),
                    std::max(2, static_cast<int>(camera.height * scale) & ~1));
  }
  cv::VideoWriter writer;
  KINEMO_RETURN_IF_ERROR(OpenArWriter(output, summary.fps, size, "output", &writer));
  summary.width = size.width;
  summary.height = size.height;
  cv::Mat scaled;
  auto read = TrackVideo(capture, summary.fps, tracker, camera, &overlay, limits.max_frames,
                         [&](const TrackedFrame& f) -> Status {
                           if (limits.before_frame) KINEMO_RETURN_IF_ERROR(limits.before_frame());
                           if (f.bgr->cols != camera.width || f.bgr->rows != camera.height) {
                             return InvalidField("video", video, " has ", f.bgr->cols, "x", f.bgr->rows,
                                                 " frames, its camera ", camera.width, "x", camera.height);
                           }
                           if (f.bgr->channels() == 1) cv::cvtColor(*f.bgr, *f.bgr, cv::COLOR_GRAY2BGR);
                           const cv::Mat* out = f.bgr;
                           if (size != f.bgr->size()) {
                             cv::resize(*f.bgr, scaled, size, 0, 0, cv::INTER_AREA);
                             out = &scaled;
                           }
                           writer.write(*out);
                           ++summary.frames;
                           if (f.drawn != nullptr && f.drawn->drawn) ++summary.drawn;
                           return absl::OkStatus();
                         });
  writer.release();
  if (!read.ok()) return read.status();
  if (summary.frames == 0) return InvalidField("video", video, " has no frame OpenCV can read");
  return summary;
}

}  // namespace kinemo::cube::ar
