// Vleo-Pleo sessions: each pairs a Vleo (a client calling Act, or a cube)
// with a robot and runs one EmotionModel. The manager publishes every change
// as a SessionEvent to its subscribers (WatchSession), and hands each emotion
// change to a RobotSink (the relay to the robot bridge). Plain C++: no gRPC.
//
// With a SessionStore, every change a client is told about (Open, Act, Close,
// cube attach / detach) is committed to the store before the call returns
// OK, and Restore() brings the stored sessions back at start; a store error
// fails the call and changes nothing. Emotion changes that follow from the
// stored state (threshold crossings) are not written: the model recomputes
// them.
//
// Thread-safe. Subscribers and the sink are called with the manager's lock
// held: they must only enqueue, never call back into the manager.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "common/status/status.h"
#include "kinemo/coordinator/v1/coordinator.pb.h"
#include "services/coordinator/core/clock.h"
#include "services/coordinator/core/emotion_model.h"
#include "services/coordinator/core/session_store.h"

namespace kinemo::coordinator {

// An emotion the robot of a session should show.
struct RobotCommand {
  std::string session_id;
  std::string robot_id;
  Emotion emotion = common::v1::EMOTION_NEUTRAL;
  double intensity = 1.0;      // in [0, 1]
  double trigger_time_s = 0;   // monotonic time of the event that caused it
  // The session closed: the relay stops re-sending its emotion. `emotion`
  // is NEUTRAL to reset the robot once (reset_robot), UNSPECIFIED otherwise.
  bool release = false;
};

// A cube attachment brought back by Restore, to re-subscribe.
struct RestoredCube {
  std::string session_id;
  cube_tracker::v1::VideoSource source;
  cube_tracker::v1::TrackConfig config;
};

struct SessionManagerOptions {
  EmotionParams emotion;
  std::uint32_t max_sessions = 10000;
  bool exclusive_robots = false;
  // Sessions with no Act, cube event or watcher for this long are closed by
  // Tick (reason "idle"), in seconds; 0 = never.
  double idle_timeout_s = 0;
};

class SessionManager {
 public:
  using EventCallback = std::function<void(const v1::SessionEvent&)>;
  using RobotSink = std::function<void(const RobotCommand&)>;

  // `clock` (and `store`, if not null) must outlive the manager. `sink` may
  // be empty (no robot relay); `store` null = sessions in memory only.
  SessionManager(const SessionManagerOptions& options, const Clock* clock, RobotSink sink,
                 SessionStore* store = nullptr);

  // Loads the store's sessions (call once, before serving): each session's
  // model is advanced over the time since it was stored (wall clock), and
  // its robot is commanded the resulting emotion. Returns the cube
  // attachments to re-subscribe. Errors from the store.
  StatusOr<std::vector<RestoredCube>> Restore();
  bool persistent() const { return store_ != nullptr; }

  // Opens a session; the robot is commanded the initial emotion.
  // INVALID_ARGUMENT for a bad id / empty robot_id / unknown enum values,
  // ALREADY_EXISTS for an id in use (or an exclusive robot in use),
  // RESOURCE_EXHAUSTED past max_sessions.
  StatusOr<v1::Session> Open(const v1::OpenSessionRequest& request);
  // Closes a session (last event SessionClosed{reason}); with reset_robot the
  // robot is commanded neutral.
  StatusOr<v1::Session> Close(const std::string& session_id, bool reset_robot,
                              const std::string& reason);
  // Applies an action (advancing the model to now first). `from_cube`: the
  // attached cube's intensity is now `intensity` (Session.cube_intensity).
  StatusOr<v1::Session> Act(const std::string& session_id, Action action, double intensity,
                            bool from_cube);
  StatusOr<v1::Session> Get(const std::string& session_id);
  // Sessions in opening order; only those of `robot_id` if not empty.
  std::vector<v1::Session> List(const std::string& robot_id);
  std::size_t size() const;

  // Advances every session to now, publishing emotion changes at their exact
  // crossing times; closes idle sessions (options.idle_timeout_s) and
  // returns their ids.
  std::vector<std::string> Tick();
  // Monotonic time of the next emotion change of any session (+infinity if
  // none is coming).
  double NextChangeTime() const;

