#include "services/robot_bridge/robot_bridge_service.h"

#include <google/protobuf/util/time_util.h>

#include <chrono>
#include <cmath>
#include <map>

#include "absl/strings/str_cat.h"
#include "common/grpc/status_mapping.h"

namespace kinemo::robot_bridge {

namespace {

using Clock = std::chrono::steady_clock;
using common::v1::Emotion;

int Ms(double s, double fallback_s) { return static_cast<int>(std::llround((s > 0 ? s : fallback_s) * 1000.0)); }

// Picks the robot's value, else the default's, else the built-in.
double Pick(double robot, double defaults, double builtin) {
  if (robot > 0) return robot;
  if (defaults > 0) return defaults;
  return builtin;
}

}  // namespace

std::optional<int> EmotionToRegister(int api) {
  switch (api) {
    case common::v1::EMOTION_NEUTRAL: return static_cast<int>(robot::Emotion::kNeutral);
    case common::v1::EMOTION_HAPPY: return static_cast<int>(robot::Emotion::kHappy);
    case common::v1::EMOTION_ANGRY: return static_cast<int>(robot::Emotion::kAngry);
    default: return std::nullopt;
  }
}

int EmotionFromRegister(robot::Emotion e) {
  switch (e) {
    case robot::Emotion::kNeutral: return common::v1::EMOTION_NEUTRAL;
    case robot::Emotion::kHappy: return common::v1::EMOTION_HAPPY;
    case robot::Emotion::kAngry: return common::v1::EMOTION_ANGRY;
  }
  return common::v1::EMOTION_UNSPECIFIED;
}

StatusOr<std::vector<robot::RobotConfig>> ToCoreConfigs(const v1::RobotBridgeOptions& options) {
  if (options.robots_size() == 0) {
    return absl::InvalidArgumentError("robots: at least one robot is required");
  }
  const v1::LinkTiming& d = options.default_timing();
  std::vector<robot::RobotConfig> out;
  for (int i = 0; i < options.robots_size(); ++i) {
    const v1::RobotConfig& r = options.robots(i);
    const std::string field = absl::StrCat("robots[", i, "]");
    robot::RobotConfig c;
    c.name = r.robot_id();
    switch (r.transport_case()) {
      case v1::RobotConfig::kTcp:
        c.link.endpoint.kind = robot::Endpoint::Kind::kTcp;
        c.link.endpoint.host = r.tcp().host().empty() ? "127.0.0.1" : r.tcp().host();
        c.link.endpoint.port = r.tcp().port() == 0 ? 502 : static_cast<int>(r.tcp().port());
        break;
      case v1::RobotConfig::kRtu: {
        c.link.endpoint.kind = robot::Endpoint::Kind::kRtu;
        c.link.endpoint.device = r.rtu().device();
        if (c.link.endpoint.device.empty()) {
          return absl::InvalidArgumentError(absl::StrCat(field, ".rtu.device: empty"));
        }
        c.link.endpoint.baud = r.rtu().baud() == 0 ? 115200 : static_cast<int>(r.rtu().baud());
        const std::string& p = r.rtu().parity();
        if (!(p.empty() || p == "N" || p == "E" || p == "O")) {
          return absl::InvalidArgumentError(
              absl::StrCat(field, ".rtu.parity: '", p, "' is not N, E or O"));
        }
        c.link.endpoint.parity = p.empty() ? 'N' : p[0];
        c.link.endpoint.data_bits = r.rtu().data_bits() == 0 ? 8 : static_cast<int>(r.rtu().data_bits());
        c.link.endpoint.stop_bits = r.rtu().stop_bits() == 0 ? 1 : static_cast<int>(r.rtu().stop_bits());
        break;
      }
      default:
        return absl::InvalidArgumentError(
            absl::StrCat(field, ".transport: set tcp { host port } or rtu { device baud }"));
    }
    if (r.unit_id() > 247) {
      return absl::InvalidArgumentError(
          absl::StrCat(field, ".unit_id: ", r.unit_id(), " is outside 1..247"));
    }
    c.link.unit_id = r.unit_id() == 0 ? 1 : static_cast<int>(r.unit_id());
    if (!(r.register_map().empty() || r.register_map() == "pleo-v1")) {
      return absl::InvalidArgumentError(absl::StrCat(
          field, ".register_map: '", r.register_map(), "' is not known (only \"pleo-v1\")"));
    }
    const v1::LinkTiming& t = r.timing();
    c.link.connect_timeout_ms = Ms(Pick(t.connect_timeout_s(), d.connect_timeout_s(), 1.0), 1.0);
    c.link.response_timeout_ms = Ms(Pick(t.response_timeout_s(), d.response_timeout_s(), 0.2), 0.2);
    c.link.byte_timeout_ms = Ms(Pick(t.byte_timeout_s(), d.byte_timeout_s(), 0.05), 0.05);
    const uint32_t retries = t.retries() > 0 ? t.retries() : (d.retries() > 0 ? d.retries() : 3);
    c.retry.max_attempts = static_cast<int>(std::min<uint32_t>(retries, 99)) + 1;
    c.retry.initial_backoff_ms = Ms(Pick(t.initial_backoff_s(), d.initial_backoff_s(), 0.01), 0.01);
    c.retry.max_backoff_ms = Ms(Pick(t.max_backoff_s(), d.max_backoff_s(), 0.5), 0.5);
    c.retry.max_backoff_ms = std::max(c.retry.max_backoff_ms, c.retry.initial_backoff_ms);
    c.reconnect_backoff_initial_ms = std::max(1, c.retry.initial_backoff_ms);
    c.reconnect_backoff_max_ms = std::max(c.reconnect_backoff_initial_ms, c.retry.max_backoff_ms);
    c.heartbeat_interval_ms = Ms(Pick(t.heartbeat_s(), d.heartbeat_s(), 0.5), 0.5);
    c.status_poll_interval_ms = Ms(Pick(t.poll_s(), d.poll_s(), 0.2), 0.2);
    c.watchdog_ms = Ms(Pick(t.watchdog_s(), d.watchdog_s(), 2.0), 2.0);
    c.ack_timeout_ms = Ms(Pick(t.ack_timeout_s(), d.ack_timeout_s(), 0.5), 0.5);
    const int off = static_cast<int>(std::min<uint32_t>(r.address_offset(), 60000));
    c.map.command_base += off;
    c.map.heartbeat += off;
    c.map.watchdog += off;
    c.map.status_base += off;
    c.map.touch_base += off;
    if (Status s = robot::ValidateRobotConfig(c); !s.ok()) {
      return Status(s.code(), absl::StrCat(field, ": ", s.message()));
    }
    out.push_back(std::move(c));
  }
  return out;
}

v1::RobotStatus ToProto(const robot::RobotStatus& s) {
  v1::RobotStatus p;
  p.set_robot_id(s.name);
  p.set_connected(s.connected);
  if (s.has_robot_data) {
    p.set_shown_emotion(static_cast<Emotion>(EmotionFromRegister(s.shown_emotion)));
    p.set_target_emotion(static_cast<Emotion>(EmotionFromRegister(s.target_emotion)));
    p.set_shown_intensity(s.shown_intensity_permille / 1000.0);
    p.set_last_applied_sequence(s.applied_sequence);
    p.set_battery_percent(s.battery_permille / 10.0);
    p.set_fault_flags(s.fault_flags);
    static constexpr std::pair<uint16_t, const char*> kFaults[] = {
        {robot::kFaultBatteryLow, "battery_low"},
        {robot::kFaultWatchdogExpired, "watchdog_expired"},
        {robot::kFaultCommandRefused, "command_refused"},
        {robot::kFaultBatteryEmpty, "battery_empty"}};
    for (auto [bit, name] : kFaults) {
      if (s.fault_flags & bit) p.add_faults(name);
    }
    p.set_firmware_version(
        absl::StrCat(s.firmware_version >> 8, ".", s.firmware_version & 0xFF));
    for (int i = 0; i < robot::reg::kTouchCount; ++i) {
      auto* t = p.add_touch_sensors();
      t->set_name(std::string(robot::kTouchNames[i]));
      t->set_touched((s.touch_mask >> i) & 1u);
    }
    p.set_autonomous(s.state == robot::RobotState::kAutonomous);
    p.set_state(static_cast<v1::RobotState>(static_cast<int>(s.state) + 1));
    p.set_uptime_s(s.uptime_s);
  }
  if (s.has_command) {
    p.set_commanded_emotion(static_cast<Emotion>(EmotionFromRegister(s.commanded_emotion)));
    p.set_last_commanded_sequence(s.commanded_sequence);
  }
  p.set_in_sync(s.in_sync);
  if (s.updated.time_since_epoch().count() != 0) {
    *p.mutable_read_time() = google::protobuf::util::TimeUtil::NanosecondsToTimestamp(
        std::chrono::duration_cast<std::chrono::nanoseconds>(s.updated.time_since_epoch()).count());
  }
  p.set_last_error(s.last_error);
  p.set_reconnects(s.reconnects);
  p.set_resends(s.resends);
  return p;
}

WorkQueue::WorkQueue(int threads) {
  for (int i = 0; i < threads; ++i) {
    threads_.emplace_back([this] {
      for (;;) {
        std::function<void()> fn;
        {
          std::unique_lock<std::mutex> l(mu_);
          cv_.wait(l, [this] { return stop_ || !queue_.empty(); });
          if (queue_.empty()) return;
          fn = std::move(queue_.front());
          queue_.pop_front();
        }
        fn();
      }
    });
  }
}

WorkQueue::~WorkQueue() {
  {
    std::lock_guard<std::mutex> l(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  for (auto& t : threads_) t.join();
}

void WorkQueue::Post(std::function<void()> fn) {
  {
    std::lock_guard<std::mutex> l(mu_);
    queue_.push_back(std::move(fn));
  }
  cv_.notify_one();
}

StatusOr<std::shared_ptr<RobotBridgeServiceImpl>> RobotBridgeServiceImpl::Create(
    const v1::RobotBridgeOptions& options) {
  KINEMO_ASSIGN_OR_RETURN(auto configs, ToCoreConfigs(options));
  KINEMO_ASSIGN_OR_RETURN(auto bridge, robot::RobotBridge::Create(std::move(configs)));
  if (options.watch_min_interval_s() < 0 || std::isnan(options.watch_min_interval_s())) {
    return absl::InvalidArgumentError("watch_min_interval_s: must be >= 0");
  }
  return std::make_shared<RobotBridgeServiceImpl>(
      std::move(bridge), options.watch_min_interval_s() > 0 ? options.watch_min_interval_s() : 0.05,
      options.max_watchers() > 0 ? static_cast<int>(options.max_watchers()) : 1024);
}

RobotBridgeServiceImpl::RobotBridgeServiceImpl(std::unique_ptr<robot::RobotBridge> bridge,
                                               double watch_min_interval_s, int max_watchers)
    : bridge_(std::move(bridge)),
      watch_min_interval_s_(watch_min_interval_s),
      max_watchers_(max_watchers),
      work_(8) {
  bridge_->Start();
  // One sample per robot of each metric, from CachedStatus() (no Modbus).
  auto per_robot = [this](std::function<double(const robot::RobotStatus&)> value) {
    return [this, value = std::move(value)](std::vector<metrics::Sample>* out) {
      for (const std::string& name : bridge_->Names()) {
        auto client = bridge_->Find(name);
        if (client.ok()) out->push_back({{{"robot", name}}, value((*client)->CachedStatus())});
      }
    };
  };
  metrics_.push_back(metrics::OnScrape(
      "kinemo_robot_link_up", "1 while the bridge's Modbus link to the robot is connected, else 0.",
      prometheus::MetricType::Gauge, per_robot([](const robot::RobotStatus& s) { return s.connected ? 1.0 : 0.0; })));
  metrics_.push_back(metrics::OnScrape(
      "kinemo_robot_in_sync", "1 while the robot shows the commanded emotion and acknowledged it.",
      prometheus::MetricType::Gauge, per_robot([](const robot::RobotStatus& s) { return s.in_sync ? 1.0 : 0.0; })));
  metrics_.push_back(metrics::OnScrape(
      "kinemo_robot_reconnects_total", "Reconnections of the Modbus link after a loss.",
      prometheus::MetricType::Counter,
      per_robot([](const robot::RobotStatus& s) { return static_cast<double>(s.reconnects); })));
  metrics_.push_back(metrics::OnScrape(
      "kinemo_robot_resends_total", "Commands re-sent to the robot by reconciliation (retries).",
      prometheus::MetricType::Counter,
      per_robot([](const robot::RobotStatus& s) { return static_cast<double>(s.resends); })));
}

RobotBridgeServiceImpl::~RobotBridgeServiceImpl() {
  metrics_.clear();
  bridge_->Stop();
}

grpc::ServerUnaryReactor* RobotBridgeServiceImpl::SetEmotion(grpc::CallbackServerContext* context,
                                                             const v1::SetEmotionRequest* request,
                                                             v1::SetEmotionResponse* response) {
  auto* reactor = context->DefaultReactor();
  auto fail = [&](const Status& s) {
    reactor->Finish(ToGrpcStatus(s));
    return reactor;
  };
  if (request->robot_id().empty()) return fail(absl::InvalidArgumentError("robot_id: empty"));
  auto client = bridge_->Find(request->robot_id());
  if (!client.ok()) return fail(client.status());
  const auto reg = EmotionToRegister(request->emotion());
  if (!reg) {
    return fail(absl::InvalidArgumentError(
        absl::StrCat("emotion: ", request->emotion(),
                     " is not EMOTION_NEUTRAL, EMOTION_HAPPY or EMOTION_ANGRY")));
  }
  const double intensity = request->intensity();
  if (!(intensity >= 0.0 && intensity <= 1.0)) {
    return fail(absl::InvalidArgumentError(
        absl::StrCat("intensity: ", intensity, " is outside [0, 1]")));
  }
  robot::CommandOptions opts;
  opts.wait_shown = request->wait_applied();
  int timeout_ms = opts.wait_shown ? 4000 : 2000;
  if (context->deadline() != std::chrono::system_clock::time_point::max()) {
    auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                    context->deadline() - std::chrono::system_clock::now())
                    .count();
    timeout_ms = static_cast<int>(std::clamp<int64_t>(left, 1, 600000));
  }
  opts.timeout_ms = timeout_ms;
  const int permille = static_cast<int>(std::lround(intensity * 1000.0));
  robot::RobotClient* robot = *client;
  work_.Post([reactor, robot, response, opts, permille, e = *reg] {
    const auto start = Clock::now();
    auto r = robot->SetEmotion(e, permille, opts);
    if (!r.ok()) {
      reactor->Finish(ToGrpcStatus(r.status()));
      return;
    }
    response->set_round_trip_ms(
        std::chrono::duration<double, std::milli>(Clock::now() - start).count());
    response->set_sequence_number(r->sequence);
    response->set_applied(true);
    response->set_shown(r->shown);
    response->set_retries(static_cast<uint32_t>(r->attempts - 1));
    *response->mutable_status() = ToProto(robot->CachedStatus());
    reactor->Finish(grpc::Status::OK);
  });
  return reactor;
}

grpc::ServerUnaryReactor* RobotBridgeServiceImpl::GetStatus(grpc::CallbackServerContext* context,
                                                            const v1::GetStatusRequest* request,
                                                            v1::RobotStatus* response) {
  auto* reactor = context->DefaultReactor();
  if (request->robot_id().empty()) {
    reactor->Finish(ToGrpcStatus(absl::InvalidArgumentError("robot_id: empty")));
    return reactor;
  }
  auto client = bridge_->Find(request->robot_id());
  if (!client.ok()) {
    reactor->Finish(ToGrpcStatus(client.status()));
    return reactor;
  }
  const double max_age_s = request->max_age_s();
  if (!(max_age_s >= 0)) {
    reactor->Finish(ToGrpcStatus(absl::InvalidArgumentError("max_age_s: must be >= 0")));
    return reactor;
  }
  robot::RobotClient* robot = *client;
  if (max_age_s > 0) {
    robot::RobotStatus cached = robot->CachedStatus();
    const auto age = std::chrono::system_clock::now() - cached.updated;
    if (cached.has_robot_data && cached.connected &&
        age <= std::chrono::duration<double>(max_age_s)) {
      *response = ToProto(cached);
      reactor->Finish(grpc::Status::OK);
      return reactor;
    }
  }
  work_.Post([reactor, robot, response] {
    auto st = robot->ReadStatus();
    if (!st.ok()) {
      reactor->Finish(ToGrpcStatus(st.status()));
      return;
    }
    *response = ToProto(*st);
    reactor->Finish(grpc::Status::OK);
  });
  return reactor;
}

grpc::ServerUnaryReactor* RobotBridgeServiceImpl::ListRobots(grpc::CallbackServerContext* context,
                                                             const v1::ListRobotsRequest*,
                                                             v1::ListRobotsResponse* response) {
  for (const std::string& name : bridge_->Names()) {
    robot::RobotClient* robot = *bridge_->Find(name);
    auto* info = response->add_robots();
    info->set_robot_id(name);
    info->set_endpoint(robot->config().link.endpoint.ToString());
    info->set_unit_id(static_cast<uint32_t>(robot->config().link.unit_id));
    *info->mutable_status() = ToProto(robot->CachedStatus());
  }
  auto* reactor = context->DefaultReactor();
  reactor->Finish(grpc::Status::OK);
  return reactor;
}

// One WatchStatus stream: subscribes to the robots, keeps the newest status
// per robot, and writes one message at a time, at most one per robot per
// min_interval.
class RobotBridgeServiceImpl::Watcher final : public grpc::ServerWriteReactor<v1::RobotStatus> {
 public:
  Watcher(RobotBridgeServiceImpl* service, std::vector<robot::RobotClient*> robots,
          double min_interval_s)
      : service_(service), robots_(std::move(robots)),
        min_interval_(std::chrono::duration_cast<Clock::duration>(
            std::chrono::duration<double>(min_interval_s))) {
    {
      std::lock_guard<std::mutex> l(mu_);
      for (robot::RobotClient* r : robots_) {
        pending_[r->name()] = r->CachedStatus();  // the current status first
      }
    }
    for (robot::RobotClient* r : robots_) {
      ids_.push_back(r->Subscribe([this](const robot::RobotStatus& s) { OnStatus(s); }));
    }
    Action a;
    {
      std::lock_guard<std::mutex> l(mu_);
      a = NextLocked();
    }
    Do(a);
  }

  void OnWriteDone(bool ok) override {
    Action a;
    {
      std::lock_guard<std::mutex> l(mu_);
      writing_ = false;
      if (!ok && !finished_) {
        finished_ = true;
        finish_status_ = grpc::Status(grpc::StatusCode::CANCELLED, "stream closed");
      }
      a = NextLocked();
    }
    Do(a);
  }

  void OnCancel() override {
    Unsubscribe();
    Action a;
    {
      std::lock_guard<std::mutex> l(mu_);
      if (!finished_) {
        finished_ = true;
        finish_status_ = grpc::Status(grpc::StatusCode::CANCELLED, "cancelled by the client");
      }
      a = NextLocked();
    }
    Do(a);
  }

  void OnDone() override {
    Unsubscribe();
    service_->watchers_--;
    delete this;
  }

 private:
  enum class Action { kNone, kWrite, kFinish };

  void Unsubscribe() {
    std::lock_guard<std::mutex> l(unsub_mu_);
    for (size_t i = 0; i < ids_.size(); ++i) robots_[i]->Unsubscribe(ids_[i]);
    ids_.clear();
  }

  void OnStatus(const robot::RobotStatus& s) {
    Action a;
    {
      std::lock_guard<std::mutex> l(mu_);
      if (finished_) return;
      pending_[s.name] = s;
      a = NextLocked();
    }
    Do(a);
  }

  // Decides what to do next; the caller does it outside the lock.
  Action NextLocked() {
    if (writing_ || finish_called_) return Action::kNone;
    if (finished_) {
      finish_called_ = true;
      return Action::kFinish;
    }
    const auto now = Clock::now();
    for (auto it = pending_.begin(); it != pending_.end(); ++it) {
      auto last = last_sent_.find(it->first);
      if (last != last_sent_.end() && now - last->second < min_interval_) continue;
      out_ = ToProto(it->second);
      last_sent_[it->first] = now;
      pending_.erase(it);
      writing_ = true;
      return Action::kWrite;
    }
    return Action::kNone;  // rate-limited: the next poll brings it
  }

  void Do(Action a) {
    if (a == Action::kWrite) StartWrite(&out_);
    if (a == Action::kFinish) Finish(finish_status_);
  }

  RobotBridgeServiceImpl* service_;
  std::vector<robot::RobotClient*> robots_;
  std::vector<int> ids_;
  const Clock::duration min_interval_;
  std::mutex unsub_mu_;
  std::mutex mu_;
  std::map<std::string, robot::RobotStatus> pending_;
  std::map<std::string, Clock::time_point> last_sent_;
  v1::RobotStatus out_;
  bool writing_ = false;
  bool finished_ = false;       // no more writes wanted
  bool finish_called_ = false;  // Finish() issued
  grpc::Status finish_status_;
};

grpc::ServerWriteReactor<v1::RobotStatus>* RobotBridgeServiceImpl::WatchStatus(
    grpc::CallbackServerContext* context, const v1::WatchStatusRequest* request) {
  class Refuse final : public grpc::ServerWriteReactor<v1::RobotStatus> {
   public:
    explicit Refuse(const Status& s) { Finish(ToGrpcStatus(s)); }
    void OnDone() override { delete this; }
  };
  (void)context;
  std::vector<robot::RobotClient*> robots;
  if (request->robot_id().empty()) {
    for (const std::string& n : bridge_->Names()) robots.push_back(*bridge_->Find(n));
  } else {
    auto c = bridge_->Find(request->robot_id());
    if (!c.ok()) return new Refuse(c.status());
    robots.push_back(*c);
  }
  const double min_interval = request->min_interval_s();
  if (!(min_interval >= 0)) {
    return new Refuse(absl::InvalidArgumentError("min_interval_s: must be >= 0"));
  }
  if (++watchers_ > max_watchers_) {
    --watchers_;
    return new Refuse(absl::ResourceExhaustedError(
        absl::StrCat("WatchStatus: ", max_watchers_, " streams already open (max_watchers)")));
  }
  return new Watcher(this, std::move(robots), min_interval > 0 ? min_interval : watch_min_interval_s_);
}

}  // namespace kinemo::robot_bridge
