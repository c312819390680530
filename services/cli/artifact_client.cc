#include "services/cli/artifact_client.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>

#include "absl/strings/str_join.h"
#include "common/grpc/status_mapping.h"
#include "kinemo/cube_tracker/v1/cube_tracker.grpc.pb.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "services/cli/commands.h"
#include "services/cli/proto_json.h"

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

void PrintArtifacts(const cv1::ListArtifactsResponse& list, bool json, bool show_kind) {
  if (json) {
    std::printf("[");
    for (int i = 0; i < list.artifacts_size(); ++i) {
      std::printf("%s%s", i ? ",\n " : "", ProtoJson(list.artifacts(i)).c_str());
    }
    std::printf("]\n");
    return;
  }
  for (const auto& a : list.artifacts()) {
    char when[32] = "";
    const std::time_t t = static_cast<std::time_t>(a.created_unix_ms() / 1000);
    std::tm tm{};
    if (gmtime_r(&t, &tm) != nullptr) std::strftime(when, sizeof when, "%Y-%m-%d %H:%M:%SZ", &tm);
    const std::string name = show_kind ? a.ref().kind() + "/" + a.ref().id() : a.ref().id();
    std::printf("%-32s v%-3u %10.1f kB  %s  %s\n", name.c_str(), a.ref().version(),
                static_cast<double>(a.size_bytes()) / 1000.0, when, a.description().c_str());
  }
  if (list.in_memory()) std::printf("(the service has no store_dir: these live in memory only)\n");
}

namespace {

[[noreturn]] void FailArtifact(const std::string& command, const Status& status) {
  FailCommand(command, status,
              {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound, absl::StatusCode::kAlreadyExists,
               absl::StatusCode::kFailedPrecondition, absl::StatusCode::kResourceExhausted});
}

// "id" or "id@3" -> (id, version).
StatusOr<std::pair<std::string, std::uint32_t>> ParseIdVersion(const std::string& text) {
  const std::size_t at = text.find('@');
  if (at == std::string::npos) return std::make_pair(text, 0u);
  const std::string v = text.substr(at + 1);
  if (v.empty() || v.size() > 9 || v.find_first_not_of("0123456789") != std::string::npos || std::stoul(v) == 0) {
    return InvalidField("ID@VERSION", "'", text, "': the version must be a number from 1");
  }
  return std::make_pair(text.substr(0, at), static_cast<std::uint32_t>(std::stoul(v)));
}

// "Quaternius Man.glb" -> "quaternius-man".
std::string IdFromFileStem(const std::string& file) {
  std::string id = std::filesystem::path(file).stem().string();
  for (char& c : id) {
    c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    if (!((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '-')) c = '-';
  }
  return id.substr(0, 64);
}

}  // namespace

void AddArtifactCommands(CLI::App* parent, const ArtifactCommandSpec& spec) {
  struct Flags {
    std::string server = DefaultServer(), file, id, description, target;
    bool overwrite = false, json = false, all = false;
  };
  auto f = std::make_shared<Flags>();
  const std::string noun = spec.noun;

  CLI::App* push = parent->add_subcommand("push", "Upload a " + noun + " to the service that owns it");
  push->add_option("FILE", f->file, spec.file_help)->required();
  auto* id = push->add_option(spec.id_option, f->id, "the id it is stored and called by ([a-z0-9_-]{1,64})" +
                                                       std::string(spec.id_from_file_stem ? "; default: FILE's stem" : ""));
  if (!spec.id_from_file_stem) id->required();
  push->add_option("--server", f->server, "address of the stack (default $KINEMO_SERVER or localhost:50050)");
  push->add_flag("--overwrite", f->overwrite, "store a new version when the id exists");
  push->add_option("--description", f->description, "stored with it");
  push->add_flag("--json", f->json, "print the stored version's ArtifactInfo as JSON");
  push->callback([f, spec] {
    PushSpec p;
    p.kind = spec.kind;
    p.id = f->id.empty() ? IdFromFileStem(f->file) : f->id;
    if (!spec.file_extensions.empty()) {
      std::string ext = std::filesystem::path(f->file).extension().string();
      for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      if (std::find(spec.file_extensions.begin(), spec.file_extensions.end(), ext) == spec.file_extensions.end()) {
        FailArtifact(spec.noun + " push", InvalidField("FILE", f->file, " must end in ",
                                                       absl::StrJoin(spec.file_extensions, " or ")));
      }
    }
    p.files = {{spec.file_name, f->file}};
    p.overwrite = f->overwrite;
    p.description = f->description;
    auto r = PushArtifact(ServerChannel(f->server), p);
    if (!r.ok()) FailArtifact(spec.noun + " push", r.status());
    const auto& a = r->artifact();
    if (f->json) {
      std::printf("%s\n", ProtoJson(a).c_str());
    } else {
      std::printf("stored %s/%s version %u (%.1f kB) at %s\n", a.ref().kind().c_str(), a.ref().id().c_str(),
                  a.ref().version(), static_cast<double>(a.size_bytes()) / 1000.0, f->server.c_str());
    }
    for (const auto& w : r->warnings()) std::cerr << "warning: " << w << "\n";
  });

  CLI::App* ls = parent->add_subcommand("ls", "List the stored " + noun + "s (the newest version of each id)");
  ls->add_option("--server", f->server, "address of the stack (default $KINEMO_SERVER or localhost:50050)");
  ls->add_flag("--all", f->all, "every version");
  ls->add_flag("--json", f->json, "print a JSON array of ArtifactInfo");
  ls->callback([f, spec] {
    auto r = ListArtifacts(ServerChannel(f->server), spec.kind, f->all);
    if (!r.ok()) FailArtifact(spec.noun + " ls", r.status());
    PrintArtifacts(*r, f->json);
  });

  CLI::App* rm = parent->add_subcommand("rm", "Delete a " + noun + " (every version, or ID@VERSION)");
  rm->add_option("ID", f->target, "id, or id@version")->required();
  rm->add_option("--server", f->server, "address of the stack (default $KINEMO_SERVER or localhost:50050)");
  rm->callback([f, spec] {
    auto target = ParseIdVersion(f->target);
    if (!target.ok()) FailArtifact(spec.noun + " rm", target.status());
    cv1::ArtifactRef ref;
    ref.set_kind(spec.kind);
    ref.set_id(target->first);
    ref.set_version(target->second);
    auto r = DeleteArtifact(ServerChannel(f->server), ref);
    if (!r.ok()) FailArtifact(spec.noun + " rm", r.status());
    for (const auto& a : r->deleted()) {
      std::printf("deleted %s/%s version %u\n", a.ref().kind().c_str(), a.ref().id().c_str(), a.ref().version());
    }
  });
}

}  // namespace kinemo::cli
