#include "services/coordinator/robot_relay.h"

#include <algorithm>
#include <chrono>

#include "common/grpc/status_mapping.h"
#include "common/logging/log.h"

namespace kinemo::coordinator {

namespace rb = ::kinemo::robot_bridge::v1;

struct RobotRelay::Worker {
  std::string robot_id;
  std::mutex mu;
  std::condition_variable cv;
  bool stopping = false;
  bool has_desired = false;
  RobotCommand desired;
  std::uint64_t desired_version = 0;
  std::uint64_t sent_version = 0;   // last version acknowledged (or refused for good)
  bool force_resend = false;
  double last_sent_s = -1e9;
  double mismatch_since_s = -1;     // robot shows another emotion since
  grpc::ClientContext* watch_context = nullptr;
  std::thread command_thread;
  std::thread watch_thread;
};

RobotRelay::RobotRelay(std::shared_ptr<grpc::Channel> channel, const RobotRelayOptions& options,
                       const Clock* clock)
    : channel_(std::move(channel)),
      stub_(rb::RobotBridgeService::NewStub(channel_)),
      options_(options),
      clock_(clock) {}

RobotRelay::~RobotRelay() { Stop(); }

void RobotRelay::Stop() {
  std::map<std::string, std::unique_ptr<Worker>> workers;
  {
    std::lock_guard<std::mutex> l(mu_);
    stopping_ = true;
    workers.swap(workers_);
  }
  for (auto& [id, w] : workers) {
    {
      std::lock_guard<std::mutex> l(w->mu);
      w->stopping = true;
      if (w->watch_context != nullptr) w->watch_context->TryCancel();
    }
    w->cv.notify_all();
  }
  for (auto& [id, w] : workers) {
    if (w->command_thread.joinable()) w->command_thread.join();
    if (w->watch_thread.joinable()) w->watch_thread.join();
  }
}

void RobotRelay::Command(const RobotCommand& command) {
  Worker* w = nullptr;
  // A closed session without reset_robot: nothing to send.
  const bool send = !command.release || command.emotion != common::v1::EMOTION_UNSPECIFIED;
  {
    std::lock_guard<std::mutex> l(mu_);
    if (stopping_) return;
    auto it = workers_.find(command.robot_id);
    if (it == workers_.end() && !send) return;
    if (it == workers_.end()) {
      auto nw = std::make_unique<Worker>();
      nw->robot_id = command.robot_id;
      w = nw.get();
      workers_.emplace(command.robot_id, std::move(nw));
      std::lock_guard<std::mutex> wl(w->mu);
      w->desired = command;
      w->has_desired = true;
      w->desired_version = 1;
      w->command_thread = std::thread([this, w] { CommandLoop(w); });
      w->watch_thread = std::thread([this, w] { WatchLoop(w); });
      return;
    }
    w = it->second.get();
  }
  {
    std::lock_guard<std::mutex> l(w->mu);
    if (!send) {
      // The closed session's emotion is no longer the robot's: stop
      // re-sending it (a newer session, if any, commands the robot next).
      if (w->has_desired && w->desired.session_id == command.session_id) {
        w->has_desired = false;
        w->force_resend = false;
      }
      return;
    }
    w->desired = command;
    w->has_desired = true;
    ++w->desired_version;
  }
  w->cv.notify_all();
}

void RobotRelay::CommandLoop(Worker* w) {
  double backoff_s = 0.02;
  std::uint64_t failed_version = 0;  // version whose failure was reported
  std::unique_lock<std::mutex> l(w->mu);
  while (!w->stopping) {
    if (!(w->has_desired && (w->desired_version != w->sent_version || w->force_resend))) {
      w->cv.wait(l);
      continue;
    }
    const RobotCommand cmd = w->desired;
    const std::uint64_t version = w->desired_version;
    w->force_resend = false;
    l.unlock();

    rb::SetEmotionRequest req;
    req.set_robot_id(cmd.robot_id);
    req.set_emotion(cmd.emotion);
    req.set_intensity(std::clamp(cmd.intensity, 0.0, 1.0));
    req.set_request_id(cmd.session_id);
    rb::SetEmotionResponse resp;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() +
                     std::chrono::microseconds(static_cast<long>(options_.deadline_s * 1e6)));
    const grpc::Status s = stub_->SetEmotion(&ctx, req, &resp);
    const double now = clock_->MonotonicS();

    // Report without holding the worker's lock (the manager calls Command
    // with its own lock held).
    const bool permanent = s.error_code() == grpc::StatusCode::NOT_FOUND ||
                           s.error_code() == grpc::StatusCode::INVALID_ARGUMENT;
    if (manager_ != nullptr && (s.ok() || failed_version != version)) {
      manager_->OnRobotCommanded(
          cmd.session_id, cmd.emotion, s.ok() ? resp.sequence_number() : 0,
          s.ok() ? std::string() : std::string(FromGrpcStatus(s, "robot_bridge").message()),
          (now - cmd.trigger_time_s) * 1e3);
    }
    l.lock();
    w->last_sent_s = now;
    if (s.ok()) {
      if (w->desired_version == version) w->sent_version = version;
      backoff_s = 0.02;
      failed_version = 0;
      continue;
    }
    failed_version = version;
    if (permanent) {
      // The bridge refuses this robot: wait for a newer command, or the
      // resend period (the bridge's configuration may change).
      if (w->desired_version == version) w->sent_version = version;
      continue;
    }
    // Transient: back off (a newer command or a stop wakes us early).
    w->cv.wait_for(l, std::chrono::duration<double>(backoff_s),
                   [&] { return w->stopping || w->desired_version != version; });
    backoff_s = std::min(backoff_s * 2, options_.max_backoff_s);
  }
}

