// `kinemo bench chaos` (chaos_bench.h).
#include "bench/system/chaos_bench.h"

#include <signal.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <mutex>
#include <random>
#include <sstream>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "common/audio/decode.h"
#include "common/process/process.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "services/coordinator/client/live_client.h"
#include "services/coordinator/core/sqlite_session_store.h"

namespace kinemo::coordinator {
namespace {

using kinemo::process::ChildProcess;
using kinemo::process::TempDir;
using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

double Now() { return std::chrono::duration<double>(Clock::now().time_since_epoch()).count(); }

void SleepS(double s) {
  if (s > 0) std::this_thread::sleep_for(std::chrono::duration<double>(s));
}

std::string Slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Channels that come back quickly after their server restarts (gRPC's
// reconnect backoff would otherwise grow to minutes over many faults).
std::shared_ptr<grpc::Channel> FastReconnectChannel(const std::string& address) {
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 500);
  return grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), args);
}

std::chrono::system_clock::time_point In(double s) {
  return std::chrono::system_clock::now() + std::chrono::milliseconds(static_cast<std::int64_t>(s * 1000));
}

// One process of the stack, restartable on the port it first bound.
struct Proc {
  std::string name;
  std::vector<std::string> argv;  // without the address arguments
  bool grpc = true;               // else pleo_sim (Modbus TCP)
  int port = 0;
  int starts = 0;
  std::unique_ptr<ChildProcess> child;
  std::shared_ptr<grpc::Channel> channel;  // grpc: health checks
  std::string Address() const { return "127.0.0.1:" + std::to_string(port); }
};

struct Fault {
  std::string kind, target;
  double start_s = 0, end_s = 0, recovered_s = 0;
  bool recovered = false;
};

struct ActSession {
  std::string id, robot;
  std::uint64_t acked = 0, failed = 0;
};

class Chaos {
 public:
  explicit Chaos(const ChaosBenchOptions& o) : o_(o), rng_(o.seed) {}

  ~Chaos() {
    stop_ = true;
    // Children stop in reverse order of their start (the coordinator first).
    for (auto it = procs_.rbegin(); it != procs_.rend(); ++it) {
      if ((*it)->child != nullptr && (*it)->child->Running()) {
        ::kill((*it)->child->pid(), SIGCONT);
        (void)(*it)->child->Stop(SIGTERM, 10s);
      }
    }
  }

  StatusOr<ChaosBenchResult> Run();

 private:
  void Log(const std::string& line) {
    if (o_.progress) o_.progress(line);
  }
  Status Setup();
  Status Start(Proc& p, double timeout_s);
  Proc& Add(std::string name, std::vector<std::string> argv, bool grpc = true) {
    procs_.push_back(std::make_unique<Proc>());
    Proc& p = *procs_.back();
    p.name = std::move(name);
    p.argv = std::move(argv);
    p.grpc = grpc;
    return p;
  }
  std::string Bin(const std::string& svc) const { return o_.bin_dir + "/services/" + svc + "/" + svc; }
  std::string File(const std::string& name) const { return dir_ + "/" + name; }

