// The artifact RPCs every artifact-owning service serves (PushArtifact,
// ListArtifacts, DeleteArtifact; kinemo/common/v1/artifact.proto), over the
// plain store of common/store. A service supplies what is particular to it:
// the kinds it owns, and how to validate + load a pushed draft.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
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

// INVALID_ARGUMENT naming `field` unless `kind` is one of `kinds` (the kinds
// a service owns).
Status ValidateArtifactKind(std::string_view kind, const std::vector<std::string>& kinds, std::string_view field);
// ListArtifacts: `kind` empty or one of `kinds`, `id` empty or valid.
Status ValidateListRequest(const common::v1::ListArtifactsRequest& request, const std::vector<std::string>& kinds);
// DeleteArtifact: `ref.kind` one of `kinds`, `ref.id` valid.
Status ValidateDeleteRequest(const common::v1::DeleteArtifactRequest& request,
                             const std::vector<std::string>& kinds);
// Store errors name "id" / "version"; in a DeleteArtifact answer they are
// "ref.id" / "ref.version".
Status InRef(const Status& status);
// Appends each meta as an ArtifactInfo.
void AddInfos(const std::vector<store::ArtifactMeta>& metas,
              google::protobuf::RepeatedPtrField<common::v1::ArtifactInfo>* out);

// Validates a header against the kinds a service owns and its size limit;
// INVALID_ARGUMENT naming the field (header.ref.kind, header.files[3].name,
// ...), RESOURCE_EXHAUSTED over the limit.
Status ValidatePushHeader(const common::v1::PushArtifactHeader& header,
                          const std::vector<std::string>& kinds, std::uint64_t max_bytes);

struct ArtifactPushHandler {
  store::ArtifactStore* store = nullptr;  // where drafts are staged (required)
  std::vector<std::string> kinds;          // kinds this service owns
  std::uint64_t max_bytes = kDefaultMaxArtifactBytes;
  // Optional: what the kind expects of the header (e.g. exactly one file
  // "model.kmodel"), checked before any data is accepted. INVALID_ARGUMENT
  // naming the header field.
  std::function<Status(const common::v1::PushArtifactHeader& header)> check_header;
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
