#include "services/coordinator/core/cube_attachment.h"

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "common/logging/log.h"

namespace kinemo::coordinator {

namespace ct = ::kinemo::cube_tracker::v1;

CubeAttachment::CubeAttachment(std::string session_id, ct::TrackSourceRequest request, OpenCubeFeed open,
                               SessionManager* manager, double max_backoff_s, bool confirm, double idle_s)
    : session_id_(std::move(session_id)),
      request_(std::move(request)),
      open_(std::move(open)),
      manager_(manager),
      max_backoff_s_(max_backoff_s),
      idle_s_(idle_s),
      go_(!confirm) {
  thread_ = std::thread([this] { Run(); });
}

void CubeAttachment::Stop() {
  {
    std::lock_guard<std::mutex> l(mu_);
    stopping_ = true;
    if (feed_ != nullptr) feed_->Cancel();
  }
  cv_.notify_all();
  if (thread_.joinable() && thread_.get_id() != std::this_thread::get_id()) thread_.join();
}

Status CubeAttachment::WaitFirst(std::chrono::system_clock::time_point deadline) {
  std::unique_lock<std::mutex> l(mu_);
  if (!cv_.wait_until(l, deadline, [&] { return first_done_; })) {
    return absl::UnavailableError("cube_tracker: no answer to TrackSource before the deadline");
  }
  return first_status_;
}

void CubeAttachment::Go() {
  {
    std::lock_guard<std::mutex> l(mu_);
    go_ = true;
  }
  cv_.notify_all();
}

bool CubeAttachment::Apply(const ct::TrackResponse& resp, common::v1::Action* action, bool* visible) {
  for (const ct::CubeEvent& e : resp.events()) {
    absl::StatusCode code = absl::StatusCode::kOk;
    if (e.has_action_launched()) {
      *action = e.action_launched().action();
      code = manager_->Act(session_id_, *action, std::clamp(e.action_launched().intensity(), -1.0, 1.0), true)
                 .status()
                 .code();
    } else if (e.has_intensity_changed()) {
      code = manager_->Act(session_id_, *action, std::clamp(e.intensity_changed().to_intensity(), -1.0, 1.0), true)
                 .status()
                 .code();
    } else if (e.has_lost() || e.has_found()) {
      *visible = e.has_found();
      code = manager_->SetCubeVisible(session_id_, *visible, e).code();
    } else if (e.has_face_changed()) {
      // Watchers see the top face (the studio's cube panel); the action it
      // launches follows as its own event.
      *visible = true;
      code = manager_->SetCubeVisible(session_id_, true, e).code();
    }
    if (code == absl::StatusCode::kNotFound) return false;  // the session closed
  }
  return true;
}

void CubeAttachment::Run() {
  double backoff_s = 0.05;
  common::v1::Action action = common::v1::ACTION_IDLE;
  std::uint64_t next_frame = request_.source().start_frame();
  bool visible = false;
  bool first_attempt = true;
  while (true) {
    {
      std::lock_guard<std::mutex> l(mu_);
      if (stopping_) return;
    }
    ct::TrackSourceRequest req = request_;
    req.mutable_source()->set_start_frame(next_frame);
    std::unique_ptr<CubeFeed> feed = open_(req);
    auto forget = [&] {  // the feed is not cancelled once it goes
      std::lock_guard<std::mutex> l(mu_);
      feed_ = nullptr;
      return stopping_;
    };
    {
      std::lock_guard<std::mutex> l(mu_);
      feed_ = feed.get();
      if (stopping_) feed->Cancel();  // Stop came while it opened
    }
    ct::TrackResponse resp;
    bool more = feed->Read(&resp);
    Status s;
    if (!more) s = feed->Finish();
    if (first_attempt) {
      first_attempt = false;
      std::unique_lock<std::mutex> l(mu_);
      if (!go_) {
        first_done_ = true;
        first_status_ = s;
        has_first_state_ = more && resp.has_state();
        if (has_first_state_) first_state_ = resp.state();
        cv_.notify_all();
        cv_.wait(l, [&] { return go_ || stopping_; });
        if (!s.ok() || stopping_) {
          feed_ = nullptr;
          return;  // AttachCube answered the error (or gave up)
        }
      }
    }
    while (more) {
      backoff_s = 0.05;
      if (resp.has_state()) next_frame = resp.state().frame() + 1;
      if (!Apply(resp, &action, &visible)) {
        feed->Cancel();
        (void)feed->Finish();
        forget();
        return;
      }
      more = feed->Read(&resp);
      if (!more) s = feed->Finish();
    }
    if (feed->idle_expired()) {
      s = absl::DeadlineExceededError(
          absl::StrCat("cube_tracker: no frame for ", idle_s_, " s (deadlines.stream_idle_s)"));
    }
    if (forget()) return;
    feed.reset();
    if (!Retry(s)) return;
    std::unique_lock<std::mutex> l(mu_);
    cv_.wait_for(l, std::chrono::duration<double>(backoff_s), [&] { return stopping_; });
    backoff_s = std::min(backoff_s * 2, max_backoff_s_);
  }
}

bool CubeAttachment::Retry(const Status& s) {
  if (absl::IsUnavailable(s) || absl::IsDeadlineExceeded(s) || absl::IsCancelled(s)) return true;
  // The source ended (OK) or the tracker refused it: detach, saying why.
  std::string reason = "source ended";
  if (!s.ok()) {
    reason = absl::StrCat(absl::StatusCodeToString(s.code()), ": ", s.message());
    log::Warn("cube_stream_failed", {{"session_id", session_id_}, {"error", reason}});
  }
  if (auto d = manager_->DetachCube(session_id_, reason); !d.ok() && d.status().code() != absl::StatusCode::kNotFound) {
    log::Warn("cube_detach_failed", {{"session_id", session_id_}, {"error", std::string(d.status().message())}});
  }
  return false;
}

}  // namespace kinemo::coordinator