  grpc::Status Act(const std::string& id, double intensity, common::v1::Action action, double deadline_s) {
    v1::ActRequest r;
    r.set_session_id(id);
    r.set_action(action);
    r.set_intensity(intensity);
    v1::ActResponse resp;
    grpc::ClientContext ctx;
    ctx.set_deadline(In(deadline_s));
    return stub_->Act(&ctx, r, &resp);
  }
  bool Serving(Proc& p) {
    if (!p.child->Running()) return false;
    if (!p.grpc) return true;
    auto stub = grpc::health::v1::Health::NewStub(p.channel);
    grpc::health::v1::HealthCheckRequest req;
    grpc::health::v1::HealthCheckResponse resp;
    grpc::ClientContext ctx;
    ctx.set_deadline(In(1));
    return stub->Check(&ctx, req, &resp).ok() &&
           resp.status() == grpc::health::v1::HealthCheckResponse::SERVING;
  }
  // Every process serving, every robot connected, an Act acknowledged.
  bool StackServes() {
    for (auto& p : procs_) {
      if (!Serving(*p)) return false;
    }
    for (const ActSession& s : sessions_) {
      v1::GetSessionRequest g;
      g.set_session_id(s.id);
      v1::Session got;
      grpc::ClientContext ctx;
      ctx.set_deadline(In(1));
      if (!stub_->GetSession(&ctx, g, &got).ok() || !got.robot_connected()) return false;
    }
    return Act("chaos-probe", 0.5, common::v1::ACTION_KISSES, 1).ok();
  }
  // Waits for StackServes; the time it served, or -1 after the timeout.
  double WaitRecovered(double timeout_s) {
    const double until = Now() + timeout_s;
    while (Now() < until) {
      if (StackServes()) return Now();
      SleepS(0.05);
    }
    return -1;
  }

  void StreamWorker(int i);
  void Actor(ActSession* s);
  void CubeLoop();
  void MalformedLoop();
  Status InjectOne(Fault* f);

  const ChaosBenchOptions& o_;
  std::mt19937_64 rng_;
  std::unique_ptr<TempDir> temp_;
  std::string dir_, store_dir_;
  std::vector<std::unique_ptr<Proc>> procs_;
  std::vector<Proc*> services_, sims_;
  Proc* coordinator_ = nullptr;
  std::shared_ptr<grpc::Channel> coord_channel_;
  std::unique_ptr<v1::CoordinatorService::Stub> stub_;
  std::vector<ActSession> sessions_;
  audio::DecodedAudio audio_;
  double stream_timeout_s_ = 30;

  std::atomic<bool> stop_{false};
  std::mutex mu_;  // guards what the load threads report
  std::vector<std::pair<double, double>> lag_;  // (received_s, lag_ms)
  std::vector<std::pair<double, std::string>> stream_failures_;  // (ended_s, code)
  std::map<std::string, std::string> stream_first_error_;         // code -> message
  std::string cube_first_error_;
  int streams_ok_ = 0, streams_hung_ = 0;
  std::map<std::string, int> acts_failed_by_code_;
  int cube_attaches_ = 0, cube_failures_ = 0;
  int malformed_sent_ = 0, malformed_refused_ = 0, malformed_unexpected_ = 0;
  std::string malformed_first_unexpected_;
  std::vector<std::atomic<bool>> worker_done_;
};

Status Chaos::Start(Proc& p, double timeout_s) {
  const std::string pf = File(p.name + ".port");
  std::remove(pf.c_str());
  std::vector<std::string> argv = p.argv;
  if (p.grpc) {
    for (const std::string& a : {std::string("--host"), std::string("127.0.0.1"), std::string("--port"),
                                 std::to_string(p.port), std::string("--port-file"), pf}) {
      argv.push_back(a);
    }
  } else {
    for (const std::string& a :
         {std::string("--tcp"), "127.0.0.1:" + std::to_string(p.port), std::string("--port-file"), pf,
          std::string("--switch-ms"), std::string("100")}) {
      argv.push_back(a);
    }
  }
  // A restart may find its port still held for a moment: a few tries.
  for (int attempt = 0;; ++attempt) {
    KINEMO_ASSIGN_OR_RETURN(p.child,
                            ChildProcess::Spawn(argv, File(p.name + "." + std::to_string(p.starts) + ".log")));
    ++p.starts;
    const int port = kinemo::process::WaitForPortFile(
        pf, p.child.get(), std::chrono::milliseconds(static_cast<int>(timeout_s * 1000)));
    if (port > 0) {
      p.port = port;
      break;
    }
    if (attempt >= 4) {
      return absl::UnavailableError(absl::StrCat(p.name, ": no port within ", timeout_s, " s: ", p.child->ReadLog()));
    }
    SleepS(0.2);
  }
  if (p.grpc) {
    if (p.channel == nullptr) p.channel = FastReconnectChannel(p.Address());
    KINEMO_RETURN_IF_ERROR(kinemo::process::WaitForServing(
        p.channel, "", std::chrono::milliseconds(static_cast<int>(timeout_s * 1000))));
  }
  return absl::OkStatus();
}