void RobotRelay::WatchLoop(Worker* w) {
  double backoff_s = 0.02;
  bool reported_connected = false;
  while (true) {
    grpc::ClientContext ctx;
    {
      std::lock_guard<std::mutex> l(w->mu);
      if (w->stopping) return;
      w->watch_context = &ctx;
    }
    rb::WatchStatusRequest req;
    req.set_robot_id(w->robot_id);
    auto reader = stub_->WatchStatus(&ctx, req);
    IdleGuard idle(options_.watchdog, &ctx, options_.stream_idle_s);
    rb::RobotStatus st;
    bool got_any = false;
    while (reader->Read(&st)) {
      idle.Touch();
      got_any = true;
      backoff_s = 0.02;
      const double now = clock_->MonotonicS();
      if (manager_ != nullptr) {
        manager_->OnRobotStatus(w->robot_id, st.connected(), st.shown_emotion(),
                                st.battery_percent());
      }
      reported_connected = st.connected();
      bool wake = false;
      {
        std::lock_guard<std::mutex> l(w->mu);
        // A release (reset_robot of a closed session) is sent once, never
        // re-sent: the robot is free for other clients.
        if (w->has_desired && !w->desired.release && w->sent_version == w->desired_version) {
          // The bridge lost our command (restarted) or holds another one.
          if (st.commanded_emotion() != w->desired.emotion &&
              now - w->last_sent_s >= std::min(options_.resend_s, 0.2)) {
            w->force_resend = true;
            wake = true;
          }
          // The robot shows another emotion for longer than resend_s.
          if (st.connected() && st.shown_emotion() != w->desired.emotion &&
              st.state() != rb::ROBOT_STATE_SWITCHING) {
            if (w->mismatch_since_s < 0) w->mismatch_since_s = now;
            if (now - w->mismatch_since_s >= options_.resend_s &&
                now - w->last_sent_s >= options_.resend_s) {
              w->force_resend = true;
              wake = true;
              w->mismatch_since_s = now;
            }
          } else {
            w->mismatch_since_s = -1;
          }
        }
      }
      if (wake) w->cv.notify_all();
    }
    grpc::Status s = reader->Finish();
    if (idle.expired()) {
      s = grpc::Status(grpc::StatusCode::DEADLINE_EXCEEDED,
                       "robot_bridge: no status for stream_idle_s (deadlines.stream_idle_s)");
    }
    {
      std::lock_guard<std::mutex> l(w->mu);
      w->watch_context = nullptr;
      if (w->stopping) return;
    }
    if (reported_connected && manager_ != nullptr) {
      manager_->OnRobotStatus(w->robot_id, false, common::v1::EMOTION_UNSPECIFIED, 0);
      reported_connected = false;
    }
    if (!got_any) {
      log::Debug("robot_watch_failed",
                 {{"robot_id", w->robot_id}, {"error", s.error_message()}});
    }
    std::unique_lock<std::mutex> l(w->mu);
    w->cv.wait_for(l, std::chrono::duration<double>(backoff_s), [&] { return w->stopping; });
    backoff_s = std::min(backoff_s * 2, options_.max_backoff_s);
    // Whatever the bridge held may be gone: re-send on the next connection.
    if (w->has_desired && !w->desired.release) w->force_resend = true;
    w->cv.notify_all();
  }
}

}  // namespace kinemo::coordinator
