// `kinemo animate --stream --vmc HOST:PORT`: the live motion and face sent
// as VMC protocol packets (common/vmc, docs/vmc.md) as each frame arrives,
// with the lag from the audio sent to the packet sent, on the client's
// clock. Implemented in animate_vmc.cc.
#pragma once

#include <chrono>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "common/status/status.h"
#include "kinemo/common/v1/motion.pb.h"

namespace kinemo::cli {

struct AnimateVmcArgs {
  std::string address;  // --vmc
  std::string bones = "unity";  // --vmc-bones
  std::string blend;            // --vmc-blend ("" = vrm0 with unity bones, vrm1 with vrm1)
  double fps = 0;               // --vmc-fps
};

// Adds --vmc, --vmc-bones, --vmc-blend, --vmc-fps to `cmd`.
void AddAnimateVmcOptions(CLI::App* cmd, AnimateVmcArgs* args);

class AnimateVmc {
 public:
  // Checks the options (INVALID_ARGUMENT naming the option), before any
  // stack starts.
  static Status Validate(const AnimateVmcArgs& args);
  // Opens the socket (NOT_FOUND naming --vmc for a host that does not resolve).
  static StatusOr<std::unique_ptr<AnimateVmc>> Open(const AnimateVmcArgs& args);
  ~AnimateVmc();

  // LiveStreamOptions::on_frame: sends the frame (the first one builds the
  // humanoid from the header's skeleton). A failure is kept (status()) and
  // stops the sending; the stream goes on.
  void OnFrame(const common::v1::MotionStreamHeader& header, const common::v1::MotionFrame& frame,
               std::chrono::steady_clock::time_point audio_sent);
  // The first error ("--vmc: ..."), OK if none.
  Status status() const;
  // vmc_address, vmc_bone_names, vmc_blend_names, vmc_frames, vmc_packets,
  // vmc_dropped, vmc_bones, vmc_blendshapes, vmc_face_frames,
  // vmc_meters_per_unit (the source unit the lengths were scaled by),
  // vmc_lag_p50_ms, vmc_lag_p99_ms, vmc_send_p99_ms.
  void AddJson(nlohmann::json* out) const;
  // One line for the text output.
  std::string Summary() const;

 private:
  struct State;
  explicit AnimateVmc(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

}  // namespace kinemo::cli