Status Chaos::Setup() {
  if (o_.work_dir.empty()) {
    temp_ = std::make_unique<TempDir>();
    dir_ = temp_->path();
  } else {
    dir_ = o_.work_dir;
    std::filesystem::create_directories(dir_);
  }
  store_dir_ = File("coordinator-store");
  KINEMO_ASSIGN_OR_RETURN(audio_, audio::DecodeAudioFile(o_.speech_file));
  const double audio_s = static_cast<double>(audio_.samples.size()) / audio_.sample_rate_hz;
  stream_timeout_s_ = 15 + 2 * audio_s;
  // The cube's video and camera (kinemo cube render: the scripted kisses and shouting).
  {
    std::string out;
    auto code = ChildProcess::Run({o_.kinemo, "cube", "render", "--model", o_.data_dir + "/cube/vleo.cube", "--script",
                                   o_.data_dir + "/cube/vleo_scenario.json", "--out", File("cube.avi"),
                                   "--camera", File("cam.yml")},
                                  File("render.log"), 900s, &out);
    if (!code.ok() || *code != 0) {
      return absl::InternalError(absl::StrCat(
          "kinemo cube render failed: ", code.ok() ? absl::StrCat("exit ", *code, ": ", out) : code.status().ToString()));
    }
  }
  const std::string seed = o_.bin_dir + "/share/kinemo/store";
  if (!std::filesystem::is_directory(seed + "/models/bundled")) {
    return absl::FailedPreconditionError(
        absl::StrCat("the bundled seed store ", seed, " has no models/bundled: build the kinemo_seed_store target"));
  }
  // The robots and their bridge.
  for (const char* robot : {"pleo-a", "pleo-b"}) {
    Proc& p = Add(std::string("pleo_sim-") + robot, {Bin("pleo_sim")}, false);
    KINEMO_RETURN_IF_ERROR(Start(p, 20));
    sims_.push_back(&p);
  }
  {
    std::ofstream cfg(File("robot_bridge.textproto"));
    cfg << "server { shutdown_grace_s: 0.5 }\n";
    for (std::size_t i = 0; i < sims_.size(); ++i) {
      cfg << "robots { robot_id: \"" << (i == 0 ? "pleo-a" : "pleo-b") << "\" tcp { host: \"127.0.0.1\" port: "
          << sims_[i]->port << " } timing { poll_s: 0.05 max_backoff_s: 0.2 } }\n";
    }
  }
  std::vector<std::string> prosody, planner;
  Proc& bridge = Add("robot_bridge", {Bin("robot_bridge"), "--config", File("robot_bridge.textproto")});
  services_.push_back(&bridge);
  for (int i = 0; i < 2; ++i) {
    const std::string n = std::to_string(i);
    services_.push_back(&Add("prosody-" + n, {Bin("prosody")}));
    std::ofstream(File("planner" + n + ".textproto"))
        << "server { shutdown_grace_s: 0.5 }\nstore_dir: \"" << File("planner-store" + n) << "\"\n"
        << "seed_store_dir: \"" << seed << "\"\nlibrary_root: \"" << o_.data_dir << "\"\n"
        << "preload { library_id: \"bundled\" paths: \"planner_gesture\" paths: \"planner_controller\" }\n";
    services_.push_back(&Add("planner-" + n, {Bin("planner"), "--config", File("planner" + n + ".textproto")}));
  }
  std::ofstream(File("inference.textproto")) << "server { shutdown_grace_s: 0.5 }\nstore_dir: \""
                                             << File("inference-store") << "\"\nseed_store_dir: \"" << seed << "\"\n";
  services_.push_back(&Add("inference", {Bin("inference"), "--config", File("inference.textproto")}));
  std::ofstream(File("cube_tracker.textproto")) << "server { shutdown_grace_s: 0.5 }\ncubes {\n"
                                                << Slurp(o_.data_dir + "/cube/vleo.cube") << "}\nfile_root: \"" << dir_
                                                << "\"\n";
  services_.push_back(&Add("cube_tracker", {Bin("cube_tracker"), "--config", File("cube_tracker.textproto")}));
  for (Proc* p : services_) KINEMO_RETURN_IF_ERROR(Start(*p, 60));
  auto targets = [&](const std::string& prefix) {
    std::string out = "ipv4:";
    for (Proc* p : services_) {
      if (p->name.rfind(prefix, 0) == 0) out += (out.size() > 5 ? "," : "") + p->Address();
    }
    return out;
  };
  auto address_of = [&](const std::string& name) {
    for (Proc* p : services_) {
      if (p->name == name) return p->Address();
    }
    return std::string();
  };
  std::ofstream(File("coordinator.textproto"))
      << "server { shutdown_grace_s: 0.5 }\n"
      << "services {\n"
      << "  prosody { address: \"" << targets("prosody-") << "\" deadline_s: 30 }\n"
      << "  inference { address: \"" << address_of("inference") << "\" deadline_s: 30 }\n"
      << "  planner { address: \"" << targets("planner-") << "\" deadline_s: 30 }\n"
      << "  cube_tracker { address: \"" << address_of("cube_tracker") << "\" }\n"
      << "  robot_bridge { address: \"" << bridge.Address() << "\" deadline_s: 1 max_reconnect_backoff_s: 0.2 }\n"
      << "}\n"
      << "animate { models { inference_model_id: \"bundled\" controller_id: \"bundled\" } }\n"
      << "emotion { rate_per_s: 0.5 }\nresend_s: 0.3\n"
      << "store_dir: \"" << store_dir_ << "\"\n";
  coordinator_ = &Add("coordinator", {Bin("coordinator"), "--config", File("coordinator.textproto")});
  services_.push_back(coordinator_);
  KINEMO_RETURN_IF_ERROR(Start(*coordinator_, 60));
  coord_channel_ = FastReconnectChannel(coordinator_->Address());
  stub_ = v1::CoordinatorService::NewStub(coord_channel_);
  // The sessions: Actors on both robots, the probe, the cube.
  auto open = [&](const std::string& id, const std::string& robot, v1::VleoKind kind) -> Status {
    v1::OpenSessionRequest r;
    r.set_session_id(id);
    r.set_robot_id(robot);
    r.set_vleo(kind);
    r.set_initial_emotion(common::v1::EMOTION_NEUTRAL);
    v1::OpenSessionResponse resp;
    grpc::ClientContext ctx;
    ctx.set_deadline(In(10));
    const grpc::Status s = stub_->OpenSession(&ctx, r, &resp);
    if (!s.ok()) return absl::UnavailableError(absl::StrCat("OpenSession ", id, ": ", s.error_message()));
    return absl::OkStatus();
  };
  for (int i = 0; i < o_.act_sessions; ++i) {
    sessions_.push_back({"chaos-act-" + std::to_string(i), i % 2 == 0 ? "pleo-a" : "pleo-b"});
    KINEMO_RETURN_IF_ERROR(open(sessions_.back().id, sessions_.back().robot, v1::VLEO_KIND_CLIENT));
  }
  KINEMO_RETURN_IF_ERROR(open("chaos-probe", "pleo-a", v1::VLEO_KIND_CLIENT));
  KINEMO_RETURN_IF_ERROR(open("chaos-cube", "pleo-b", v1::VLEO_KIND_CUBE));
  if (WaitRecovered(60) < 0) return absl::UnavailableError("the stack did not serve within 60 s of its start");
  return absl::OkStatus();
}

