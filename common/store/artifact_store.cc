#include "common/store/artifact_store.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "common/json/json_fields.h"

namespace kinemo::store {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr std::string_view kMetaFile = "artifact.json";
constexpr std::string_view kStaging = ".staging";
constexpr std::size_t kMaxMetaBytes = 4 << 20;

bool IdChar(char c) { return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '-'; }

bool FileChar(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
         c == '_' || c == '-';
}

// Flushes a file or folder to disk (best effort on file systems without it).
void Sync(const fs::path& p, bool directory) {
  const int fd = ::open(p.c_str(), directory ? (O_RDONLY | O_DIRECTORY) : O_RDONLY);
  if (fd < 0) return;
  (void)::fsync(fd);
  ::close(fd);
}

void SyncTree(const fs::path& dir) {
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::recursive_directory_iterator();
       it.increment(ec)) {
    Sync(it->path(), it->is_directory());
  }
  Sync(dir, true);
}

bool ParseVersion(const std::string& name, std::uint32_t* version) {
  if (name.empty() || name.size() > 9 || name[0] == '0') return false;
  if (!std::all_of(name.begin(), name.end(), [](char c) { return c >= '0' && c <= '9'; })) return false;
  *version = static_cast<std::uint32_t>(std::stoul(name));
  return *version > 0;
}

std::string RandomSuffix() {
  static thread_local std::mt19937_64 rng(std::random_device{}() ^
                                          static_cast<std::uint64_t>(::getpid()) << 20);
  std::ostringstream s;
  s << std::hex << rng();
  return s.str();
}

StatusOr<std::string> ReadSmallFile(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) return absl::NotFoundError(kinemo::StrCat(p.string(), ": cannot read"));
  std::string out;
  char buf[65536];
  while (in.read(buf, sizeof buf) || in.gcount() > 0) {
    out.append(buf, static_cast<std::size_t>(in.gcount()));
    if (out.size() > kMaxMetaBytes) return absl::InvalidArgumentError(kinemo::StrCat(p.string(), ": too large"));
  }
  return out;
}

std::int64_t NowUnixMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace

bool IsValidId(std::string_view id) {
  return !id.empty() && id.size() <= 64 && std::all_of(id.begin(), id.end(), IdChar);
}

Status ValidateId(std::string_view id, std::string_view field) {
  if (IsValidId(id)) return absl::OkStatus();
  std::string shown(id.substr(0, 80));
  for (char& c : shown) {
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) >= 0x7f) c = '?';
  }
  return InvalidField(field, "'", shown, "' must be 1..64 characters of [a-z0-9_-]");
}

Status ValidateFileName(std::string_view name, std::string_view field) {
  auto bad = [&](std::string_view why) { return InvalidField(field, why); };
  if (name.empty() || name.size() > 512) return bad("must be 1..512 characters");
  if (name == kMetaFile) return bad("'artifact.json' is reserved");
  std::size_t start = 0;
  while (start <= name.size()) {
    const std::size_t slash = name.find('/', start);
    const std::string_view part = name.substr(start, slash == std::string_view::npos ? std::string_view::npos : slash - start);
    if (part.empty() || part.size() > 128 || part[0] == '.' || !std::all_of(part.begin(), part.end(), FileChar)) {
      return bad("each path part must be 1..128 characters of [A-Za-z0-9._-], not starting with '.'");
    }
    if (slash == std::string_view::npos) break;
    start = slash + 1;
  }
  return absl::OkStatus();
}

std::uint64_t ArtifactMeta::size_bytes() const {
  std::uint64_t n = 0;
  for (const auto& f : files) n += f.size_bytes;
  return n;
}

std::string RefString(const ArtifactRef& ref) { return kinemo::StrCat(ref.kind, "/", ref.id, "/", ref.version); }

std::string MetaToJson(const ArtifactMeta& m) {
  json j;
  j["kind"] = m.kind;
  j["id"] = m.id;
  j["version"] = m.version;
  j["created_unix_ms"] = m.created_unix_ms;
  j["description"] = m.description;
  json files = json::array();
  for (const auto& f : m.files) files.push_back({{"name", f.name}, {"size_bytes", f.size_bytes}});
  j["files"] = std::move(files);
  json deps = json::array();
  for (const auto& d : m.depends_on) deps.push_back({{"kind", d.kind}, {"id", d.id}, {"version", d.version}});
  j["depends_on"] = std::move(deps);
  json summary = json::parse(m.summary_json.empty() ? "{}" : m.summary_json, nullptr, false);
  j["summary"] = summary.is_discarded() ? json::object() : summary;
  if (m.seeded) j["seeded"] = true;
  return j.dump(2) + "\n";
}