  // Attaches a cube (stored with its source and config; the session's Vleo
  // becomes CUBE). `first`, if not null, is the tracker's state after the
  // first frame: its visibility, top face and intensity become the
  // session's cube fields and go with the CubeStatusChanged event (so a
  // watcher sees the face before the cube is first turned).
  StatusOr<v1::Session> AttachCube(const std::string& session_id,
                                   const cube_tracker::v1::VideoSource& source,
                                   const cube_tracker::v1::TrackConfig& config,
                                   const cube_tracker::v1::CubeState* first = nullptr);
  // Detaches the session's cube, if any (stored); `reason` goes to the
  // CubeStatusChanged event (empty for DetachCube).
  StatusOr<v1::Session> DetachCube(const std::string& session_id, const std::string& reason);
  // The attached cube was seen / lost, or turned onto another face (`event`
  // says which; not stored). Found and FaceChanged set the session's
  // cube_face (FaceChanged resets cube_intensity to 0, as the tracker does).
  Status SetCubeVisible(const std::string& session_id, bool visible,
                        const cube_tracker::v1::CubeEvent& event);
  // The relay reports on a command it sent for a session.
  void OnRobotCommanded(const std::string& session_id, Emotion emotion, std::uint32_t sequence,
                        const std::string& error, double latency_ms);
  // The relay reports a robot's status (every session paired with it).
  void OnRobotStatus(const std::string& robot_id, bool connected, Emotion shown,
                     double battery_percent);
  // The emotion every open session of `robot_id` wants, newest session first
  // (for re-sending after a restart). Empty if no session has that robot.
  std::vector<RobotCommand> DesiredCommands(const std::string& robot_id);

  // Subscribes to one session ("" = all, present and future). The current
  // state (a snapshot per session) is delivered first, before Subscribe
  // returns. NOT_FOUND for an unknown session.
  StatusOr<std::uint64_t> Subscribe(const std::string& session_id, EventCallback callback);
  void Unsubscribe(std::uint64_t id);

  // Closes every session with reason "shutdown" (a coordinator without a
  // store; with one, sessions stay stored for the next start).
  void CloseAll();

 private:
  struct Session {
    v1::Session info;  // static fields + robot-side fields
    EmotionModel model;
    double open_time_s;
    std::int64_t open_wall_ns;
    std::uint64_t order;
    double last_activity_s;
    std::uint64_t acts = 0;
    std::string cube_source;  // serialized VideoSource; empty = no cube
    std::string cube_config;  // serialized TrackConfig
    Emotion robot_emotion = common::v1::EMOTION_UNSPECIFIED;  // last acknowledged command
    std::uint32_t robot_sequence = 0;
  };
  struct Subscriber {
    std::string session_id;
    EventCallback callback;
  };

  v1::Session SnapshotLocked(const Session& s, double now_s) const;
  v1::SessionEvent NewEventLocked(const Session& s, double time_s) const;
  void PublishLocked(const v1::SessionEvent& event);
  // Advances one session, publishing its emotion changes and commanding the robot.
  void AdvanceLocked(Session& s, double now_s);
  void PublishChangesLocked(Session& s, const std::vector<EmotionChange>& changes);
  void CommandLocked(const Session& s, Emotion emotion, double trigger_s);
  StatusOr<Session*> FindLocked(const std::string& session_id);
  bool WatchedLocked(const std::string& session_id) const;
  void CloseLocked(Session& s, bool reset_robot, const std::string& reason, double now_s);
  // After a session of `robot_id` closed: the newest other session of that
  // robot (if any) commands it again.
  void HandOverLocked(const std::string& robot_id, double now_s);
  // Writes a session (with `model` as its model) to the store; OK without one.
  Status PersistLocked(const Session& s, const EmotionModel& model, double now_s);
  void PublishCubeLocked(const Session& s, bool attached, bool visible,
                         const cube_tracker::v1::CubeEvent* event, const std::string& reason);

  const SessionManagerOptions options_;
  const Clock* clock_;
  RobotSink sink_;
  SessionStore* store_;
  mutable std::mutex mu_;
  std::map<std::string, std::unique_ptr<Session>> sessions_;
  std::map<std::uint64_t, Subscriber> subscribers_;
  std::uint64_t next_subscriber_ = 1;
  std::uint64_t next_order_ = 1;
  std::uint64_t next_generated_id_ = 1;
};

// Session id rule: [a-z0-9_-]{1,64}.
bool ValidSessionId(const std::string& id);

}  // namespace kinemo::coordinator