void Chaos::StreamWorker(int i) {
  LiveStreamOptions lo;
  lo.realtime = true;
  lo.keep_frames = false;
  lo.timeout_s = stream_timeout_s_;
  lo.config.set_request_id("chaos-stream-" + std::to_string(i));
  // Streams start spread over the clip.
  SleepS(static_cast<double>(i) * 7.0 / std::max(1, o_.streams));
  while (!stop_) {
    const double t0 = Now();
    auto r = RunLiveStream(coord_channel_, audio_.samples, audio_.sample_rate_hz, lo);
    const double t1 = Now();
    {
      std::lock_guard<std::mutex> l(mu_);
      if (t1 - t0 > lo.timeout_s + 5) {
        ++streams_hung_;
      } else if (r.ok()) {
        ++streams_ok_;
        for (std::size_t k = 0; k < r->motion_lag_ms.size(); ++k) {
          lag_.emplace_back(r->motion_lag_received_s[k], r->motion_lag_ms[k]);
        }
      } else {
        const std::string code = absl::StatusCodeToString(r.status().code());
        stream_failures_.emplace_back(t1, code);
        stream_first_error_.try_emplace(code, std::string(r.status().message()));
      }
    }
    if (!r.ok()) SleepS(0.2);
  }
  worker_done_[i] = true;
}