StatusOr<ArtifactMeta> MetaFromJson(std::string_view text, std::string_view source) {
  const json j = json::parse(text.begin(), text.end(), nullptr, false);
  auto bad = [&](std::string_view why) {
    return absl::InvalidArgumentError(kinemo::StrCat(source, ": ", why));
  };
  if (j.is_discarded() || !j.is_object()) return bad("not a JSON object");
  const std::string prefix = kinemo::StrCat(source, ": ");
  ArtifactMeta m;
  try {
    m.kind = j.at("kind").get<std::string>();
    m.id = j.at("id").get<std::string>();
    KINEMO_ASSIGN_OR_RETURN(m.version,
                            JsonInteger<std::uint32_t>(j, "version", std::nullopt, prefix, 1));
    KINEMO_ASSIGN_OR_RETURN(m.created_unix_ms,
                            JsonInteger<std::int64_t>(j, "created_unix_ms", 0, prefix));
    m.description = j.value("description", std::string());
    int i = 0;
    for (const auto& f : j.value("files", json::array())) {
      if (!f.is_object()) return bad(kinemo::StrCat("files[", i, "]: not an object"));
      const std::string where = kinemo::StrCat(prefix, "files[", i++, "].");
      KINEMO_ASSIGN_OR_RETURN(std::uint64_t size,
                              JsonInteger<std::uint64_t>(f, "size_bytes", 0, where));
      m.files.push_back({f.at("name").get<std::string>(), size});
    }
    i = 0;
    for (const auto& d : j.value("depends_on", json::array())) {
      if (!d.is_object()) return bad(kinemo::StrCat("depends_on[", i, "]: not an object"));
      const std::string where = kinemo::StrCat(prefix, "depends_on[", i++, "].");
      KINEMO_ASSIGN_OR_RETURN(std::uint32_t version,
                              JsonInteger<std::uint32_t>(d, "version", 0, where));
      m.depends_on.push_back(
          {d.at("kind").get<std::string>(), d.at("id").get<std::string>(), version});
    }
    m.summary_json = j.contains("summary") ? j["summary"].dump() : "{}";
    m.seeded = j.value("seeded", false);
  } catch (const json::exception& e) {
    return bad(e.what());
  }
  if (!IsValidId(m.kind) || !IsValidId(m.id) || m.version == 0) return bad("kind, id or version invalid");
  return m;
}

// ---- Draft ------------------------------------------------------------------

Draft::Draft(Draft&& o) noexcept : kind_(std::move(o.kind_)), id_(std::move(o.id_)), dir_(std::move(o.dir_)) {
  o.dir_.clear();
}

Draft& Draft::operator=(Draft&& o) noexcept {
  if (this != &o) {
    if (!dir_.empty()) {
      std::error_code ec;
      fs::remove_all(dir_, ec);
    }
    kind_ = std::move(o.kind_);
    id_ = std::move(o.id_);
    dir_ = std::move(o.dir_);
    o.dir_.clear();
  }
  return *this;
}

Draft::~Draft() {
  if (!dir_.empty()) {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
}

StatusOr<std::string> Draft::PathFor(std::string_view name) const {
  KINEMO_RETURN_IF_ERROR(ValidateFileName(name, "file name"));
  return (fs::path(dir_) / std::string(name)).string();
}

Status Draft::WriteFile(std::string_view name, std::string_view bytes) {
  KINEMO_ASSIGN_OR_RETURN(std::string path, PathFor(name));
  std::error_code ec;
  fs::create_directories(fs::path(path).parent_path(), ec);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return absl::PermissionDeniedError(kinemo::StrCat(name, ": cannot create in the store"));
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out.flush()) return absl::ResourceExhaustedError(kinemo::StrCat(name, ": write failed (disk full?)"));
  return absl::OkStatus();
}

Status Draft::CopyFile(std::string_view name, const std::string& source_path) {
  KINEMO_ASSIGN_OR_RETURN(std::string path, PathFor(name));
  std::error_code ec;
  fs::create_directories(fs::path(path).parent_path(), ec);
  fs::copy_file(source_path, path, fs::copy_options::overwrite_existing, ec);
  if (ec) return absl::NotFoundError(kinemo::StrCat(name, ": cannot copy: ", ec.message()));
  return absl::OkStatus();
}

