#include "common/grpc/artifact_rpcs.h"

#include <algorithm>
#include <atomic>
#include <mutex>
#include <optional>
#include <set>
#include <thread>

#include "common/grpc/status_mapping.h"

namespace kinemo {

namespace cv1 = ::kinemo::common::v1;

cv1::ArtifactRef ToProto(const store::ArtifactRef& ref) {
  cv1::ArtifactRef out;
  out.set_kind(ref.kind);
  out.set_id(ref.id);
  out.set_version(ref.version);
  return out;
}

store::ArtifactRef FromProto(const cv1::ArtifactRef& ref) { return {ref.kind(), ref.id(), ref.version()}; }

cv1::ArtifactInfo ToProto(const store::ArtifactMeta& m) {
  cv1::ArtifactInfo out;
  *out.mutable_ref() = ToProto(m.ref());
  out.set_created_unix_ms(m.created_unix_ms);
  out.set_description(m.description);
  for (const auto& f : m.files) {
    auto* p = out.add_files();
    p->set_name(f.name);
    p->set_size_bytes(f.size_bytes);
  }
  out.set_size_bytes(m.size_bytes());
  for (const auto& d : m.depends_on) *out.add_depends_on() = ToProto(d);
  out.set_summary_json(m.summary_json);
  return out;
}

Status ValidateArtifactKind(std::string_view kind, const std::vector<std::string>& kinds, std::string_view field) {
  if (std::find(kinds.begin(), kinds.end(), kind) != kinds.end()) return absl::OkStatus();
  std::string known;
  for (const auto& k : kinds) known += (known.empty() ? "" : ", ") + k;
  return InvalidField(field, "'", CapMessage(std::string(kind), 64), "' is not a kind this service owns (", known, ")");
}

Status ValidateListRequest(const cv1::ListArtifactsRequest& r, const std::vector<std::string>& kinds) {
  if (!r.kind().empty()) KINEMO_RETURN_IF_ERROR(ValidateArtifactKind(r.kind(), kinds, "kind"));
  if (!r.id().empty()) KINEMO_RETURN_IF_ERROR(store::ValidateId(r.id(), "id"));
  return absl::OkStatus();
}

Status ValidateDeleteRequest(const cv1::DeleteArtifactRequest& r, const std::vector<std::string>& kinds) {
  KINEMO_RETURN_IF_ERROR(ValidateArtifactKind(r.ref().kind(), kinds, "ref.kind"));
  return store::ValidateId(r.ref().id(), "ref.id");
}

Status InRef(const Status& s) {
  const std::string m(s.message());
  if (s.ok() || !(m.rfind("id: ", 0) == 0 || m.rfind("version: ", 0) == 0)) return s;
  return Status(s.code(), kinemo::StrCat("ref.", m));
}

void AddInfos(const std::vector<store::ArtifactMeta>& metas, google::protobuf::RepeatedPtrField<cv1::ArtifactInfo>* out) {
  for (const auto& m : metas) *out->Add() = ToProto(m);
}

Status ValidatePushHeader(const cv1::PushArtifactHeader& h, const std::vector<std::string>& kinds,
                          std::uint64_t max_bytes) {
  KINEMO_RETURN_IF_ERROR(ValidateArtifactKind(h.ref().kind(), kinds, "header.ref.kind"));
  KINEMO_RETURN_IF_ERROR(store::ValidateId(h.ref().id(), "header.ref.id"));
  if (h.files_size() == 0) return InvalidField("header.files", "empty");
  if (h.files_size() > kMaxArtifactFiles) return InvalidField("header.files", "more than ", kMaxArtifactFiles, " files");
  std::set<std::string> names;
  std::uint64_t total = 0;
  for (int i = 0; i < h.files_size(); ++i) {
    const std::string field = kinemo::StrCat("header.files[", i, "].name");
    KINEMO_RETURN_IF_ERROR(store::ValidateFileName(h.files(i).name(), field));
    if (!names.insert(h.files(i).name()).second) return InvalidField(field, "'", h.files(i).name(), "' twice");
    if (h.files(i).size_bytes() > max_bytes || total + h.files(i).size_bytes() > max_bytes) {
      return absl::ResourceExhaustedError(
          kinemo::StrCat("header.files: more than ", max_bytes, " bytes (max_artifact_bytes)"));
    }
    total += h.files(i).size_bytes();
  }
  for (int i = 0; i < h.depends_on_size(); ++i) {
    const auto& d = h.depends_on(i);
    KINEMO_RETURN_IF_ERROR(store::ValidateId(d.kind(), kinemo::StrCat("header.depends_on[", i, "].kind")));
    KINEMO_RETURN_IF_ERROR(store::ValidateId(d.id(), kinemo::StrCat("header.depends_on[", i, "].id")));
  }
  if (h.description().size() > 4096) return InvalidField("header.description", "longer than 4096 bytes");
  return absl::OkStatus();
}

namespace {

class PushReactor final : public grpc::ServerReadReactor<cv1::PushArtifactRequest> {
 public:
  PushReactor(cv1::PushArtifactResponse* response, std::shared_ptr<const ArtifactPushHandler> handler)
      : response_(response), handler_(std::move(handler)) {
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {  // the client half-closed (or went away)
      End();
      return;
    }
    const Status s = Handle();
    if (!s.ok()) {
      Fail(s);
      return;
    }
    StartRead(&request_);
  }
  void OnCancel() override { cancelled_ = true; }
  void OnDone() override {
    if (worker_.joinable()) worker_.join();
    delete this;
  }

