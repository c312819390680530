// The planner's artifact store: opening it at start (seed import, then every
// stored artifact served, libraries first), the helpers the areas use to
// commit what they build, and the RPCs PushArtifact, ListArtifacts and
// DeleteArtifact. Layout and kinds: docs/store.md.
#include <stdlib.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <google/protobuf/text_format.h>
#include <google/protobuf/util/json_util.h>

#include "common/config/options.h"
#include "common/grpc/status_mapping.h"
#include "common/logging/log.h"
#include "services/planner/rpc/planner_service.h"

namespace kinemo::planner {
namespace {

namespace fs = std::filesystem;
namespace cv1 = ::kinemo::common::v1;

constexpr std::uint64_t kMaxArtifactTextBytes = 16u << 20;

double SecondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

std::string SummaryJson(const google::protobuf::Message& message) {
  std::string out;
  google::protobuf::util::JsonPrintOptions o;
  o.preserve_proto_field_names = true;
  if (!google::protobuf::util::MessageToJsonString(message, &out, o).ok()) return "{}";
  return out;
}

Status PushError(const Status& status, const store::Draft& draft, std::string_view field) {
  std::string message(status.message());
  const std::string prefix = draft.dir() + "/";
  for (size_t at = message.find(prefix); at != std::string::npos; at = message.find(prefix, at)) {
    message.erase(at, prefix.size());
  }
  if (field.empty()) return Status(status.code(), message);
  return Status(status.code(), kinemo::StrCat(field, ": ", message));
}

StatusOr<int> LibraryDependency(const cv1::PushArtifactHeader& header) {
  int found = -1;
  for (int i = 0; i < header.depends_on_size(); ++i) {
    if (header.depends_on(i).kind() != store::kLibraries) continue;
    if (found >= 0) return InvalidField("header.depends_on", "names more than one library");
    found = i;
  }
  return found;
}

PlannerServiceImpl::~PlannerServiceImpl() {
  if (temporary_store_dir_.empty()) return;
  store_.reset();
  std::error_code ec;
  fs::remove_all(temporary_store_dir_, ec);
}

Status PlannerServiceImpl::OpenStore() {
  std::string root = options_.store_dir();
  if (root.empty()) {
    // In memory only: the same code path over a temporary store.
    std::error_code ec;
    std::string pattern = (fs::temp_directory_path(ec) / "kinemo-planner-XXXXXX").string();
    if (::mkdtemp(pattern.data()) == nullptr) {
      return absl::FailedPreconditionError(
          kinemo::StrCat("store_dir: empty, and no temporary store could be created: ", std::strerror(errno)));
    }
    temporary_store_dir_ = root = pattern;
  }
  KINEMO_ASSIGN_OR_RETURN(store_, store::ArtifactStore::Open(root, "store_dir"));
  kinds_ = {LibraryKind(), ControllerKind(), GestureGraphKind(), LocomotionGraphKind(), RigKind()};

  auto handler = std::make_shared<ArtifactPushHandler>();
  handler->store = store_.get();
  for (const auto& k : kinds_) handler->kinds.push_back(k.kind);
  if (options_.max_artifact_bytes() > 0) handler->max_bytes = options_.max_artifact_bytes();
  handler->commit = [this](store::Draft draft, const cv1::PushArtifactHeader& header) {
    // The reactor has checked that the kind is one of ours.
    return FindKind(header.ref().kind())->push(std::move(draft), header);
  };
  push_handler_ = std::move(handler);

  const auto t0 = std::chrono::steady_clock::now();
  if (!options_.seed_store_dir().empty()) {
    for (const auto& k : kinds_) {
      auto imported = store_->ImportSeed(options_.seed_store_dir(), k.kind);
      if (!imported.ok()) {
        log::Warn("seed_failed", {{"kind", k.kind}, {"error", std::string(imported.status().message())}});
        continue;
      }
      for (const auto& m : *imported) {
        log::Info("artifact_seeded", {{"artifact", store::RefString(m.ref())}, {"seed", options_.seed_store_dir()}});
      }
    }
  }
  // Newest version of each id, in dependency order. An artifact that does
  // not load is skipped: the rest is served.
  int loaded = 0, skipped = 0;
  for (const auto& k : kinds_) {
    auto newest = store_->List(k.kind);
    if (!newest.ok()) {
      log::Warn("artifact_list_failed", {{"kind", k.kind}, {"error", std::string(newest.status().message())}});
      continue;
    }
    for (const auto& m : *newest) {
      const auto t = std::chrono::steady_clock::now();
      const Status s = k.serve(m);
      if (s.ok()) {
        ++loaded;
        log::Info("artifact_loaded", {{"artifact", store::RefString(m.ref())}, {"load_s", SecondsSince(t)}});
      } else {
        ++skipped;
        log::Error("artifact_skipped", {{"artifact", store::RefString(m.ref())}, {"error", std::string(s.message())}});
      }
    }
  }
  log::Info("store_opened", {{"store_dir", store_->root()},
                             {"in_memory", !temporary_store_dir_.empty()},
                             {"loaded", loaded},
                             {"skipped", skipped},
                             {"load_s", SecondsSince(t0)}});
  return absl::OkStatus();
}

const PlannerServiceImpl::ArtifactKind* PlannerServiceImpl::FindKind(std::string_view kind) const {
  for (const auto& k : kinds_) {
    if (k.kind == kind) return &k;
  }
  return nullptr;
}

Status PlannerServiceImpl::CheckNewVersion(std::string_view kind, const std::string& id, bool overwrite,
                                           std::string_view field) const {
  if (overwrite) return absl::OkStatus();
  auto existing = store_->Get(kind, id);
  if (!existing.ok()) return absl::OkStatus();
  return absl::AlreadyExistsError(kinemo::StrCat(field, ": '", id, "' exists (version ", existing->version,
                                                 "; set overwrite for a new version)"));
}

StatusOr<store::ArtifactMeta> PlannerServiceImpl::CommitArtifact(store::Draft draft, store::ArtifactMeta meta,
                                                                 bool overwrite, std::string_view field,
                                                                 const std::function<void(int)>& install) {
  const std::string kind = draft.kind(), id = draft.id();
  std::lock_guard lock(store_mu_);
  for (const auto& d : meta.depends_on) {
    if (!store_->Get(d.kind, d.id, d.version).ok()) {
      return absl::FailedPreconditionError(
          kinemo::StrCat(field, ": ", store::RefString(d), " was deleted while this was being built"));
    }
  }
  auto committed = store_->Commit(std::move(draft), std::move(meta), overwrite);
  if (!committed.ok()) {
    if (absl::IsAlreadyExists(committed.status())) return CheckNewVersion(kind, id, false, field);
    return committed.status();
  }
  install(static_cast<int>(committed->version));
  log::Info("artifact_stored", {{"artifact", store::RefString(committed->ref())},
                                {"size_bytes", static_cast<std::int64_t>(committed->size_bytes())}});
  return committed;
}

StatusOr<std::string> PlannerServiceImpl::ReadArtifactFile(const std::string& path, std::string_view field) {
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  if (ec) return absl::NotFoundError(kinemo::StrCat(field, ": cannot read (", ec.message(), ")"));
  if (size > kMaxArtifactTextBytes) return InvalidField(field, size, " bytes (at most ", kMaxArtifactTextBytes, ")");
  std::ifstream in(path, std::ios::binary);
  std::string text(size, '\0');
  if (!in.read(text.data(), static_cast<std::streamsize>(size))) {
    return absl::DataLossError(kinemo::StrCat(field, ": cannot read"));
  }
  return text;
}

StatusOr<store::Draft> PlannerServiceImpl::WriteRecipe(std::string_view kind, const std::string& id,
                                                       const google::protobuf::Message& recipe, const Library& library,
                                                       std::string description, std::string summary_json,
                                                       store::ArtifactMeta* meta) {
  KINEMO_ASSIGN_OR_RETURN(store::Draft draft, store_->Begin(kind, id));
  std::string text;
  if (!google::protobuf::TextFormat::PrintToString(recipe, &text)) {
    return absl::InternalError(kinemo::StrCat(kind, "/", id, ": cannot print the recipe"));
  }
  KINEMO_RETURN_IF_ERROR(draft.WriteFile(
      kGraphRecipeFile, kinemo::StrCat("# ", recipe.GetDescriptor()->full_name(), ", rebuilt at start on library '",
                                       library.id, "' version ", library.version, "\n", text)));
  *meta = store::ArtifactMeta();
  meta->description = std::move(description);
  meta->depends_on.push_back(
      {std::string(store::kLibraries), library.id, static_cast<std::uint32_t>(library.version)});
  meta->summary_json = std::move(summary_json);
  return draft;
}

StatusOr<std::shared_ptr<const Library>> PlannerServiceImpl::ReadStoredRecipe(const store::ArtifactMeta& meta,
                                                                              google::protobuf::Message* recipe) {
  const std::string path = store_->FilePath(meta.ref(), kGraphRecipeFile);
  KINEMO_ASSIGN_OR_RETURN(std::string text, ReadArtifactFile(path, path));
  KINEMO_RETURN_IF_ERROR(config::ParseTextProto(text, path, recipe));
  return DependencyLibrary(meta);
}

StatusOr<std::shared_ptr<const Library>> PlannerServiceImpl::ReadPushedRecipe(
    const store::Draft& draft, const cv1::PushArtifactHeader& header, google::protobuf::Message* recipe) {
  if (header.files_size() != 1 || header.files(0).name() != kGraphRecipeFile) {
    return InvalidField("header.files", "a graph is one ", kGraphRecipeFile, " (a ",
                        recipe->GetDescriptor()->name(), ")");
  }
  KINEMO_ASSIGN_OR_RETURN(std::string text,
                          ReadArtifactFile(kinemo::StrCat(draft.dir(), "/", kGraphRecipeFile), "header.files[0]"));
  if (Status s = config::ParseTextProto(text, kGraphRecipeFile, recipe); !s.ok()) {
    return Annotate(s, "header.files[0]");
  }
  KINEMO_RETURN_IF_ERROR(CheckNewVersion(draft.kind(), header.ref().id(), header.overwrite(), "header.ref.id"));
  const auto* library_field = recipe->GetDescriptor()->FindFieldByName("library_id");
  std::string library_id = library_field != nullptr ? recipe->GetReflection()->GetString(*recipe, library_field) : "";
  KINEMO_ASSIGN_OR_RETURN(int dep, LibraryDependency(header));
  if (dep < 0) {
    if (library_id.empty()) return InvalidField("header.depends_on", "name the library (or library_id in the recipe)");
    return StoredLibrary(library_id, 0, kinemo::StrCat("header.files[0]: ", kGraphRecipeFile, ": library_id"));
  }
  const std::string field = kinemo::StrCat("header.depends_on[", dep, "]");
  const cv1::ArtifactRef& d = header.depends_on(dep);
  if (!library_id.empty() && library_id != d.id()) {
    return InvalidField(field, "library '", d.id(), "' but ", kGraphRecipeFile, " names '", library_id, "'");
  }
  return StoredLibrary(d.id(), d.version(), field);
}

// ---- RPCs --------------------------------------------------------------------

grpc::ServerReadReactor<cv1::PushArtifactRequest>* PlannerServiceImpl::PushArtifact(
    grpc::CallbackServerContext* ctx, cv1::PushArtifactResponse* response) {
  return NewArtifactPushReactor(ctx, response, push_handler_);
}

grpc::ServerUnaryReactor* PlannerServiceImpl::ListArtifacts(grpc::CallbackServerContext* ctx,
                                                            const cv1::ListArtifactsRequest* request,
                                                            cv1::ListArtifactsResponse* response) {
  auto run = [&]() -> Status {
    std::vector<std::string> kinds;
    if (request->kind().empty()) {
      for (const auto& k : kinds_) kinds.push_back(k.kind);
      std::sort(kinds.begin(), kinds.end());  // the listing is sorted by kind, id, version
    } else if (FindKind(request->kind()) != nullptr) {
      kinds.push_back(request->kind());
    } else {
      return InvalidField("kind", "'", CapMessage(request->kind(), 64),
                          "' is not a planner kind (libraries, controllers, gesture_graphs, locomotion_graphs)");
    }
    if (!request->id().empty()) KINEMO_RETURN_IF_ERROR(store::ValidateId(request->id(), "id"));
    const bool in_memory = !temporary_store_dir_.empty();
    for (const auto& kind : kinds) {
      KINEMO_ASSIGN_OR_RETURN(auto metas, store_->List(kind, request->id(), request->all_versions()));
      for (const auto& m : metas) {
        cv1::ArtifactInfo* info = response->add_artifacts();
        *info = kinemo::ToProto(m);
        if (in_memory) info->clear_files();  // they live in a temporary folder
      }
    }
    response->set_in_memory(in_memory);
    return absl::OkStatus();
  };
  return FinishUnary(ctx, run());
}

grpc::ServerUnaryReactor* PlannerServiceImpl::DeleteArtifact(grpc::CallbackServerContext* ctx,
                                                             const cv1::DeleteArtifactRequest* request,
                                                             cv1::DeleteArtifactResponse* response) {
  auto run = [&]() -> Status {
    const cv1::ArtifactRef& ref = request->ref();
    const ArtifactKind* kind = FindKind(ref.kind());
    if (kind == nullptr) {
      return InvalidField("ref.kind", "'", CapMessage(ref.kind(), 64),
                          "' is not a planner kind (libraries, controllers, gesture_graphs, locomotion_graphs)");
    }
    KINEMO_RETURN_IF_ERROR(store::ValidateId(ref.id(), "ref.id"));
    std::lock_guard lock(store_mu_);
    if (ref.kind() == store::kLibraries) {
      // Controllers and graphs hold on to the library version they were built on.
      for (const auto& other : kinds_) {
        if (other.kind == store::kLibraries) continue;
        KINEMO_ASSIGN_OR_RETURN(auto metas, store_->List(other.kind, "", /*all_versions=*/true));
        for (const auto& m : metas) {
          for (const auto& d : m.depends_on) {
            if (d.kind == store::kLibraries && d.id == ref.id() && (ref.version() == 0 || d.version == ref.version())) {
              return absl::FailedPreconditionError(kinemo::StrCat("ref: ", store::RefString(d), " is used by ",
                                                                  store::RefString(m.ref()), " (delete that first)"));
            }
          }
        }
      }
    }
    auto deleted = store_->Delete(ref.kind(), ref.id(), ref.version());
    if (!deleted.ok()) return Status(deleted.status().code(), kinemo::StrCat("ref.", deleted.status().message()));
    // Serve what is left: the newest remaining version, or nothing.
    const std::string id = ref.id();
    auto newest = store_->Get(ref.kind(), id);
    if (!newest.ok()) {
      kind->unserve(id);
    } else if (kind->served_version(id) != static_cast<int>(newest->version)) {
      if (const Status s = kind->serve(*newest); !s.ok()) {
        kind->unserve(id);
        log::Error("artifact_skipped", {{"artifact", store::RefString(newest->ref())}, {"error", std::string(s.message())}});
      }
    }
    for (const auto& m : *deleted) {
      *response->add_deleted() = kinemo::ToProto(m);
      log::Info("artifact_deleted", {{"artifact", store::RefString(m.ref())}});
    }
    return absl::OkStatus();
  };
  return FinishUnary(ctx, run());
}

}  // namespace kinemo::planner
