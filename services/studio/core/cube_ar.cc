// The AR view of the attached cube videos (cube_ar.h).
#include "services/studio/core/cube_ar.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cctype>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <system_error>

#include <nlohmann/json.hpp>
#include <opencv2/videoio.hpp>

#include "common/logging/log.h"
#include "services/cube_tracker/ar/ar_video.h"
#include "services/cube_tracker/core/camera.h"
#include "services/cube_tracker/core/cube_model.h"

namespace kinemo::studio {
namespace {

namespace fs = std::filesystem;

// The field of view the AR view assumes for an upload without its camera.
constexpr double kDefaultHfovDeg = 60;

// Beside a kept AR video (NAME.ar.webm -> NAME.ar.json): what it holds
// (answered when it is reused).
std::string SidecarOf(const std::string& video) { return fs::path(video).replace_extension(".json").string(); }

bool ReadSidecar(const std::string& video, CubeArResult* out) {
  std::error_code ec;
  if (!fs::is_regular_file(video, ec)) return false;
  std::ifstream in(SidecarOf(video));
  const auto j = nlohmann::json::parse(in, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return false;
  out->frames = j.value("frames", std::int64_t{0});
  out->drawn = j.value("drawn", std::int64_t{0});
  out->width = j.value("width", 0);
  out->height = j.value("height", 0);
  out->fps = j.value("fps", 0.0);
  return out->frames > 0;
}

StatusOr<cube::CameraModel> CameraFor(const CubeArTarget& target) {
  if (!target.camera.empty()) return cube::LoadCameraModel(target.camera);
  cv::VideoCapture probe;
  try {
    probe.open(target.input_video);
  } catch (const cv::Exception&) {
  }
  const int w = static_cast<int>(probe.get(cv::CAP_PROP_FRAME_WIDTH));
  const int h = static_cast<int>(probe.get(cv::CAP_PROP_FRAME_HEIGHT));
  if (!probe.isOpened() || w <= 0 || h <= 0) return InvalidField("video", "OpenCV cannot read its frame size");
  return cube::PinholeCamera(w, h, kDefaultHfovDeg);
}

}  // namespace

bool IsCubeArName(std::string_view name) {
  if (name.empty() || name.size() > 128) return false;
  for (unsigned char c : name) {
    if (!std::isalnum(c) && c != '_' && c != '-') return false;
  }
  return true;
}

std::string CubeArTarget::path() const { return kinemo::StrCat(kind, "/", name, ".ar.webm"); }
std::string CubeArTarget::url() const { return kinemo::StrCat("/cube/ar/", kind, "/", name, ".webm"); }

CubeArRenderer::CubeArRenderer(const v1::StudioOptions& options) : cube_dir_(options.cube_dir()) {
  std::error_code ec;
  cube_model_path_ = (fs::path(options.cube_data_dir()) / "vleo.cube").string();
  character_ = (fs::path(options.character_dir()) / kCubeArCharacter).string();
  clip_dir_ = options.cube_ar_clip_dir();
  if (cube_dir_.empty()) {
    off_reason_ = "cube_ar: the studio has no cube_dir";
  } else if (options.character_dir().empty() || !fs::is_regular_file(character_, ec)) {
    off_reason_ = kinemo::StrCat("cube_ar: no ", kCubeArCharacter, " in character_dir");
  } else if (clip_dir_.empty()) {
    off_reason_ = "cube_ar: no action clips (cube_ar_clip_dir)";
  }
  if (!off_reason_.empty()) {
    if (!cube_dir_.empty()) log::Warn("cube_ar_off", {{"reason", off_reason_}});
    return;
  }
  fs::remove_all(fs::path(cube_dir_) / "rendering", ec);
  fs::create_directories(fs::path(cube_dir_) / "rendering", ec);
  worker_ = std::thread([this] { Work(); });
}

CubeArRenderer::~CubeArRenderer() { Shutdown(); }

void CubeArRenderer::Request(const CubeArTarget& target, Done done) {
  if (!off_reason_.empty()) return done(absl::FailedPreconditionError(off_reason_));
  if ((target.kind != "bundled" && target.kind != "uploads") || !IsCubeArName(target.name)) {
    return done(absl::InvalidArgumentError(
        kinemo::StrCat("cube_ar: \"", target.name.substr(0, 64), "\" cannot name an AR video (A-Z a-z 0-9 _ -)")));
  }
  const std::string path = (fs::path(cube_dir_) / target.path()).string();
  std::unique_lock<std::mutex> l(mu_);
  if (stopping_) {
    l.unlock();
    return done(absl::CancelledError("cube_ar: the studio is stopping"));
  }
  CubeArResult kept;
  if (target.kind == "bundled" && ReadSidecar(path, &kept)) {
    l.unlock();
    kept.url = target.url();
    kept.path = path;
    return done(kept);
  }
  if (running_ && running_->target.path() == target.path() && !running_->stop) {
    running_->waiting.push_back(std::move(done));
    return;
  }
  for (const auto& job : queue_) {
    if (job->target.path() == target.path()) {
      job->waiting.push_back(std::move(done));
      return;
    }
  }
  auto job = std::make_shared<Job>();
  job->target = target;
  job->waiting.push_back(std::move(done));
  queue_.push_back(std::move(job));
  cv_.notify_one();
}

void CubeArRenderer::Forget(const CubeArTarget& target) {
  if (!off_reason_.empty() || target.kind.empty()) return;
  std::vector<Done> cancelled;
  {
    std::lock_guard<std::mutex> l(mu_);
    for (auto it = queue_.begin(); it != queue_.end();) {
      if ((*it)->target.path() == target.path()) {
        for (auto& d : (*it)->waiting) cancelled.push_back(std::move(d));
        it = queue_.erase(it);
      } else {
        ++it;
      }
    }
    if (running_ && running_->target.path() == target.path()) {
      running_->stop = true;
      cv_.notify_all();  // a drawing waiting for a live stream to end
    }
    // Under the lock: a drawing that finishes keeps its video only while not
    // stopped (Work), so nothing of it stays.
    std::error_code ec;
    const std::string path = (fs::path(cube_dir_) / target.path()).string();
    fs::remove(path, ec);
    fs::remove(SidecarOf(path), ec);
  }
  for (auto& d : cancelled) d(absl::CancelledError("cube_ar: the video was removed"));
}

void CubeArRenderer::LiveStreamStarted() {
  std::lock_guard<std::mutex> l(mu_);
  ++live_streams_;
}

void CubeArRenderer::LiveStreamEnded() {
  {
    std::lock_guard<std::mutex> l(mu_);
    --live_streams_;
  }
  cv_.notify_all();
}

void CubeArRenderer::Shutdown() {
  std::deque<std::shared_ptr<Job>> queued;
  {
    std::lock_guard<std::mutex> l(mu_);
    stopping_ = true;
    if (running_) running_->stop = true;
    queued.swap(queue_);
  }
  cv_.notify_all();
  for (auto& job : queued) {
    for (auto& d : job->waiting) d(absl::CancelledError("cube_ar: the studio is stopping"));
  }
  if (worker_.joinable()) worker_.join();
}

void CubeArRenderer::Work() {
  // A low priority for this thread only: a waking thread of the live path
  // (the socket's I/O threads, the coordinator, the page) preempts it, and
  // under contention it gets about a tenth of a busy thread's share (nice
  // 19's 1.5 % left a 14 s drawing unfinished after minutes on a machine
  // busy compiling).
  setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), kCubeArNice);
  for (;;) {
    std::shared_ptr<Job> job;
    {
      std::unique_lock<std::mutex> l(mu_);
      cv_.wait(l, [this] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      job = queue_.front();
      queue_.pop_front();
      running_ = job;
    }
    StatusOr<CubeArResult> result = Draw(*job);
    std::vector<Done> waiting;
    {
      std::lock_guard<std::mutex> l(mu_);
      running_.reset();
      waiting.swap(job->waiting);
    }
    for (auto& d : waiting) d(result);
  }
}

StatusOr<CubeArResult> CubeArRenderer::Draw(Job& job) {
  const CubeArTarget& t = job.target;
  const auto started = std::chrono::steady_clock::now();
  const std::string partial = (fs::path(cube_dir_) / "rendering" / (t.kind + "-" + t.name + ".webm")).string();
  const auto fail = [&](const Status& s) -> Status {
    std::error_code ec;
    fs::remove(partial, ec);
    // Stopped (removed, or the studio stops): whatever failed on the way,
    // e.g. the removed upload no longer opening, is not an error of its own.
    if (job.stop) return absl::CancelledError("cube_ar: the video was removed");
    if (s.code() == absl::StatusCode::kCancelled) return s;
    log::Warn("cube_ar_failed", {{"video", t.url()}, {"error", std::string(s.message())}});
    return Annotate(s, "cube_ar");
  };
  auto model = cube::LoadCubeModel(cube_model_path_);
  if (!model.ok()) return fail(Annotate(model.status(), "cube_data_dir"));
  auto camera = CameraFor(t);
  if (!camera.ok()) return fail(Annotate(camera.status(), "camera"));
  auto overlay = cube::ar::MakeArOverlay({.character = character_,
                                          .rig = t.character ? std::shared_ptr<const retarget::Rig>(
                                                                   t.character, &t.character->rig)
                                                             : nullptr,
                                          .action_clips = cube::ar::DefaultActionClips(clip_dir_),
                                          .options = {},
                                          .character_field = "character_dir",
                                          .action_clip_field = "cube_ar_clip_dir"});
  if (!overlay.ok()) return fail(overlay.status());
  double waited_s = 0;  // for live streams
  const auto before_frame = [&]() -> Status {
    std::unique_lock<std::mutex> l(mu_);
    if (live_streams_ > 0 && !job.stop && !stopping_) {
      const auto from = std::chrono::steady_clock::now();
      cv_.wait(l, [&] { return live_streams_ <= 0 || job.stop || stopping_; });
      waited_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - from).count();
    }
    if (job.stop || stopping_) return absl::CancelledError("cube_ar: stopped");
    return absl::OkStatus();
  };
  auto summary = cube::ar::WriteArVideo(
      t.input_video, *model, *camera, *overlay, partial,
      {.max_frames = kMaxCubeArFrames, .max_side_px = kMaxCubeArSidePx, .before_frame = before_frame});
  if (!summary.ok()) return fail(summary.status());
  CubeArResult out;
  out.url = t.url();
  out.path = (fs::path(cube_dir_) / t.path()).string();
  out.frames = summary->frames;
  out.drawn = summary->drawn;
  out.width = summary->width;
  out.height = summary->height;
  out.fps = summary->fps;
  out.render_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count() - waited_s;
  {
    std::lock_guard<std::mutex> l(mu_);
    if (job.stop) return fail(absl::CancelledError("cube_ar: the video was removed"));
    std::error_code ec;
    if (t.kind == "bundled") {
      std::ofstream(SidecarOf(out.path)) << nlohmann::json{{"frames", out.frames}, {"drawn", out.drawn},
                                                           {"width", out.width}, {"height", out.height},
                                                           {"fps", out.fps}, {"render_s", out.render_s}}
                                                .dump();
    }
    fs::rename(partial, out.path, ec);
    if (ec) return fail(absl::InternalError(kinemo::StrCat("cube_dir: cannot keep ", out.path, ": ", ec.message())));
  }
  log::Info("cube_ar_rendered", {{"video", out.url},
                                 {"frames", out.frames},
                                 {"drawn", out.drawn},
                                 {"width", out.width},
                                 {"height", out.height},
                                 {"seconds", out.render_s},
                                 {"waited_for_live_s", waited_s}});
  return out;
}

}  // namespace kinemo::studio
