// Live motion and face out over the VMC protocol (docs/vmc.md): per motion
// frame, one OSC bundle (split into datagrams of at most
// max_datagram_bytes) with
//
//   /VMC/Ext/Root/Pos "root" 0 0 0  0 0 0 1       the model's root stays put
//   /VMC/Ext/Bone/Pos NAME px py pz qx qy qz qw  every humanoid bone the
//        source drives, parents first: local position (m) and local
//        rotation of the normalized humanoid (humanoid.h), Unity axes; the
//        hips' position is the body's place above the floor
//   /VMC/Ext/Blend/Val NAME w ... /VMC/Ext/Blend/Apply   when the frame has a face (blend.h)
//   /VMC/Ext/OK 1                                  a model is loaded and sending
//   /VMC/Ext/T t                                   the frame's media time (s)
//
// At most `fps` frames per second of media time (a frame goes when it
// reaches the next 1/fps tick; 0 = every frame). Plain C++; callers feed it
// the frames of a stream (the CLI's StreamAnimate client, the coordinator's
// StreamAnimate).
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>

#include "common/face/face_frame.h"
#include "common/motion/skeleton.h"
#include "common/status/status.h"
#include "common/vmc/blend.h"
#include "common/vmc/humanoid.h"
#include "common/vmc/osc.h"

namespace kinemo::vmc {

struct VmcStreamOptions {
  BoneNaming bones = BoneNaming::kUnity;
  BlendNaming blend = BlendNaming::kVrm0;
  // Frames per second of media time at most; 0 = every motion frame. Above
  // the motion's rate every frame goes (none is made up). [0, 240].
  double fps = 0;
  std::size_t max_datagram_bytes = kDefaultMaxDatagramBytes;
  HumanoidOptions humanoid;
};

// "--vmc-fps"-style checks of the options; INVALID_ARGUMENT naming `field`.
Status ValidateVmcOptions(const VmcStreamOptions& options, std::string_view field);

struct VmcStats {
  std::uint64_t frames = 0;     // frames sent
  std::uint64_t packets = 0;    // datagrams sent
  std::uint64_t dropped = 0;    // datagrams the socket did not take
  std::uint32_t bones = 0;      // bones per frame
  std::uint32_t blendshapes = 0;  // blend shapes per frame with a face (0: no face yet)
  std::uint64_t face_frames = 0;  // frames sent with blend shapes
};

class VmcStream {
 public:
  VmcStream(std::unique_ptr<UdpSender> sender, const VmcStreamOptions& options);

  // The source skeleton (the stream's header): builds the humanoid.
  // `meters_per_unit` > 0: the skeleton's unit (when the options give none).
  // Errors as HumanoidPoser::Create.
  Status Start(const motion::Skeleton& skeleton, double meters_per_unit = 0);
  bool started() const { return poser_.has_value(); }
  // One frame (after Start): false when the fps limit skips it.
  StatusOr<bool> SendFrame(double time_s, std::span<const double> values, const face::FaceFrame* face);

  const VmcStats& stats() const { return stats_; }
  const HumanoidPoser* poser() const { return poser_ ? &*poser_ : nullptr; }
  const UdpSender& sender() const { return *sender_; }

 private:
  std::unique_ptr<UdpSender> sender_;
  VmcStreamOptions options_;
  std::optional<HumanoidPoser> poser_;
  HumanoidPose pose_;
  BundleWriter writer_;
  std::int64_t last_tick_ = -1;
  VmcStats stats_;
};

}  // namespace kinemo::vmc