Status Draft::Append(std::string_view name, std::string_view bytes) {
  KINEMO_ASSIGN_OR_RETURN(std::string path, PathFor(name));
  std::error_code ec;
  fs::create_directories(fs::path(path).parent_path(), ec);
  std::ofstream out(path, std::ios::binary | std::ios::app);
  if (!out) return absl::PermissionDeniedError(kinemo::StrCat(name, ": cannot create in the store"));
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out.flush()) return absl::ResourceExhaustedError(kinemo::StrCat(name, ": write failed (disk full?)"));
  return absl::OkStatus();
}

std::uint64_t Draft::bytes_written() const {
  std::uint64_t n = 0;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir_, ec); !ec && it != fs::recursive_directory_iterator();
       it.increment(ec)) {
    if (it->is_regular_file()) n += it->file_size();
  }
  return n;
}

// ---- ArtifactStore ------------------------------------------------------------

StatusOr<std::unique_ptr<ArtifactStore>> ArtifactStore::Open(const std::string& root, std::string_view field) {
  if (root.empty()) return InvalidField(field, "is empty");
  std::error_code ec;
  fs::create_directories(root, ec);
  if (ec || !fs::is_directory(root)) {
    return absl::FailedPreconditionError(kinemo::StrCat(field, ": cannot create '", root, "'",
                                                        ec ? kinemo::StrCat(": ", ec.message()) : ""));
  }
  const fs::path abs = fs::absolute(root, ec);
  const fs::path staging = abs / std::string(kStaging);
  fs::remove_all(staging, ec);  // drafts of a previous run
  fs::create_directories(staging, ec);
  if (ec || ::access(staging.c_str(), W_OK) != 0) {
    return absl::FailedPreconditionError(kinemo::StrCat(field, ": '", root, "' is not writable"));
  }
  return std::unique_ptr<ArtifactStore>(new ArtifactStore(abs.lexically_normal().string()));
}

StatusOr<Draft> ArtifactStore::Begin(std::string_view kind, std::string_view id) {
  KINEMO_RETURN_IF_ERROR(ValidateId(kind, "kind"));
  KINEMO_RETURN_IF_ERROR(ValidateId(id, "id"));
  Draft d;
  d.kind_ = std::string(kind);
  d.id_ = std::string(id);
  const fs::path dir = fs::path(root_) / std::string(kStaging) / kinemo::StrCat(kind, "-", id, "-", RandomSuffix());
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return absl::PermissionDeniedError(kinemo::StrCat("store: cannot create a draft: ", ec.message()));
  d.dir_ = dir.string();
  return d;
}

