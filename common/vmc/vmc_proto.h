// A live stream's messages (kinemo.common.v1.MotionStreamHeader and
// MotionFrame, with their FaceFrame) into a VmcStream: what the CLI's
// StreamAnimate client, the coordinator and the studio share.
#pragma once

#include <memory>
#include <vector>
#include <string>

#include "common/status/status.h"
#include "common/vmc/vmc_stream.h"
#include "kinemo/common/v1/motion.pb.h"
#include "kinemo/coordinator/v1/coordinator.pb.h"

namespace kinemo::vmc {

// The stream's skeleton; INVALID_ARGUMENT naming "header.skeleton..." when bad.
StatusOr<motion::Skeleton> SkeletonFromStreamHeader(const common::v1::MotionStreamHeader& header);

class ProtoVmcStream {
 public:
  explicit ProtoVmcStream(std::unique_ptr<VmcStream> stream) : stream_(std::move(stream)) {}
  // The header: the humanoid of its skeleton (its meters_per_unit when set,
  // else estimated; the options' role map).
  Status OnHeader(const common::v1::MotionStreamHeader& header);
  // A frame (after the header): true when sent (the fps limit may skip it).
  // Its face goes out as blend shapes when it has one.
  StatusOr<bool> OnFrame(const common::v1::MotionFrame& frame);
  const VmcStream& stream() const { return *stream_; }

 private:
  std::unique_ptr<VmcStream> stream_;
  int channels_ = 0;
};

// A StreamAnimate's VMC target (StreamAnimateConfig.vmc) opened: loopback
// addresses only, unless `allowed_hosts` names the host as written (case
// aside) or holds "*". Errors name `field` ("config.vmc") and its members:
// INVALID_ARGUMENT (.address malformed, .fps out of range), NOT_FOUND (the
// host does not resolve), PERMISSION_DENIED (.address not allowed).
StatusOr<std::unique_ptr<ProtoVmcStream>> OpenVmcTarget(const coordinator::v1::VmcTarget& target,
                                                        const std::vector<std::string>& allowed_hosts,
                                                        std::string_view field);

}  // namespace kinemo::vmc
