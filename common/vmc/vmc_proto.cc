#include "common/vmc/vmc_proto.h"

#include <algorithm>
#include <cctype>

#include "common/face/face_proto.h"

namespace kinemo::vmc {

StatusOr<motion::Skeleton> SkeletonFromStreamHeader(const common::v1::MotionStreamHeader& header) {
  std::vector<motion::Joint> joints;
  const auto& skeleton = header.skeleton();
  for (int i = 0; i < skeleton.joints_size(); ++i) {
    const auto& pj = skeleton.joints(i);
    motion::Joint j;
    j.name = pj.name();
    j.parent = pj.parent_index();
    j.offset = {pj.offset().x(), pj.offset().y(), pj.offset().z()};
    for (int c : pj.channels()) {
      if (c < common::v1::CHANNEL_X_POSITION || c > common::v1::CHANNEL_Z_ROTATION) {
        return InvalidField(kinemo::StrCat("header.skeleton.joints[", i, "].channels"), "channel ", c, " is not valid");
      }
      j.channels.push_back(static_cast<motion::ChannelType>(c - common::v1::CHANNEL_X_POSITION));
    }
    joints.push_back(std::move(j));
  }
  auto made = motion::Skeleton::Create(std::move(joints));
  if (!made.ok()) return Annotate(made.status(), "header.skeleton");
  return made;
}

Status ProtoVmcStream::OnHeader(const common::v1::MotionStreamHeader& header) {
  KINEMO_ASSIGN_OR_RETURN(motion::Skeleton skeleton, SkeletonFromStreamHeader(header));
  channels_ = skeleton.num_channels();
  return Annotate(stream_->Start(skeleton, header.skeleton().meters_per_unit()), "header.skeleton");
}

StatusOr<bool> ProtoVmcStream::OnFrame(const common::v1::MotionFrame& frame) {
  if (!stream_->started()) return absl::FailedPreconditionError("frames: a frame before the header");
  if (frame.values_size() != channels_) {
    return InvalidField("frames.values", frame.values_size(), " values, the skeleton has ", channels_, " channels");
  }
  if (frame.has_face()) {
    const face::FaceFrame face = face::FromProto(frame.face());
    return stream_->SendFrame(frame.time_s(), {frame.values().data(), static_cast<size_t>(frame.values_size())}, &face);
  }
  return stream_->SendFrame(frame.time_s(), {frame.values().data(), static_cast<size_t>(frame.values_size())}, nullptr);
}

StatusOr<std::unique_ptr<ProtoVmcStream>> OpenVmcTarget(const coordinator::v1::VmcTarget& target,
                                                        const std::vector<std::string>& allowed_hosts,
                                                        std::string_view field) {
  namespace cv1 = ::kinemo::coordinator::v1;
  KINEMO_ASSIGN_OR_RETURN(Endpoint endpoint, ParseEndpoint(target.address(), kinemo::StrCat(field, ".address")));
  VmcStreamOptions o;
  o.bones = target.bone_names() == cv1::VMC_BONE_NAMES_VRM1 ? BoneNaming::kVrm1 : BoneNaming::kUnity;
  const bool vrm1_blend = target.blend_names() == cv1::VMC_BLEND_NAMES_VRM1 ||
                          (target.blend_names() == cv1::VMC_BLEND_NAMES_UNSPECIFIED && o.bones == BoneNaming::kVrm1);
  o.blend = vrm1_blend ? BlendNaming::kVrm1 : BlendNaming::kVrm0;
  o.fps = target.fps();
  KINEMO_RETURN_IF_ERROR(ValidateVmcOptions(o, kinemo::StrCat(field, ".fps")));
  auto lower = [](std::string s) {
    for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return s;
  };
  bool named = false;
  for (const std::string& h : allowed_hosts) named = named || h == "*" || lower(h) == lower(endpoint.host);
  KINEMO_ASSIGN_OR_RETURN(std::unique_ptr<UdpSender> sender,
                          UdpSender::Open(endpoint, /*loopback_only=*/!named, kinemo::StrCat(field, ".address")));
  return std::make_unique<ProtoVmcStream>(std::make_unique<VmcStream>(std::move(sender), o));
}

}  // namespace kinemo::vmc