std::vector<std::uint32_t> ArtifactStore::Versions(std::string_view kind, std::string_view id) const {
  std::vector<std::uint32_t> out;
  std::error_code ec;
  const fs::path dir = fs::path(root_) / std::string(kind) / std::string(id);
  for (auto it = fs::directory_iterator(dir, ec); !ec && it != fs::directory_iterator(); it.increment(ec)) {
    std::uint32_t v = 0;
    if (it->is_directory() && ParseVersion(it->path().filename().string(), &v) &&
        fs::exists(it->path() / std::string(kMetaFile))) {
      out.push_back(v);
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

StatusOr<ArtifactMeta> ArtifactStore::Commit(Draft draft, ArtifactMeta meta, bool overwrite) {
  return CommitImpl(std::move(draft), std::move(meta), overwrite, 0);
}

StatusOr<ArtifactMeta> ArtifactStore::CommitImpl(Draft draft, ArtifactMeta meta, bool overwrite,
                                                 std::uint32_t keep_version) {
  if (draft.dir_.empty()) return absl::FailedPreconditionError("store: draft already committed");
  meta.kind = draft.kind_;
  meta.id = draft.id_;
  if (keep_version == 0 || meta.created_unix_ms == 0) meta.created_unix_ms = NowUnixMs();
  meta.files.clear();
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(draft.dir_, ec); !ec && it != fs::recursive_directory_iterator();
       it.increment(ec)) {
    if (!it->is_regular_file()) continue;
    meta.files.push_back({fs::relative(it->path(), draft.dir_).generic_string(), it->file_size()});
  }
  std::sort(meta.files.begin(), meta.files.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
  std::lock_guard<std::mutex> lock(mu_);
  const auto versions = Versions(meta.kind, meta.id);
  if (keep_version != 0) {
    if (std::find(versions.begin(), versions.end(), keep_version) != versions.end()) {
      return absl::AlreadyExistsError(
          kinemo::StrCat("id: '", meta.id, "' version ", keep_version, " exists in ", meta.kind));
    }
    meta.version = keep_version;
    return Place(std::move(draft), std::move(meta));
  }
  if (!versions.empty() && !overwrite) {
    return absl::AlreadyExistsError(kinemo::StrCat("id: '", meta.id, "' exists in ", meta.kind,
                                                   " (version ", versions.back(), "; set overwrite for a new version)"));
  }
  meta.version = versions.empty() ? 1 : versions.back() + 1;
  return Place(std::move(draft), std::move(meta));
}

StatusOr<ArtifactMeta> ArtifactStore::Place(Draft draft, ArtifactMeta meta) {
  std::error_code ec;
  {
    std::ofstream out(fs::path(draft.dir_) / std::string(kMetaFile), std::ios::binary | std::ios::trunc);
    out << MetaToJson(meta);
    if (!out.flush()) return absl::ResourceExhaustedError("store: cannot write artifact.json (disk full?)");
  }
  SyncTree(draft.dir_);
  const fs::path parent = fs::path(root_) / meta.kind / meta.id;
  fs::create_directories(parent, ec);
  const fs::path target = parent / std::to_string(meta.version);
  fs::rename(draft.dir_, target, ec);
  if (ec) return absl::InternalError(kinemo::StrCat("store: cannot commit ", RefString(meta.ref()), ": ", ec.message()));
  draft.dir_.clear();
  Sync(parent, true);
  Sync(parent.parent_path(), true);
  return meta;
}

StatusOr<ArtifactMeta> ArtifactStore::Get(std::string_view kind, std::string_view id, std::uint32_t version) const {
  KINEMO_RETURN_IF_ERROR(ValidateId(kind, "kind"));
  KINEMO_RETURN_IF_ERROR(ValidateId(id, "id"));
  if (version == 0) {
    const auto versions = Versions(kind, id);
    if (versions.empty()) return absl::NotFoundError(kinemo::StrCat("id: no ", kind, " '", id, "'"));
    version = versions.back();
  }
  const fs::path meta_path = fs::path(Dir({std::string(kind), std::string(id), version})) / std::string(kMetaFile);
  if (!fs::exists(meta_path)) {
    return absl::NotFoundError(kinemo::StrCat("version: no version ", version, " of ", kind, " '", id, "'"));
  }
  KINEMO_ASSIGN_OR_RETURN(std::string text, ReadSmallFile(meta_path));
  KINEMO_ASSIGN_OR_RETURN(ArtifactMeta m, MetaFromJson(text, RefString({std::string(kind), std::string(id), version})));
  // The folder names are the truth (a copied folder keeps its old json).
  m.kind = std::string(kind);
  m.id = std::string(id);
  m.version = version;
  return m;
}

std::string ArtifactStore::Dir(const ArtifactRef& ref) const {
  return (fs::path(root_) / ref.kind / ref.id / std::to_string(ref.version)).string();
}

std::string ArtifactStore::FilePath(const ArtifactRef& ref, std::string_view name) const {
  return (fs::path(Dir(ref)) / std::string(name)).string();
}

StatusOr<std::vector<ArtifactMeta>> ArtifactStore::List(std::string_view kind, std::string_view id,
                                                        bool all_versions) const {
  if (!kind.empty()) KINEMO_RETURN_IF_ERROR(ValidateId(kind, "kind"));
  if (!id.empty()) KINEMO_RETURN_IF_ERROR(ValidateId(id, "id"));
  std::vector<std::string> kinds;
  std::error_code ec;
  if (kind.empty()) {
    for (auto it = fs::directory_iterator(root_, ec); !ec && it != fs::directory_iterator(); it.increment(ec)) {
      const std::string name = it->path().filename().string();
      if (it->is_directory() && IsValidId(name)) kinds.push_back(name);
    }
  } else {
    kinds.emplace_back(kind);
  }
  std::sort(kinds.begin(), kinds.end());
  std::vector<ArtifactMeta> out;
  for (const auto& k : kinds) {
    std::vector<std::string> ids;
    if (id.empty()) {
      for (auto it = fs::directory_iterator(fs::path(root_) / k, ec); !ec && it != fs::directory_iterator();
           it.increment(ec)) {
        const std::string name = it->path().filename().string();
        if (it->is_directory() && IsValidId(name)) ids.push_back(name);
      }
      ec.clear();
    } else {
      ids.emplace_back(id);
    }
    std::sort(ids.begin(), ids.end());
    for (const auto& i : ids) {
      auto versions = Versions(k, i);
      if (versions.empty()) continue;
      if (!all_versions) versions = {versions.back()};
      for (auto v : versions) {
        auto m = Get(k, i, v);
        if (m.ok()) out.push_back(*std::move(m));
      }
    }
  }
  return out;
}

StatusOr<std::vector<ArtifactMeta>> ArtifactStore::Delete(std::string_view kind, std::string_view id,
                                                          std::uint32_t version) {
  KINEMO_RETURN_IF_ERROR(ValidateId(kind, "kind"));
  KINEMO_RETURN_IF_ERROR(ValidateId(id, "id"));
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<std::uint32_t> versions = Versions(kind, id);
  if (version != 0) {
    if (std::find(versions.begin(), versions.end(), version) == versions.end()) {
      return absl::NotFoundError(kinemo::StrCat("version: no version ", version, " of ", kind, " '", id, "'"));
    }
    versions = {version};
  }
  if (versions.empty()) return absl::NotFoundError(kinemo::StrCat("id: no ", kind, " '", id, "'"));
  std::vector<ArtifactMeta> removed;
  std::error_code ec;
  for (auto v : versions) {
    auto m = Get(kind, id, v);
    // Rename out of the way first (atomic), then remove the files.
    const fs::path from = Dir({std::string(kind), std::string(id), v});
    const fs::path trash = fs::path(root_) / std::string(kStaging) / kinemo::StrCat("deleted-", RandomSuffix());
    fs::rename(from, trash, ec);
    if (ec) return absl::InternalError(kinemo::StrCat("store: cannot delete ", kind, "/", id, "/", v, ": ", ec.message()));
    fs::remove_all(trash, ec);
    if (m.ok()) removed.push_back(*std::move(m));
  }
  const fs::path id_dir = fs::path(root_) / std::string(kind) / std::string(id);
  if (fs::is_empty(id_dir, ec)) fs::remove(id_dir, ec);
  Sync(fs::path(root_) / std::string(kind), true);
  return removed;
}

namespace {

// Whether `stored` (the newest version here) is the seed's artifact and
// `seed` a different build of it.
bool SeedChanged(const ArtifactMeta& stored, const ArtifactMeta& seed) {
  const bool from_seed =
      stored.seeded || (stored.version == seed.version && stored.description == seed.description);
  if (!from_seed) return false;
  auto same_files = [](const std::vector<ArtifactFile>& a, const std::vector<ArtifactFile>& b) {
    return std::equal(a.begin(), a.end(), b.begin(), b.end(),
                      [](const ArtifactFile& x, const ArtifactFile& y) {
                        return x.name == y.name && x.size_bytes == y.size_bytes;
                      });
  };
  return stored.version != seed.version || stored.created_unix_ms != seed.created_unix_ms ||
         !same_files(stored.files, seed.files);
}

}  // namespace

StatusOr<std::vector<ArtifactMeta>> ArtifactStore::ImportSeed(const std::string& seed_root, std::string_view kind) {
  std::vector<ArtifactMeta> imported;
  std::error_code ec;
  if (seed_root.empty() || !fs::is_directory(fs::path(seed_root) / std::string(kind), ec)) return imported;
  // Read the seed without Open (it may be read-only).
  ArtifactStore seed(fs::absolute(seed_root, ec).lexically_normal().string());
  KINEMO_ASSIGN_OR_RETURN(auto newest, seed.List(kind));
  for (ArtifactMeta m : newest) {
    const std::vector<std::uint32_t> versions = Versions(m.kind, m.id);
    if (!versions.empty()) {
      auto stored = Get(m.kind, m.id, versions.back());
      // An unreadable newest version is left to the loaders to report.
      if (!stored.ok() || !SeedChanged(*stored, m) || m.version < stored->version) continue;
    }
    KINEMO_ASSIGN_OR_RETURN(Draft d, Begin(m.kind, m.id));
    for (const auto& f : m.files) KINEMO_RETURN_IF_ERROR(d.CopyFile(f.name, seed.FilePath(m.ref(), f.name)));
    // The same version of an older seed goes first (a crash in between
    // leaves the id missing, and the next start imports it).
    if (!versions.empty() && versions.back() == m.version) {
      KINEMO_RETURN_IF_ERROR(Delete(m.kind, m.id, m.version).status());
    }
    // Same version number, so that references between artifacts still hold.
    m.seeded = true;
    KINEMO_ASSIGN_OR_RETURN(ArtifactMeta stored, CommitImpl(std::move(d), m, false, m.version));
    imported.push_back(std::move(stored));
  }
  return imported;
}

}  // namespace kinemo::store
