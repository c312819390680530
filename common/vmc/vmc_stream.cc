#include "common/vmc/vmc_stream.h"

#include <array>
#include <cmath>

namespace kinemo::vmc {

Status ValidateVmcOptions(const VmcStreamOptions& options, std::string_view field) {
  if (!(options.fps >= 0) || options.fps > 240) {
    return InvalidField(field, "the frame rate must be in [0, 240] (0 = every frame), got ", options.fps);
  }
  return absl::OkStatus();
}

VmcStream::VmcStream(std::unique_ptr<UdpSender> sender, const VmcStreamOptions& options)
    : sender_(std::move(sender)), options_(options), writer_(options.max_datagram_bytes) {}

Status VmcStream::Start(const motion::Skeleton& skeleton, double meters_per_unit) {
  HumanoidOptions ho = options_.humanoid;
  if (ho.meters_per_unit == 0 && meters_per_unit > 0 && meters_per_unit <= 1000) ho.meters_per_unit = meters_per_unit;
  KINEMO_ASSIGN_OR_RETURN(HumanoidPoser poser, HumanoidPoser::Create(skeleton, ho));
  poser_ = std::move(poser);
  stats_.bones = static_cast<std::uint32_t>(poser_->bones().size());
  last_tick_ = -1;
  return absl::OkStatus();
}

StatusOr<bool> VmcStream::SendFrame(double time_s, std::span<const double> values, const face::FaceFrame* face) {
  if (!poser_) return absl::FailedPreconditionError("VMC: a frame before the skeleton");
  if (options_.fps > 0) {
    // The frame goes when it reaches the next tick of 1/fps (a frame time
    // rounded in the file, 0.0333333 for 1/30 s, counts at its tick).
    const auto tick = static_cast<std::int64_t>(std::floor(time_s * options_.fps + 1e-3));
    if (tick <= last_tick_) return false;
    last_tick_ = tick;
  }
  KINEMO_RETURN_IF_ERROR(poser_->Pose(values, &pose_));
  writer_.Begin();
  static constexpr std::array<float, 7> kRoot = {0, 0, 0, 0, 0, 0, 1};
  KINEMO_RETURN_IF_ERROR(writer_.Add("/VMC/Ext/Root/Pos", "root", kRoot));
  const auto bones = poser_->bones();
  for (std::size_t i = 0; i < bones.size(); ++i) {
    const Eigen::Vector3d p = i == 0 ? pose_.hips_position_m : bones[i].local_position_m;
    const Eigen::Quaterniond& q = pose_.local_rotation[i];
    const std::array<float, 7> v = {static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()),
                                    static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()),
                                    static_cast<float>(q.w())};
    KINEMO_RETURN_IF_ERROR(writer_.Add("/VMC/Ext/Bone/Pos", BoneName(bones[i].role, options_.bones), v));
  }
  if (face != nullptr) {
    const BlendWeights w = FaceBlendWeights(*face);
    const auto& names = BlendShapeNames(options_.blend);
    for (int k = 0; k < kNumBlendShapes; ++k) {
      KINEMO_RETURN_IF_ERROR(writer_.Add("/VMC/Ext/Blend/Val", names[k], std::span<const float>(&w[k], 1)));
    }
    KINEMO_RETURN_IF_ERROR(writer_.AddInts("/VMC/Ext/Blend/Apply", {}));
    stats_.blendshapes = kNumBlendShapes;
    ++stats_.face_frames;
  }
  static constexpr std::array<std::int32_t, 1> kLoaded = {1};
  KINEMO_RETURN_IF_ERROR(writer_.AddInts("/VMC/Ext/OK", kLoaded));
  KINEMO_RETURN_IF_ERROR(writer_.AddFloat("/VMC/Ext/T", static_cast<float>(time_s)));
  KINEMO_RETURN_IF_ERROR(writer_.End());
  for (const std::string& d : writer_.datagrams()) {
    if (sender_->Send(d)) {
      ++stats_.packets;
    } else {
      ++stats_.dropped;
    }
  }
  ++stats_.frames;
  return true;
}

}  // namespace kinemo::vmc