void Chaos::Actor(ActSession* s) {
  for (std::uint64_t k = 0; !stop_; ++k) {
    // Each Act its own intensity (in (0, 1)), alternating kisses and shouting.
    const double intensity = 0.1 + 0.8 * std::fmod(static_cast<double>(k) * 1e-4, 1.0);
    const grpc::Status st =
        Act(s->id, intensity, k % 2 == 0 ? common::v1::ACTION_KISSES : common::v1::ACTION_SHOUTING, 3);
    if (st.ok()) {
      ++s->acked;
    } else {
      ++s->failed;
      std::lock_guard<std::mutex> l(mu_);
      ++acts_failed_by_code_[absl::StatusCodeToString(static_cast<absl::StatusCode>(st.error_code()))];
    }
    SleepS(st.ok() ? o_.act_every_s : 0.1);
  }
}

void Chaos::CubeLoop() {
  while (!stop_) {
    v1::GetSessionRequest g;
    g.set_session_id("chaos-cube");
    v1::Session got;
    grpc::ClientContext gctx;
    gctx.set_deadline(In(2));
    if (stub_->GetSession(&gctx, g, &got).ok() && !got.cube_attached()) {
      v1::AttachCubeRequest a;
      a.set_session_id("chaos-cube");
      a.mutable_source()->set_video_file(File("cube.avi"));
      a.mutable_source()->set_realtime(true);
      a.mutable_config()->set_cube_id("vleo");
      a.mutable_config()->set_intrinsics_file(File("cam.yml"));
      v1::AttachCubeResponse r;
      grpc::ClientContext ctx;
      ctx.set_deadline(In(10));
      const grpc::Status st = stub_->AttachCube(&ctx, a, &r);
      std::lock_guard<std::mutex> l(mu_);
      ++(st.ok() ? cube_attaches_ : cube_failures_);
      if (!st.ok() && cube_first_error_.empty()) {
        cube_first_error_ = absl::StrCat(static_cast<int>(st.error_code()), " ", st.error_message());
      }
    }
    SleepS(0.5);
  }
}

