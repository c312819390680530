// The artifact RPCs every artifact-owning service serves (PushArtifact,
// ListArtifacts, DeleteArtifact; kinemo/common/v1/artifact.proto), over the
// plain store of common/store. A service supplies what is particular to it:
// the kinds it owns, and how to validate + load a pushed draft.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "common/status/status.h"
#include "common/store/artifact_store.h"
#include "kinemo/common/v1/artifact.pb.h"

namespace kinemo {

// Store metadata -> its proto.
common::v1::ArtifactInfo ToProto(const store::ArtifactMeta& meta);
common::v1::ArtifactRef ToProto(const store::ArtifactRef& ref);
store::ArtifactRef FromProto(const common::v1::ArtifactRef& ref);

// Largest chunk accepted (bytes of data in one ArtifactChunk).
inline constexpr std::uint64_t kMaxArtifactChunkBytes = 4u << 20;
// Most files in one push.
inline constexpr int kMaxArtifactFiles = 10000;
// Default limit of a whole push (max_artifact_bytes = 0).
inline constexpr std::uint64_t kDefaultMaxArtifactBytes = 1ull << 30;

// Validates a header against the kinds a service owns and its size limit;
// INVALID_ARGUMENT naming the field (header.ref.kind, header.files[3].name,
// ...), RESOURCE_EXHAUSTED over the limit.
Status ValidatePushHeader(const common::v1::PushArtifactHeader& header,
                          const std::vector<std::string>& kinds, std::uint64_t max_bytes);

struct ArtifactPushHandler {
  store::ArtifactStore* store = nullptr;  // where drafts are staged (required)
  std::vector<std::string> kinds;          // kinds this service owns
  std::uint64_t max_bytes = kDefaultMaxArtifactBytes;
  // Called (on a worker thread) with the complete draft: validates it, commits
  // it to the store and makes it served. On error nothing must be stored (the
  // draft is discarded when it is not committed).
  std::function<StatusOr<common::v1::PushArtifactResponse>(store::Draft draft,
                                                           const common::v1::PushArtifactHeader& header)>
      commit;
};

// The PushArtifact reactor: header, then chunks in order per file (offset =
// bytes of that file received so far), each file exactly its declared size.
// Errors end the call with the message naming the field (chunk.file_index,
// chunk.offset, ...), and the draft is removed.
grpc::ServerReadReactor<common::v1::PushArtifactRequest>* NewArtifactPushReactor(
    grpc::CallbackServerContext* context, common::v1::PushArtifactResponse* response,
    std::shared_ptr<const ArtifactPushHandler> handler);

}  // namespace kinemo
