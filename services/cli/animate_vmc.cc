// kinemo animate --stream --vmc HOST:PORT (see animate_vmc.h).

#include "services/cli/animate_vmc.h"

#include <cstdio>
#include <vector>

#include "common/vmc/vmc_proto.h"
#include "services/coordinator/client/live_client.h"

namespace kinemo::cli {

namespace {
namespace animate_vmc {  // this file's own helpers (the unity build puts files together)

using Clock = std::chrono::steady_clock;

double Ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

StatusOr<vmc::VmcStreamOptions> VmcOptionsFor(const AnimateVmcArgs& a) {
  vmc::VmcStreamOptions o;
  KINEMO_ASSIGN_OR_RETURN(o.bones, vmc::ParseBoneNaming(a.bones, "--vmc-bones"));
  const std::string blend = a.blend.empty() ? (o.bones == vmc::BoneNaming::kVrm1 ? "vrm1" : "vrm0") : a.blend;
  KINEMO_ASSIGN_OR_RETURN(o.blend, vmc::ParseBlendNaming(blend, "--vmc-blend"));
  o.fps = a.fps;
  KINEMO_RETURN_IF_ERROR(vmc::ValidateVmcOptions(o, "--vmc-fps"));
  return o;
}

}  // namespace animate_vmc
}  // namespace

struct AnimateVmc::State {
  std::unique_ptr<vmc::ProtoVmcStream> stream;
  vmc::VmcStreamOptions options;
  bool started = false;
  Status error;
  // Per frame sent: audio sent -> its packets sent, and frame seen -> sent.
  std::vector<double> lag_ms, send_ms;
};

void AddAnimateVmcOptions(CLI::App* cmd, AnimateVmcArgs* a) {
  cmd->add_option("--vmc", a->address,
                  "with --stream: send the live motion and face as VMC protocol packets (OSC over UDP) to "
                  "HOST:PORT (PORT alone: 127.0.0.1; a VRM app, EVMC4U, VMC4UE or VMC4B listens on 39539). "
                  "--json adds vmc_packets, vmc_bones, vmc_blendshapes, vmc_lag_p50_ms, ... See docs/vmc.md");
  cmd->add_option("--vmc-bones", a->bones, "with --vmc: bone names, unity (HumanBodyBones) or vrm1")
      ->capture_default_str();
  cmd->add_option("--vmc-blend", a->blend,
                  "with --vmc: blend shape names, vrm0 (A I U E O, Blink, Joy ...) or vrm1 (aa ih ou ee oh, blink, "
                  "happy ...); default vrm1 with --vmc-bones vrm1, else vrm0");
  cmd->add_option("--vmc-fps", a->fps, "with --vmc: at most this many frames per second (0 = every motion frame)")
      ->capture_default_str();
}

Status AnimateVmc::Validate(const AnimateVmcArgs& a) {
  using namespace animate_vmc;
  KINEMO_RETURN_IF_ERROR(vmc::ParseEndpoint(a.address, "--vmc").status());
  return VmcOptionsFor(a).status();
}

StatusOr<std::unique_ptr<AnimateVmc>> AnimateVmc::Open(const AnimateVmcArgs& a) {
  using namespace animate_vmc;
  KINEMO_ASSIGN_OR_RETURN(vmc::Endpoint endpoint, vmc::ParseEndpoint(a.address, "--vmc"));
  auto state = std::make_unique<State>();
  KINEMO_ASSIGN_OR_RETURN(state->options, VmcOptionsFor(a));
  // The user names the receiver: any host they give (loopback by default).
  KINEMO_ASSIGN_OR_RETURN(std::unique_ptr<vmc::UdpSender> sender,
                          vmc::UdpSender::Open(endpoint, /*loopback_only=*/false, "--vmc"));
  state->stream =
      std::make_unique<vmc::ProtoVmcStream>(std::make_unique<vmc::VmcStream>(std::move(sender), state->options));
  state->lag_ms.reserve(1 << 14);
  state->send_ms.reserve(1 << 14);
  return std::unique_ptr<AnimateVmc>(new AnimateVmc(std::move(state)));
}

AnimateVmc::AnimateVmc(std::unique_ptr<State> state) : state_(std::move(state)) {}
AnimateVmc::~AnimateVmc() = default;

void AnimateVmc::OnFrame(const common::v1::MotionStreamHeader& header, const common::v1::MotionFrame& frame,
                         std::chrono::steady_clock::time_point audio_sent) {
  using namespace animate_vmc;
  State& s = *state_;
  if (!s.error.ok()) return;
  const Clock::time_point seen = Clock::now();
  if (!s.started) {
    s.started = true;
    if (Status st = s.stream->OnHeader(header); !st.ok()) {
      s.error = Annotate(st, "--vmc: the stream's skeleton");
      return;
    }
  }
  auto sent = s.stream->OnFrame(frame);
  if (!sent.ok()) {
    s.error = Annotate(sent.status(), "--vmc");
    return;
  }
  if (*sent) {
    const Clock::time_point done = Clock::now();
    s.lag_ms.push_back(Ms(done - audio_sent));
    s.send_ms.push_back(Ms(done - seen));
  }
}

Status AnimateVmc::status() const { return state_->error; }

void AnimateVmc::AddJson(nlohmann::json* out) const {
  const State& s = *state_;
  const vmc::VmcStats& st = s.stream->stream().stats();
  nlohmann::json& j = *out;
  j["vmc_address"] = s.stream->stream().sender().address();
  j["vmc_bone_names"] = std::string(vmc::BoneNamingName(s.options.bones));
  j["vmc_blend_names"] = s.options.blend == vmc::BlendNaming::kVrm0 ? "vrm0" : "vrm1";
  j["vmc_frames"] = st.frames;
  j["vmc_packets"] = st.packets;
  j["vmc_dropped"] = st.dropped;
  j["vmc_bones"] = st.bones;
  const vmc::HumanoidPoser* poser = s.stream->stream().poser();
  j["vmc_meters_per_unit"] = poser != nullptr ? poser->meters_per_unit() : 0.0;
  j["vmc_blendshapes"] = st.blendshapes;
  j["vmc_face_frames"] = st.face_frames;
  j["vmc_lag_p50_ms"] = coordinator::Percentile(s.lag_ms, 0.5);
  j["vmc_lag_p99_ms"] = coordinator::Percentile(s.lag_ms, 0.99);
  j["vmc_send_p99_ms"] = coordinator::Percentile(s.send_ms, 0.99);
}

std::string AnimateVmc::Summary() const {
  const State& s = *state_;
  const vmc::VmcStats& st = s.stream->stream().stats();
  char line[256];
  std::snprintf(line, sizeof line,
                "VMC to %s: %llu frames, %u bones, %u blend shapes, %llu packets (%llu dropped), lag p50 %.1f ms "
                "p99 %.1f ms",
                s.stream->stream().sender().address().c_str(), static_cast<unsigned long long>(st.frames), st.bones,
                st.blendshapes, static_cast<unsigned long long>(st.packets), static_cast<unsigned long long>(st.dropped),
                coordinator::Percentile(s.lag_ms, 0.5), coordinator::Percentile(s.lag_ms, 0.99));
  return line;
}

}  // namespace kinemo::cli