void Chaos::MalformedLoop() {
  for (int k = 0; !stop_; ++k) {
    grpc::Status st;
    std::string what;
    if (k % 3 == 0) {
      what = "Act intensity 7";
      st = Act("chaos-probe", 7.0, common::v1::ACTION_KISSES, 2);
    } else if (k % 3 == 1) {
      what = "Act intensity NaN";
      st = Act("chaos-probe", std::numeric_limits<double>::quiet_NaN(), common::v1::ACTION_KISSES, 2);
    } else {
      what = "OpenSession id 'Bad Id!'";
      v1::OpenSessionRequest r;
      r.set_session_id("Bad Id!");
      r.set_robot_id("pleo-a");
      v1::OpenSessionResponse resp;
      grpc::ClientContext ctx;
      ctx.set_deadline(In(2));
      st = stub_->OpenSession(&ctx, r, &resp);
    }
    {
      std::lock_guard<std::mutex> l(mu_);
      const auto code = st.error_code();
      if (code == grpc::StatusCode::UNAVAILABLE || code == grpc::StatusCode::DEADLINE_EXCEEDED) {
        // Not reached (a fault): not counted.
      } else {
        ++malformed_sent_;
        const bool names_field = st.error_message().find(k % 3 == 2 ? "session_id" : "intensity") != std::string::npos;
        if (code == grpc::StatusCode::INVALID_ARGUMENT && names_field) {
          ++malformed_refused_;
        } else {
          ++malformed_unexpected_;
          if (malformed_first_unexpected_.empty()) {
            malformed_first_unexpected_ = what + ": " + std::to_string(static_cast<int>(code)) + " " + st.error_message();
          }
        }
      }
    }
    SleepS(0.5);
  }
}

Status Chaos::InjectOne(Fault* f) {
  std::uniform_real_distribution<double> unit(0, 1);
  const double u = unit(rng_);
  f->kind = u < 0.5 ? "kill" : (u < 0.8 ? "freeze" : "robot");
  Proc* target = nullptr;
  if (f->kind == "robot") {
    target = sims_[std::uniform_int_distribution<std::size_t>(0, sims_.size() - 1)(rng_)];
  } else {
    target = services_[std::uniform_int_distribution<std::size_t>(0, services_.size() - 1)(rng_)];
  }
  f->target = target->name;
  f->start_s = Now();
  if (f->kind == "freeze") {
    ::kill(target->child->pid(), SIGSTOP);
    SleepS(2 + 3 * unit(rng_));
    ::kill(target->child->pid(), SIGCONT);
    f->end_s = Now();
  } else if (f->kind == "robot") {
    auto code = target->child->Stop(SIGKILL, 10s);
    if (!code.ok()) return code.status();
    SleepS(2);
    KINEMO_RETURN_IF_ERROR(Start(*target, 60));
    f->end_s = Now();  // the link can come back
  } else {
    auto code = target->child->Stop(SIGKILL, 10s);
    if (!code.ok()) return code.status();
    f->end_s = Now();  // the restart starts: its time counts in the recovery
    KINEMO_RETURN_IF_ERROR(Start(*target, 60));
  }
  return absl::OkStatus();
}

