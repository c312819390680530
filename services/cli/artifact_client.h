// Client side of the artifact RPCs behind `kinemo <kind> push|ls|rm`
// (artifact_commands.h): chunked uploads of local files, listings, deletion,
// against any address that serves the kind's owner (the service itself, or a
// coordinator, which forwards).
#pragma once

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "common/status/status.h"
#include "services/cli/channel.h"
#include "kinemo/common/v1/artifact.pb.h"

namespace kinemo::cli {

// $KINEMO_SERVER, else "localhost:50050" (the local stack's coordinator, or
// the all-in-one).
std::string DefaultServer();

struct PushSpec {
  std::string kind, id;
  // (name in the artifact, local path) per file.
  std::vector<std::pair<std::string, std::string>> files;
  bool overwrite = false;
  std::string description;
  std::vector<common::v1::ArtifactRef> depends_on;
  double timeout_s = 0;  // 0 = 60 s + 1 s per 10 MB
};

// Uploads the files in 1 MiB chunks to the service that owns spec.kind.
StatusOr<common::v1::PushArtifactResponse> PushArtifact(const std::shared_ptr<grpc::Channel>& channel,
                                                        const PushSpec& spec);
StatusOr<common::v1::ListArtifactsResponse> ListArtifacts(const std::shared_ptr<grpc::Channel>& channel,
                                                          const std::string& kind, bool all_versions,
                                                          double timeout_s = 10);
StatusOr<common::v1::DeleteArtifactResponse> DeleteArtifact(const std::shared_ptr<grpc::Channel>& channel,
                                                            const common::v1::ArtifactRef& ref,
                                                            double timeout_s = 10);

// Every kind one owner ("inference", "planner", "cube_tracker") holds.
StatusOr<common::v1::ListArtifactsResponse> ListOwnerArtifacts(const std::shared_ptr<grpc::Channel>& channel,
                                                               const std::string& owner, bool all_versions,
                                                               double timeout_s = 10);

}  // namespace kinemo::cli
