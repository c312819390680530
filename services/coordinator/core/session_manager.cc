#include "services/coordinator/core/session_manager.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/logging/log.h"

namespace kinemo::coordinator {
namespace {

void SetTimestamp(std::int64_t unix_ns, google::protobuf::Timestamp* ts) {
  ts->set_seconds(unix_ns / 1'000'000'000);
  ts->set_nanos(static_cast<std::int32_t>(unix_ns % 1'000'000'000));
}

bool ValidEmotion(Emotion e) {
  return e == common::v1::EMOTION_UNSPECIFIED || e == common::v1::EMOTION_NEUTRAL ||
         e == common::v1::EMOTION_HAPPY || e == common::v1::EMOTION_ANGRY;
}

}  // namespace

bool ValidSessionId(const std::string& id) {
  if (id.empty() || id.size() > 64) return false;
  return std::all_of(id.begin(), id.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '-';
  });
}

SessionManager::SessionManager(const SessionManagerOptions& options, const Clock* clock,
                               RobotSink sink, SessionStore* store)
    : options_(options), clock_(clock), sink_(std::move(sink)), store_(store) {}

Status SessionManager::PersistLocked(const Session& s, const EmotionModel& model, double now_s) {
  if (store_ == nullptr) return absl::OkStatus();
  StoredSession st;
  st.session_id = s.info.session_id();
  st.robot_id = s.info.robot_id();
  st.vleo = s.info.vleo();
  st.vleo_name = s.info.vleo_name();
  st.open_wall_ns = s.open_wall_ns;
  st.order = s.order;
  st.valence = model.valence();
  st.emotion = model.emotion();
  st.action = model.action();
  st.intensity = model.intensity();
  // The model's own time, on the wall clock.
  st.model_wall_ns = clock_->WallUnixNs() - std::llround((now_s - model.time_s()) * 1e9);
  st.acts = s.acts;
  st.cube_source = s.cube_source;
  st.cube_config = s.cube_config;
  st.robot_emotion = s.robot_emotion;
  st.robot_sequence = s.robot_sequence;
  return store_->Put(st);
}

StatusOr<std::vector<RestoredCube>> SessionManager::Restore() {
  std::vector<RestoredCube> cubes;
  if (store_ == nullptr) return cubes;
  KINEMO_ASSIGN_OR_RETURN(std::vector<StoredSession> stored, store_->LoadAll());
  std::lock_guard<std::mutex> l(mu_);
  const double now = clock_->MonotonicS();
  const std::int64_t now_wall = clock_->WallUnixNs();
  // Monotonic time of a stored wall-clock time (never in the future: a wall
  // clock set back leaves the model where it was stored).
  auto monotonic_of = [&](std::int64_t wall_ns) {
    return now - std::max<std::int64_t>(0, now_wall - wall_ns) / 1e9;
  };
  for (const StoredSession& st : stored) {
    if (!ValidSessionId(st.session_id) || st.robot_id.empty() || sessions_.count(st.session_id)) {
      log::Warn("session_not_restored", {{"session_id", st.session_id}, {"why", "invalid record"}});
      continue;
    }
    const Emotion emotion = static_cast<Emotion>(st.emotion);
    const Action action = static_cast<Action>(st.action);
    auto s = std::make_unique<Session>(Session{
        v1::Session{},
        EmotionModel::Restore(options_.emotion, common::v1::Emotion_IsValid(emotion) ? emotion
                                                                                    : common::v1::EMOTION_NEUTRAL,
                              st.valence, common::v1::Action_IsValid(action) ? action : common::v1::ACTION_IDLE,
                              st.intensity, monotonic_of(st.model_wall_ns)),
        monotonic_of(st.open_wall_ns), st.open_wall_ns, st.order, now});
    s->acts = st.acts;
    s->cube_source = st.cube_source;
    s->cube_config = st.cube_config;
    s->robot_emotion = static_cast<Emotion>(st.robot_emotion);
    s->robot_sequence = st.robot_sequence;
    s->info.set_session_id(st.session_id);
    s->info.set_robot_id(st.robot_id);
    s->info.set_vleo(v1::VleoKind_IsValid(st.vleo) ? static_cast<v1::VleoKind>(st.vleo)
                                                   : v1::VLEO_KIND_CLIENT);
    s->info.set_vleo_name(st.vleo_name);
    next_order_ = std::max(next_order_, st.order + 1);
    RestoredCube cube;
    if (!st.cube_source.empty()) {
      if (cube.source.ParseFromString(st.cube_source) && cube.config.ParseFromString(st.cube_config)) {
        s->info.set_cube_attached(true);
        cube.session_id = st.session_id;
        cubes.push_back(std::move(cube));
      } else {
        s->cube_source.clear();
        s->cube_config.clear();
      }
    }
    Session& ref = *s;
    sessions_.emplace(st.session_id, std::move(s));
    // Over the downtime, as the model's rules say; then the robot is told.
    std::vector<EmotionChange> changes;
    ref.model.AdvanceTo(now, &changes);
    CommandLocked(ref, ref.model.emotion(), now);
    log::Info("session_restored", {{"session_id", st.session_id},
                                   {"robot_id", st.robot_id},
                                   {"valence", ref.model.valence()},
                                   {"emotion", common::v1::Emotion_Name(ref.model.emotion())},
                                   {"acts", static_cast<std::int64_t>(st.acts)},
                                   {"cube", !ref.cube_source.empty()}});
  }
  return cubes;
}

StatusOr<SessionManager::Session*> SessionManager::FindLocked(const std::string& session_id) {
  auto it = sessions_.find(session_id);
  if (it == sessions_.end()) {
    return absl::NotFoundError(absl::StrCat("session_id: no open session \"", session_id, "\""));
  }
  return it->second.get();
}

v1::Session SessionManager::SnapshotLocked(const Session& s, double now_s) const {
  v1::Session out = s.info;
  out.set_action(s.model.action());
  out.set_intensity(s.model.intensity());
  out.set_valence(s.model.valence());
  out.set_emotion(s.model.emotion());
  SetTimestamp(s.open_wall_ns, out.mutable_open_time());
  out.set_session_time_s(std::max(0.0, now_s - s.open_time_s));
  return out;
}

v1::SessionEvent SessionManager::NewEventLocked(const Session& s, double time_s) const {
  v1::SessionEvent e;
  e.set_session_id(s.info.session_id());
  const double since_open = std::max(0.0, time_s - s.open_time_s);
  SetTimestamp(s.open_wall_ns + static_cast<std::int64_t>(std::llround(since_open * 1e9)),
               e.mutable_event_time());
  e.set_session_time_s(since_open);
  return e;
}

void SessionManager::PublishLocked(const v1::SessionEvent& event) {
  for (auto& [id, sub] : subscribers_) {
    if (sub.session_id.empty() || sub.session_id == event.session_id()) sub.callback(event);
  }
}

void SessionManager::CommandLocked(const Session& s, Emotion emotion, double trigger_s) {
  if (!sink_) return;
  RobotCommand c;
  c.session_id = s.info.session_id();
  c.robot_id = s.info.robot_id();
  c.emotion = emotion;
  c.intensity = s.model.RobotIntensity();
  c.trigger_time_s = trigger_s;
  sink_(c);
}

void SessionManager::PublishChangesLocked(Session& s, const std::vector<EmotionChange>& changes) {
  for (const EmotionChange& c : changes) {
    v1::SessionEvent e = NewEventLocked(s, c.time_s);
    auto* ec = e.mutable_emotion_changed();
    ec->set_from_emotion(c.from);
    ec->set_to_emotion(c.to);
    ec->set_valence(c.valence);
    ec->set_action(c.action);
    ec->set_intensity(c.intensity);
    PublishLocked(e);
  }
  if (!changes.empty()) CommandLocked(s, changes.back().to, changes.back().time_s);
}

void SessionManager::AdvanceLocked(Session& s, double now_s) {
  std::vector<EmotionChange> changes;
  s.model.AdvanceTo(now_s, &changes);
  PublishChangesLocked(s, changes);
}

StatusOr<v1::Session> SessionManager::Open(const v1::OpenSessionRequest& r) {
  if (r.robot_id().empty()) return absl::InvalidArgumentError("robot_id: must not be empty");
  if (r.robot_id().size() > 64) return absl::InvalidArgumentError("robot_id: longer than 64");
  if (!v1::VleoKind_IsValid(r.vleo())) {
    return absl::InvalidArgumentError(absl::StrCat("vleo: unknown value ", r.vleo()));
  }
  if (!ValidEmotion(r.initial_emotion())) {
    return absl::InvalidArgumentError(
        absl::StrCat("initial_emotion: unknown value ", r.initial_emotion()));
  }
  if (!r.session_id().empty() && !ValidSessionId(r.session_id())) {
    return absl::InvalidArgumentError(
        absl::StrCat("session_id: must match [a-z0-9_-]{1,64}, got \"", r.session_id(), "\""));
  }
  std::lock_guard<std::mutex> l(mu_);
  if (sessions_.size() >= options_.max_sessions) {
    return absl::ResourceExhaustedError(
        absl::StrCat("OpenSession: ", options_.max_sessions, " sessions open (max_sessions)"));
  }
  std::string id = r.session_id();
  if (id.empty()) {
    do {
      id = absl::StrCat("s", next_generated_id_++);
    } while (sessions_.count(id) != 0);
  } else if (sessions_.count(id) != 0) {
    return absl::AlreadyExistsError(absl::StrCat("session_id: \"", id, "\" is open"));
  }
  if (options_.exclusive_robots) {
    for (const auto& [sid, s] : sessions_) {
      if (s->info.robot_id() == r.robot_id()) {
        return absl::AlreadyExistsError(absl::StrCat(
            "robot_id: \"", r.robot_id(), "\" is paired with session \"", sid, "\""));
      }
    }
  }
  const double now = clock_->MonotonicS();
  auto s = std::make_unique<Session>(Session{
      v1::Session{}, EmotionModel(options_.emotion, r.initial_emotion(), now), now,
      clock_->WallUnixNs(), next_order_++, now});
  s->info.set_session_id(id);
  s->info.set_robot_id(r.robot_id());
  s->info.set_vleo(r.vleo() == v1::VLEO_KIND_UNSPECIFIED ? v1::VLEO_KIND_CLIENT : r.vleo());
  s->info.set_vleo_name(r.vleo_name());
  KINEMO_RETURN_IF_ERROR(PersistLocked(*s, s->model, now));
  Session& ref = *s;
  sessions_.emplace(id, std::move(s));
  v1::Session snap = SnapshotLocked(ref, now);
  v1::SessionEvent e = NewEventLocked(ref, now);
  *e.mutable_snapshot() = snap;
  PublishLocked(e);
  CommandLocked(ref, ref.model.emotion(), now);
  return snap;
}

void SessionManager::CloseLocked(Session& s, bool reset_robot, const std::string& reason,
                                 double now_s) {
  if (sink_) {
    RobotCommand c;
    c.session_id = s.info.session_id();
    c.robot_id = s.info.robot_id();
    c.emotion = reset_robot ? common::v1::EMOTION_NEUTRAL : common::v1::EMOTION_UNSPECIFIED;
    c.trigger_time_s = now_s;
    c.release = true;
    sink_(c);
  }
  v1::SessionEvent e = NewEventLocked(s, now_s);
  e.mutable_session_closed()->set_reason(reason);
  PublishLocked(e);
}

void SessionManager::HandOverLocked(const std::string& robot_id, double now_s) {
  Session* newest = nullptr;
  for (auto& [id, s] : sessions_) {
    if (s->info.robot_id() == robot_id && (newest == nullptr || s->order > newest->order)) {
      newest = s.get();
    }
  }
  if (newest != nullptr) CommandLocked(*newest, newest->model.emotion(), now_s);
}

StatusOr<v1::Session> SessionManager::Close(const std::string& session_id, bool reset_robot,
                                            const std::string& reason) {
  std::lock_guard<std::mutex> l(mu_);
  KINEMO_ASSIGN_OR_RETURN(Session * s, FindLocked(session_id));
  if (store_ != nullptr) KINEMO_RETURN_IF_ERROR(store_->Delete(session_id));
  const double now = clock_->MonotonicS();
  AdvanceLocked(*s, now);
  v1::Session snap = SnapshotLocked(*s, now);
  snap.set_cube_attached(false);
  CloseLocked(*s, reset_robot, reason, now);
  const std::string robot_id = s->info.robot_id();
  sessions_.erase(session_id);
  HandOverLocked(robot_id, now);
  return snap;
}

bool SessionManager::WatchedLocked(const std::string& session_id) const {
  for (const auto& [id, sub] : subscribers_) {
    if (sub.session_id == session_id) return true;
  }
  return false;
}

StatusOr<v1::Session> SessionManager::Act(const std::string& session_id, Action action,
                                          double intensity, bool from_cube) {
  if (action == common::v1::ACTION_UNSPECIFIED || !common::v1::Action_IsValid(action)) {
    return absl::InvalidArgumentError(
        absl::StrCat("action: must be IDLE, KISSES or SHOUTING, got ", action));
  }
  if (!std::isfinite(intensity) || intensity < -1 || intensity > 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("intensity: must be in [-1, 1], got ", intensity));
  }
  std::lock_guard<std::mutex> l(mu_);
  KINEMO_ASSIGN_OR_RETURN(Session * s, FindLocked(session_id));
  const double now = clock_->MonotonicS();
  std::vector<EmotionChange> changes;
  const bool changed = s->model.action() != action || s->model.intensity() != intensity;
  // On a copy first: a store error leaves the session as it was.
  EmotionModel model = s->model;
  model.SetAction(now, action, intensity, &changes);
  ++s->acts;
  if (Status st = PersistLocked(*s, model, now); !st.ok()) {
    --s->acts;
    return st;
  }
  s->model = model;
  s->last_activity_s = now;
  if (from_cube && s->info.cube_attached()) s->info.set_cube_intensity(intensity);
  PublishChangesLocked(*s, changes);
  if (changed) {
    v1::SessionEvent e = NewEventLocked(*s, now);
    auto* ac = e.mutable_action_changed();
    ac->set_action(action);
    ac->set_intensity(s->model.intensity());
    ac->set_from_cube(from_cube);
    PublishLocked(e);
  }
  return SnapshotLocked(*s, now);
}

StatusOr<v1::Session> SessionManager::Get(const std::string& session_id) {
  std::lock_guard<std::mutex> l(mu_);
  KINEMO_ASSIGN_OR_RETURN(Session * s, FindLocked(session_id));
  const double now = clock_->MonotonicS();
  AdvanceLocked(*s, now);
  return SnapshotLocked(*s, now);
}

std::vector<v1::Session> SessionManager::List(const std::string& robot_id) {
  std::lock_guard<std::mutex> l(mu_);
  const double now = clock_->MonotonicS();
  std::vector<const Session*> picked;
  for (auto& [id, s] : sessions_) {
    if (!robot_id.empty() && s->info.robot_id() != robot_id) continue;
    AdvanceLocked(*s, now);
    picked.push_back(s.get());
  }
  std::sort(picked.begin(), picked.end(),
            [](const Session* a, const Session* b) { return a->order < b->order; });
  std::vector<v1::Session> out;
  out.reserve(picked.size());
  for (const Session* s : picked) out.push_back(SnapshotLocked(*s, now));
  return out;
}

std::size_t SessionManager::size() const {
  std::lock_guard<std::mutex> l(mu_);
  return sessions_.size();
}

std::vector<std::string> SessionManager::Tick() {
  std::lock_guard<std::mutex> l(mu_);
  const double now = clock_->MonotonicS();
  std::vector<std::string> closed;
  for (auto& [id, s] : sessions_) {
    AdvanceLocked(*s, now);
    if (options_.idle_timeout_s > 0 && now - s->last_activity_s >= options_.idle_timeout_s) {
      if (WatchedLocked(id)) {
        s->last_activity_s = now;  // a watcher keeps it alive
      } else {
        closed.push_back(id);
      }
    }
  }
  for (const std::string& id : closed) {
    if (store_ != nullptr) {
      if (Status st = store_->Delete(id); !st.ok()) {
        log::Warn("session_delete_failed", {{"session_id", id}, {"error", std::string(st.message())}});
      }
    }
    Session& s = *sessions_.at(id);
    CloseLocked(s, false, "idle", now);
    const std::string robot_id = s.info.robot_id();
    sessions_.erase(id);
    HandOverLocked(robot_id, now);
  }
  return closed;
}

double SessionManager::NextChangeTime() const {
  std::lock_guard<std::mutex> l(mu_);
  double next = std::numeric_limits<double>::infinity();
  for (const auto& [id, s] : sessions_) next = std::min(next, s->model.NextChangeTime());
  return next;
}

void SessionManager::PublishCubeLocked(const Session& s, bool attached, bool visible,
                                       const cube_tracker::v1::CubeEvent* event,
                                       const std::string& reason) {
  v1::SessionEvent e = NewEventLocked(s, clock_->MonotonicS());
  auto* cs = e.mutable_cube_status_changed();
  cs->set_attached(attached);
  cs->set_visible(visible);
  if (event != nullptr) *cs->mutable_cube_event() = *event;
  cs->set_reason(reason);
  cs->set_top_face(s.info.cube_face());
  cs->set_intensity(s.info.cube_intensity());
  PublishLocked(e);
}

StatusOr<v1::Session> SessionManager::AttachCube(const std::string& session_id,
                                                 const cube_tracker::v1::VideoSource& source,
                                                 const cube_tracker::v1::TrackConfig& config,
                                                 const cube_tracker::v1::CubeState* first) {
  std::lock_guard<std::mutex> l(mu_);
  KINEMO_ASSIGN_OR_RETURN(Session * s, FindLocked(session_id));
  const double now = clock_->MonotonicS();
  AdvanceLocked(*s, now);
  Session updated = {s->info, s->model, s->open_time_s, s->open_wall_ns, s->order, now};
  updated.acts = s->acts;
  updated.robot_emotion = s->robot_emotion;
  updated.robot_sequence = s->robot_sequence;
  updated.cube_source = source.SerializeAsString();
  updated.cube_config = config.SerializeAsString();
  if (updated.cube_source.empty()) updated.cube_source = std::string(1, '\0');  // never empty
  updated.info.set_cube_attached(true);
  updated.info.set_vleo(v1::VLEO_KIND_CUBE);
  updated.info.set_cube_visible(first != nullptr && first->visible());
  updated.info.set_cube_face(first != nullptr ? first->top_face() : cube_tracker::v1::CUBE_FACE_UNSPECIFIED);
  updated.info.set_cube_intensity(first != nullptr ? std::clamp(first->intensity(), -1.0, 1.0) : 0.0);
  KINEMO_RETURN_IF_ERROR(PersistLocked(updated, updated.model, now));
  *s = std::move(updated);
  PublishCubeLocked(*s, true, s->info.cube_visible(), nullptr, "");
  return SnapshotLocked(*s, now);
}

StatusOr<v1::Session> SessionManager::DetachCube(const std::string& session_id,
                                                 const std::string& reason) {
  std::lock_guard<std::mutex> l(mu_);
  KINEMO_ASSIGN_OR_RETURN(Session * s, FindLocked(session_id));
  const double now = clock_->MonotonicS();
  AdvanceLocked(*s, now);
  if (!s->info.cube_attached()) return SnapshotLocked(*s, now);
  std::string source, config;
  source.swap(s->cube_source);
  config.swap(s->cube_config);
  if (Status st = PersistLocked(*s, s->model, now); !st.ok()) {
    s->cube_source.swap(source);
    s->cube_config.swap(config);
    return st;
  }
  s->info.set_cube_attached(false);
  s->info.clear_cube_visible();
  s->info.clear_cube_face();
  s->info.clear_cube_intensity();
  s->last_activity_s = now;
  PublishCubeLocked(*s, false, false, nullptr, reason);
  return SnapshotLocked(*s, now);
}

Status SessionManager::SetCubeVisible(const std::string& session_id, bool visible,
                                      const cube_tracker::v1::CubeEvent& event) {
  std::lock_guard<std::mutex> l(mu_);
  KINEMO_ASSIGN_OR_RETURN(Session * s, FindLocked(session_id));
  s->last_activity_s = clock_->MonotonicS();
  if (s->info.cube_attached()) {
    s->info.set_cube_visible(visible);
    if (event.has_found()) s->info.set_cube_face(event.found().top_face());
    if (event.has_face_changed()) {
      s->info.set_cube_face(event.face_changed().to_face());
      s->info.set_cube_intensity(0);
    }
  }
  PublishCubeLocked(*s, s->info.cube_attached(), visible, &event, "");
  return absl::OkStatus();
}

void SessionManager::OnRobotCommanded(const std::string& session_id, Emotion emotion,
                                      std::uint32_t sequence, const std::string& error,
                                      double latency_ms) {
  std::lock_guard<std::mutex> l(mu_);
  auto it = sessions_.find(session_id);
  if (it == sessions_.end()) return;
  Session& s = *it->second;
  const double now = clock_->MonotonicS();
  if (error.empty() && (s.robot_emotion != emotion || s.robot_sequence != sequence)) {
    s.robot_emotion = emotion;
    s.robot_sequence = sequence;
    // Not a change a client is told about with an answer: a failed write
    // costs only this record (the bridge is asked again after a restart).
    if (Status st = PersistLocked(s, s.model, now); !st.ok()) {
      log::Warn("session_write_failed", {{"session_id", session_id}, {"error", std::string(st.message())}});
    }
  }
  v1::SessionEvent e = NewEventLocked(s, now);
  auto* rc = e.mutable_robot_commanded();
  rc->set_emotion(emotion);
  rc->set_sequence_number(sequence);
  rc->set_error(error);
  rc->set_latency_ms(latency_ms);
  PublishLocked(e);
}

void SessionManager::OnRobotStatus(const std::string& robot_id, bool connected, Emotion shown,
                                   double battery_percent) {
  std::lock_guard<std::mutex> l(mu_);
  const double now = clock_->MonotonicS();
  for (auto& [id, s] : sessions_) {
    if (s->info.robot_id() != robot_id) continue;
    if (s->info.robot_connected() == connected && s->info.robot_emotion() == shown) continue;
    s->info.set_robot_connected(connected);
    s->info.set_robot_emotion(shown);
    v1::SessionEvent e = NewEventLocked(*s, now);
    auto* rs = e.mutable_robot_status_changed();
    rs->set_connected(connected);
    rs->set_shown_emotion(shown);
    rs->set_battery_percent(battery_percent);
    PublishLocked(e);
  }
}

std::vector<RobotCommand> SessionManager::DesiredCommands(const std::string& robot_id) {
  std::lock_guard<std::mutex> l(mu_);
  const double now = clock_->MonotonicS();
  std::vector<const Session*> picked;
  for (auto& [id, s] : sessions_) {
    if (s->info.robot_id() != robot_id) continue;
    AdvanceLocked(*s, now);
    picked.push_back(s.get());
  }
  std::sort(picked.begin(), picked.end(),
            [](const Session* a, const Session* b) { return a->order > b->order; });
  std::vector<RobotCommand> out;
  for (const Session* s : picked) {
    out.push_back(RobotCommand{s->info.session_id(), robot_id, s->model.emotion(),
                               s->model.RobotIntensity(), now});
  }
  return out;
}

StatusOr<std::uint64_t> SessionManager::Subscribe(const std::string& session_id,
                                                  EventCallback callback) {
  std::lock_guard<std::mutex> l(mu_);
  const double now = clock_->MonotonicS();
  if (!session_id.empty()) {
    KINEMO_ASSIGN_OR_RETURN(Session * s, FindLocked(session_id));
    AdvanceLocked(*s, now);
    v1::SessionEvent e = NewEventLocked(*s, now);
    *e.mutable_snapshot() = SnapshotLocked(*s, now);
    callback(e);
  } else {
    std::vector<Session*> all;
    for (auto& [id, s] : sessions_) all.push_back(s.get());
    std::sort(all.begin(), all.end(),
              [](const Session* a, const Session* b) { return a->order < b->order; });
    for (Session* s : all) {
      AdvanceLocked(*s, now);
      v1::SessionEvent e = NewEventLocked(*s, now);
      *e.mutable_snapshot() = SnapshotLocked(*s, now);
      callback(e);
    }
  }
  const std::uint64_t id = next_subscriber_++;
  subscribers_.emplace(id, Subscriber{session_id, std::move(callback)});
  return id;
}

void SessionManager::Unsubscribe(std::uint64_t id) {
  std::lock_guard<std::mutex> l(mu_);
  subscribers_.erase(id);
}

void SessionManager::CloseAll() {
  std::vector<std::string> ids;
  {
    std::lock_guard<std::mutex> l(mu_);
    for (const auto& [id, s] : sessions_) ids.push_back(id);
  }
  for (const std::string& id : ids) (void)Close(id, false, "shutdown");
}

}  // namespace kinemo::coordinator
