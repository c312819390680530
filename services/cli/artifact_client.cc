#include "services/cli/artifact_client.h"

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "common/grpc/status_mapping.h"
#include "kinemo/cube_tracker/v1/cube_tracker.grpc.pb.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"

namespace kinemo::cli {
namespace {

namespace cv1 = ::kinemo::common::v1;
namespace fs = std::filesystem;

constexpr std::size_t kChunkBytes = 1 << 20;

std::chrono::system_clock::time_point After(double s) {
  return std::chrono::system_clock::now() + std::chrono::milliseconds(static_cast<long long>(s * 1000));
}

// Which service owns a kind: "inference", "planner", "cube_tracker", or "".
std::string OwnerOf(const std::string& kind) {
  if (kind == "models") return "inference";
  if (kind == "libraries" || kind == "controllers" || kind == "gesture_graphs" || kind == "locomotion_graphs" ||
      kind == "rigs")
    return "planner";
  if (kind == "cubes") return "cube_tracker";
  return "";
}

template <typename Service>
StatusOr<cv1::PushArtifactResponse> PushVia(const std::shared_ptr<grpc::Channel>& channel, const PushSpec& spec,
                                            const cv1::PushArtifactHeader& header, double timeout_s,
                                            const std::string& owner) {
  auto stub = Service::NewStub(channel);
  grpc::ClientContext ctx;
  ctx.set_deadline(After(timeout_s));
  cv1::PushArtifactResponse response;
  auto writer = stub->PushArtifact(&ctx, &response);
  cv1::PushArtifactRequest first;
  *first.mutable_header() = header;
  bool ok = writer->Write(first);
  std::string buffer(kChunkBytes, '\0');
  for (std::size_t i = 0; ok && i < spec.files.size(); ++i) {
    std::ifstream in(spec.files[i].second, std::ios::binary);
    std::uint64_t offset = 0;
    while (ok && in) {
      in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
      const auto n = static_cast<std::size_t>(in.gcount());
      if (n == 0) break;
      cv1::PushArtifactRequest q;
      q.mutable_chunk()->set_file_index(static_cast<std::uint32_t>(i));
      q.mutable_chunk()->set_offset(offset);
      q.mutable_chunk()->set_data(buffer.data(), n);
      offset += n;
      ok = writer->Write(q);
    }
  }
  if (ok) writer->WritesDone();
  const grpc::Status s = writer->Finish();
  if (!s.ok()) return FromGrpcStatus(s, owner);
  return response;
}

// ListArtifacts of `owner` ("inference", "planner" or "cube_tracker"); kind "" = all it owns.
StatusOr<cv1::ListArtifactsResponse> ListAt(const std::shared_ptr<grpc::Channel>& channel, const std::string& owner,
                                            const std::string& kind, bool all_versions, double timeout_s) {
  cv1::ListArtifactsRequest req;
  req.set_kind(kind);
  req.set_all_versions(all_versions);
  cv1::ListArtifactsResponse resp;
  grpc::ClientContext ctx;
  ctx.set_deadline(After(timeout_s));
  grpc::Status s;
  if (owner == "inference") {
    s = inference::v1::InferenceService::NewStub(channel)->ListArtifacts(&ctx, req, &resp);
  } else if (owner == "planner") {
    s = planner::v1::PlannerService::NewStub(channel)->ListArtifacts(&ctx, req, &resp);
  } else {
    s = cube_tracker::v1::CubeTrackerService::NewStub(channel)->ListArtifacts(&ctx, req, &resp);
  }
  if (!s.ok()) return FromGrpcStatus(s, owner);
  return resp;
}

}  // namespace

std::string DefaultServer() {
  if (const char* env = std::getenv("KINEMO_SERVER"); env != nullptr && *env) return env;
  return "localhost:50050";
}

StatusOr<cv1::PushArtifactResponse> PushArtifact(const std::shared_ptr<grpc::Channel>& channel,
                                                 const PushSpec& spec) {
  const std::string owner = OwnerOf(spec.kind);
  if (owner.empty()) return InvalidField("kind", "'", spec.kind, "' is not an artifact kind");
  cv1::PushArtifactHeader header;
  header.mutable_ref()->set_kind(spec.kind);
  header.mutable_ref()->set_id(spec.id);
  header.set_overwrite(spec.overwrite);
  header.set_description(spec.description);
  for (const auto& d : spec.depends_on) *header.add_depends_on() = d;
  std::uint64_t total = 0;
  for (const auto& [name, path] : spec.files) {
    std::error_code ec;
    const auto size = fs::file_size(path, ec);
    if (ec) return absl::NotFoundError(kinemo::StrCat(path, ": cannot read (", ec.message(), ")"));
    auto* f = header.add_files();
    f->set_name(name);
    f->set_size_bytes(size);
    total += size;
  }
  const double timeout_s = spec.timeout_s > 0 ? spec.timeout_s : 60.0 + static_cast<double>(total) / 10e6;
  if (owner == "inference") return PushVia<inference::v1::InferenceService>(channel, spec, header, timeout_s, owner);
  if (owner == "planner") return PushVia<planner::v1::PlannerService>(channel, spec, header, timeout_s, owner);
  return PushVia<cube_tracker::v1::CubeTrackerService>(channel, spec, header, timeout_s, owner);
}

StatusOr<cv1::ListArtifactsResponse> ListArtifacts(const std::shared_ptr<grpc::Channel>& channel,
                                                   const std::string& kind, bool all_versions, double timeout_s) {
  const std::string owner = OwnerOf(kind);
  if (owner.empty()) return InvalidField("kind", "'", kind, "' is not an artifact kind");
  return ListAt(channel, owner, kind, all_versions, timeout_s);
}

StatusOr<cv1::DeleteArtifactResponse> DeleteArtifact(const std::shared_ptr<grpc::Channel>& channel,
                                                     const cv1::ArtifactRef& ref, double timeout_s) {
  const std::string owner = OwnerOf(ref.kind());
  if (owner.empty()) return InvalidField("kind", "'", ref.kind(), "' is not an artifact kind");
  cv1::DeleteArtifactRequest req;
  *req.mutable_ref() = ref;
  cv1::DeleteArtifactResponse resp;
  grpc::ClientContext ctx;
  ctx.set_deadline(After(timeout_s));
  grpc::Status s;
  if (owner == "inference") {
    s = inference::v1::InferenceService::NewStub(channel)->DeleteArtifact(&ctx, req, &resp);
  } else if (owner == "planner") {
    s = planner::v1::PlannerService::NewStub(channel)->DeleteArtifact(&ctx, req, &resp);
  } else {
    s = cube_tracker::v1::CubeTrackerService::NewStub(channel)->DeleteArtifact(&ctx, req, &resp);
  }
  if (!s.ok()) return FromGrpcStatus(s, owner);
  return resp;
}

StatusOr<cv1::ListArtifactsResponse> ListOwnerArtifacts(const std::shared_ptr<grpc::Channel>& channel,
                                                        const std::string& owner, bool all_versions,
                                                        double timeout_s) {
  if (owner != "inference" && owner != "planner" && owner != "cube_tracker") {
    return InvalidField("owner", "'", owner, "' owns no artifacts");
  }
  return ListAt(channel, owner, "", all_versions, timeout_s);
}

}  // namespace kinemo::cli