StatusOr<ChaosBenchResult> Chaos::Run() {
  KINEMO_RETURN_IF_ERROR(Setup());
  ChaosBenchResult res;
  const double t_start = Now();
  const double t_end = t_start + o_.minutes * 60;
  worker_done_ = std::vector<std::atomic<bool>>(static_cast<std::size_t>(o_.streams));
  std::vector<std::thread> workers, others;
  for (int i = 0; i < o_.streams; ++i) workers.emplace_back([this, i] { StreamWorker(i); });
  for (ActSession& s : sessions_) others.emplace_back([this, &s] { Actor(&s); });
  others.emplace_back([this] { CubeLoop(); });
  others.emplace_back([this] { MalformedLoop(); });

  std::vector<Fault> faults;
  std::uniform_real_distribution<double> gap(o_.gap_min_s, std::max(o_.gap_min_s, o_.gap_max_s));
  // A short first pause: the load settles.
  SleepS(std::min(gap(rng_), std::max(1.0, (t_end - Now()) / 3)));
  Status failure;
  while (Now() < t_end && (o_.max_faults <= 0 || static_cast<int>(faults.size()) < o_.max_faults)) {
    Fault f;
    failure = InjectOne(&f);
    if (!failure.ok()) break;
    const double served = WaitRecovered(o_.recovery_timeout_s);
    f.recovered = served >= 0;
    f.recovered_s = f.recovered ? served : Now();
    faults.push_back(f);
    Log(absl::StrCat("fault ", faults.size(), ": ", f.kind, " ", f.target, " at ", std::round((f.start_s - t_start) * 10) / 10,
                     " s, ", f.recovered ? "recovered in " : "NOT recovered after ",
                     std::round((f.recovered_s - f.end_s) * 100) / 100, " s"));
    const double rest = std::min(gap(rng_), t_end - Now());
    SleepS(rest);
  }
  // Stop the load; streams finish the clip they are playing.
  stop_ = true;
  for (std::thread& t : others) t.join();
  const double give_up = Now() + stream_timeout_s_ + 10;
  while (Now() < give_up) {
    if (std::all_of(worker_done_.begin(), worker_done_.end(), [](const std::atomic<bool>& d) { return d.load(); })) {
      break;
    }
    SleepS(0.1);
  }
  bool leak = false;
  for (std::size_t i = 0; i < workers.size(); ++i) {
    if (worker_done_[i]) {
      workers[i].join();
    } else {
      workers[i].detach();  // a hung stream: counted, and this state is kept alive
      ++streams_hung_;
      leak = true;
    }
  }
  res.wall_s = Now() - t_start;
  if (!failure.ok()) return failure;

  // Sessions: every one still open.
  std::vector<std::string> ids;
  for (const ActSession& s : sessions_) ids.push_back(s.id);
  ids.push_back("chaos-probe");
  ids.push_back("chaos-cube");
  res.sessions_opened = static_cast<int>(ids.size());
  {
    v1::ListSessionsResponse listed;
    grpc::ClientContext ctx;
    ctx.set_deadline(In(10));
    const grpc::Status s = stub_->ListSessions(&ctx, v1::ListSessionsRequest(), &listed);
    if (!s.ok()) return absl::UnavailableError(absl::StrCat("ListSessions after the run: ", s.error_message()));
    for (const std::string& id : ids) {
      const bool found = std::any_of(listed.sessions().begin(), listed.sessions().end(),
                                     [&](const v1::Session& x) { return x.session_id() == id; });
      if (!found) ++res.sessions_lost;
    }
  }
  // Acts: the coordinator stops (gracefully: its store stays), the store is read.
  auto stopped = coordinator_->child->Stop(SIGTERM, 20s);
  if (!stopped.ok()) return stopped.status();
  KINEMO_ASSIGN_OR_RETURN(auto store, SqliteSessionStore::Open(store_dir_));
  KINEMO_ASSIGN_OR_RETURN(auto rows, store->LoadAll());
  for (const ActSession& s : sessions_) {
    res.acts_acknowledged += s.acked;
    res.acts_failed += s.failed;
    auto row = std::find_if(rows.begin(), rows.end(), [&](const StoredSession& r) { return r.session_id == s.id; });
    if (row == rows.end()) {
      res.acts_lost += s.acked;
      continue;
    }
    if (row->acts < s.acked) res.acts_lost += s.acked - row->acts;
    if (row->acts > s.acked + s.failed) res.acts_extra += row->acts - (s.acked + s.failed);
  }

  std::lock_guard<std::mutex> l(mu_);
  res.faults = static_cast<int>(faults.size());
  std::vector<double> recovery;
  for (const Fault& f : faults) {
    ChaosFaultKindStats& k = res.by_kind[f.kind];
    ++k.count;
    ++res.faults_by_target[f.target];
    if (!f.recovered) {
      ++k.not_recovered;
      continue;
    }
    k.recovery_s.push_back(f.recovered_s - f.end_s);
    recovery.push_back(f.recovered_s - f.end_s);
  }
  // Fault windows: injection to 1 s after the stack served again.
  auto window_of = [&](double t) -> const Fault* {
    for (const Fault& f : faults) {
      if (t >= f.start_s && t <= f.recovered_s + 1.0) return &f;
    }
    return nullptr;
  };
  double window_s = 0;
  for (const Fault& f : faults) window_s += f.recovered_s + 1.0 - f.start_s;
  res.fault_window_share = res.wall_s > 0 ? std::min(1.0, window_s / res.wall_s) : 0;
  res.streams_ok = streams_ok_;
  res.streams_hung = streams_hung_;
  for (const auto& [t, code] : stream_failures_) {
    ++res.streams_failed_with_status;
    ++res.streams_failed_by_code[code];
    // A stream fails when a fault ends it: count it against the fault whose
    // window it ended in (or the last one before it).
    const Fault* f = window_of(t);
    if (f == nullptr) {
      for (const Fault& g : faults) {
        if (g.start_s <= t) f = &g;
      }
    }
    if (f != nullptr) ++res.by_kind[f->kind].streams_failed;
  }
  std::vector<double> outside, all;
  outside.reserve(lag_.size());
  all.reserve(lag_.size());
  for (const auto& [t, ms] : lag_) {
    all.push_back(ms);
    if (window_of(t) == nullptr) outside.push_back(ms);
  }
  res.lag_samples_all = all.size();
  res.lag_samples_outside = outside.size();
  res.lag_p99_ms_all = Percentile(all, 0.99);
  res.lag_p50_ms_outside_faults = Percentile(outside, 0.5);
  res.lag_p99_ms_outside_faults = Percentile(outside, 0.99);
  auto summarize = [](const std::vector<double>& v, double* p50, double* p95, double* max) {
    *p50 = Percentile(v, 0.5);
    *p95 = Percentile(v, 0.95);
    *max = v.empty() ? 0 : *std::max_element(v.begin(), v.end());
  };
  for (auto& [kind, k] : res.by_kind) {
    summarize(k.recovery_s, &k.recovery_s_p50, &k.recovery_s_p95, &k.recovery_s_max);
  }
  summarize(recovery, &res.recovery_s_p50, &res.recovery_s_p95, &res.recovery_s_max);
  res.acts_failed_by_code = acts_failed_by_code_;
  res.cube_attaches = cube_attaches_;
  res.cube_attach_failures = cube_failures_;
  res.cube_first_error = cube_first_error_;
  res.streams_first_error = stream_first_error_;
  res.malformed_sent = malformed_sent_;
  res.malformed_refused = malformed_refused_;
  res.malformed_unexpected = malformed_unexpected_;
  res.malformed_first_unexpected = malformed_first_unexpected_;
  if (leak) {
    // Hung streams still reference this state: stop the children now and
    // keep the rest (the caller reports and exits).
    for (auto it = procs_.rbegin(); it != procs_.rend(); ++it) {
      if ((*it)->child != nullptr && (*it)->child->Running()) (void)(*it)->child->Stop(SIGKILL, 5s);
    }
  }
  return res;
}

}  // namespace

