// A cube attached to a session (AttachCube): the cube tracker's TrackSource
// stream drives the session's Vleo. Every answer's events become the
// session's actions and cube status (SessionManager); a stream that breaks
// (UNAVAILABLE, DEADLINE_EXCEEDED, CANCELLED) is reopened from the next frame
// after a backoff that doubles up to max_backoff_s; a source that ends, or a
// tracker that refuses it, detaches the cube saying why. Plain C++: the
// stream itself is a CubeFeed the adapter opens over gRPC.
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "common/status/status.h"
#include "kinemo/common/v1/vleo.pb.h"
#include "kinemo/cube_tracker/v1/cube_tracker.pb.h"
#include "services/coordinator/core/session_manager.h"

namespace kinemo::coordinator {

// One TrackSource stream of the cube tracker.
class CubeFeed {
 public:
  virtual ~CubeFeed() = default;
  // The next answer; false at the stream's end.
  virtual bool Read(cube_tracker::v1::TrackResponse* response) = 0;
  // After Read returned false: how the stream ended.
  virtual Status Finish() = 0;
  // The stream was ended for want of a frame (deadlines.stream_idle_s).
  virtual bool idle_expired() const = 0;
  // Ends the stream from another thread (Read then returns false).
  virtual void Cancel() = 0;
};
// Opens a stream for a request (its source starting at the frame to resume from).
using OpenCubeFeed = std::function<std::unique_ptr<CubeFeed>(const cube_tracker::v1::TrackSourceRequest&)>;

class CubeAttachment {
 public:
  // With `confirm`, the stream's first answer is held until Go(): AttachCube
  // waits for it (WaitFirst) to answer the tracker's error up front, and
  // records the attachment before any of the cube's actions apply.
  // `idle_s` names the idle timeout in the error of a stream that expired.
  CubeAttachment(std::string session_id, cube_tracker::v1::TrackSourceRequest request, OpenCubeFeed open,
                 SessionManager* manager, double max_backoff_s, bool confirm, double idle_s);
  ~CubeAttachment() { Stop(); }
  CubeAttachment(const CubeAttachment&) = delete;
  CubeAttachment& operator=(const CubeAttachment&) = delete;
  // Ends the stream and the thread (idempotent).
  void Stop();
  // The first answer of the tracker: OK once a frame was tracked (or the
  // source ended at once), the tracker's error (e.g. NOT_FOUND naming
  // source.video_file), or UNAVAILABLE if it did not answer before `deadline`.
  Status WaitFirst(std::chrono::system_clock::time_point deadline);
  // The tracker's state after the first frame (after WaitFirst answered OK;
  // null if its first answer carried none).
  const cube_tracker::v1::CubeState* first_state() const { return has_first_state_ ? &first_state_ : nullptr; }
  // The held first answer applies, and the stream runs on.
  void Go();

 private:
  // Applies one answer of the tracker; false once the session is gone.
  bool Apply(const cube_tracker::v1::TrackResponse& resp, common::v1::Action* action, bool* visible);
  void Run();
  // The stream's end: retried, or detached (false).
  bool Retry(const Status& s);

  const std::string session_id_;
  const cube_tracker::v1::TrackSourceRequest request_;
  const OpenCubeFeed open_;
  SessionManager* manager_;
  const double max_backoff_s_;
  const double idle_s_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool stopping_ = false;
  bool go_;
  bool first_done_ = false;
  bool has_first_state_ = false;
  cube_tracker::v1::CubeState first_state_;
  Status first_status_;
  CubeFeed* feed_ = nullptr;  // the stream open now (under mu_)
  std::thread thread_;
};

}  // namespace kinemo::coordinator