 private:
  Status Handle() {
    if (!header_) {
      if (!request_.has_header()) return InvalidField("header", "must be the first message");
      KINEMO_RETURN_IF_ERROR(ValidatePushHeader(request_.header(), handler_->kinds, handler_->max_bytes));
      if (handler_->check_header) KINEMO_RETURN_IF_ERROR(handler_->check_header(request_.header()));
      header_ = request_.header();
      KINEMO_ASSIGN_OR_RETURN(store::Draft d, handler_->store->Begin(header_->ref().kind(), header_->ref().id()));
      draft_.emplace(std::move(d));
      received_.assign(static_cast<std::size_t>(header_->files_size()), 0);
      return absl::OkStatus();
    }
    if (request_.has_header()) return InvalidField("header", "sent twice");
    if (!request_.has_chunk()) return InvalidField("message", "empty request");
    const cv1::ArtifactChunk& c = request_.chunk();
    if (c.file_index() >= static_cast<std::uint32_t>(header_->files_size())) {
      return InvalidField("chunk.file_index", c.file_index(), " but the header lists ", header_->files_size(),
                          " files");
    }
    const std::size_t i = c.file_index();
    if (c.data().size() > kMaxArtifactChunkBytes) {
      return InvalidField("chunk.data", c.data().size(), " bytes (at most ", kMaxArtifactChunkBytes, " per chunk)");
    }
    if (c.offset() != received_[i]) {
      return InvalidField("chunk.offset", c.offset(), " for file ", i, " after ", received_[i], " bytes");
    }
    const std::uint64_t declared = header_->files(static_cast<int>(i)).size_bytes();
    if (received_[i] + c.data().size() > declared) {
      return InvalidField("chunk.data", "file ", i, " ('", header_->files(static_cast<int>(i)).name(),
                          "') is longer than its declared ", declared, " bytes");
    }
    KINEMO_RETURN_IF_ERROR(draft_->Append(header_->files(static_cast<int>(i)).name(), c.data()));
    received_[i] += c.data().size();
    return absl::OkStatus();
  }

  void End() {
    if (cancelled_) {
      Finish(grpc::Status(grpc::StatusCode::CANCELLED, "cancelled by the client; nothing was stored"));
      return;
    }
    if (!header_) {
      Fail(InvalidField("header", "missing (the stream ended before it)"));
      return;
    }
    for (int i = 0; i < header_->files_size(); ++i) {
      if (received_[static_cast<std::size_t>(i)] != header_->files(i).size_bytes()) {
        Fail(InvalidField(kinemo::StrCat("header.files[", i, "]"), "'", header_->files(i).name(), "' got ",
                          received_[static_cast<std::size_t>(i)], " of ", header_->files(i).size_bytes(), " bytes"));
        return;
      }
      if (header_->files(i).size_bytes() == 0) {
        // Empty files never get a chunk: create them.
        if (Status s = draft_->WriteFile(header_->files(i).name(), ""); !s.ok()) {
          Fail(s);
          return;
        }
      }
    }
    // Validation may take a while (e.g. parsing a library): off the gRPC thread.
    worker_ = std::thread([this] {
      auto r = handler_->commit(std::move(*draft_), *header_);
      draft_.reset();
      if (!r.ok()) {
        Finish(ToGrpcStatus(r.status()));
        return;
      }
      *response_ = *std::move(r);
      response_->set_request_id(header_->request_id());
      Finish(grpc::Status::OK);
    });
  }

  void Fail(const Status& s) {
    draft_.reset();
    Finish(ToGrpcStatus(s));
  }

  cv1::PushArtifactResponse* response_;
  std::shared_ptr<const ArtifactPushHandler> handler_;
  cv1::PushArtifactRequest request_;
  std::optional<cv1::PushArtifactHeader> header_;
  std::optional<store::Draft> draft_;
  std::vector<std::uint64_t> received_;
  std::atomic<bool> cancelled_{false};
  std::thread worker_;
};

}  // namespace

grpc::ServerReadReactor<cv1::PushArtifactRequest>* NewArtifactPushReactor(
    grpc::CallbackServerContext* /*context*/, cv1::PushArtifactResponse* response,
    std::shared_ptr<const ArtifactPushHandler> handler) {
  return new PushReactor(response, std::move(handler));
}

}  // namespace kinemo