StatusOr<ChaosBenchResult> RunChaosBench(const ChaosBenchOptions& options) {
  if (!(options.minutes > 0) || options.minutes > 24 * 60) {
    return absl::InvalidArgumentError(absl::StrCat("--minutes: ", options.minutes, " is outside (0, 1440]"));
  }
  if (options.streams < 0 || options.streams > 64) {
    return absl::InvalidArgumentError(absl::StrCat("--streams: ", options.streams, " is outside [0, 64]"));
  }
  if (options.act_sessions < 1 || options.act_sessions > 64) {
    return absl::InvalidArgumentError(absl::StrCat("--act-sessions: ", options.act_sessions, " is outside [1, 64]"));
  }
  if (!(options.gap_min_s >= 0) || !(options.gap_max_s >= options.gap_min_s) || options.gap_max_s > 3600) {
    return absl::InvalidArgumentError("--gap-s: needs 0 <= min <= max <= 3600");
  }
  if (options.max_faults < 0 || options.max_faults > 100000) {
    return absl::InvalidArgumentError(absl::StrCat("--max-faults: ", options.max_faults, " is outside [0, 100000]"));
  }
  auto chaos = std::make_unique<Chaos>(options);
  auto result = chaos->Run();
  if (result.ok() && result->streams_hung > 0) {
    (void)chaos.release();  // hung streams' threads still use it
  }
  return result;
}

}  // namespace kinemo::coordinator
