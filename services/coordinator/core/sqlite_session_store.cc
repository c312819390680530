#include "services/coordinator/core/sqlite_session_store.h"

#include <sqlite3.h>

#include <filesystem>
#include <system_error>

namespace kinemo::coordinator {
namespace {

constexpr int kSchemaVersion = 1;

constexpr const char* kSchema =
    "CREATE TABLE IF NOT EXISTS sessions ("
    " session_id TEXT PRIMARY KEY NOT NULL,"
    " robot_id TEXT NOT NULL,"
    " vleo INTEGER NOT NULL,"
    " vleo_name TEXT NOT NULL,"
    " open_wall_ns INTEGER NOT NULL,"
    " open_order INTEGER NOT NULL,"
    " valence REAL NOT NULL,"
    " emotion INTEGER NOT NULL,"
    " action INTEGER NOT NULL,"
    " intensity REAL NOT NULL,"
    " model_wall_ns INTEGER NOT NULL,"
    " acts INTEGER NOT NULL,"
    " cube_source BLOB NOT NULL,"
    " cube_config BLOB NOT NULL,"
    " robot_emotion INTEGER NOT NULL,"
    " robot_sequence INTEGER NOT NULL)";

constexpr const char* kColumns =
    "session_id, robot_id, vleo, vleo_name, open_wall_ns, open_order, valence, emotion, action,"
    " intensity, model_wall_ns, acts, cube_source, cube_config, robot_emotion, robot_sequence";

void BindText(sqlite3_stmt* st, int i, const std::string& s) {
  sqlite3_bind_text(st, i, s.data(), static_cast<int>(s.size()), SQLITE_TRANSIENT);
}
void BindBlob(sqlite3_stmt* st, int i, const std::string& s) {
  sqlite3_bind_blob(st, i, s.data(), static_cast<int>(s.size()), SQLITE_TRANSIENT);
}
std::string ColumnBytes(sqlite3_stmt* st, int i) {
  const void* p = sqlite3_column_blob(st, i);
  const int n = sqlite3_column_bytes(st, i);
  return p == nullptr ? std::string() : std::string(static_cast<const char*>(p), n);
}

}  // namespace

Status SqliteSessionStore::Error(const char* what) const {
  return absl::UnavailableError(kinemo::StrCat(field_, ": ", what, " ", path_, ": ",
                                               db_ != nullptr ? sqlite3_errmsg(db_) : "no database"));
}

StatusOr<std::unique_ptr<SqliteSessionStore>> SqliteSessionStore::Open(const std::string& dir,
                                                                       const std::string& field) {
  auto bad = [&](const std::string& why) {
    return absl::InvalidArgumentError(kinemo::StrCat(field, ": ", dir, ": ", why));
  };
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return bad(kinemo::StrCat("cannot create the directory (", ec.message(), ")"));
  if (!std::filesystem::is_directory(dir, ec)) return bad("not a directory");
  std::unique_ptr<SqliteSessionStore> store(new SqliteSessionStore());
  store->field_ = field;
  store->path_ = (std::filesystem::path(dir) / "sessions.db").string();
  if (sqlite3_open_v2(store->path_.c_str(), &store->db_,
                      SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX,
                      nullptr) != SQLITE_OK) {
    return bad(kinemo::StrCat("cannot open sessions.db (", sqlite3_errmsg(store->db_), ")"));
  }
  sqlite3_busy_timeout(store->db_, 5000);
  auto exec = [&](const char* sql) -> Status {
    char* err = nullptr;
    if (sqlite3_exec(store->db_, sql, nullptr, nullptr, &err) != SQLITE_OK) {
      std::string m = err != nullptr ? err : sqlite3_errmsg(store->db_);
      sqlite3_free(err);
      return bad(kinemo::StrCat("sessions.db is not a usable session store (", m, ")"));
    }
    return absl::OkStatus();
  };
  // The first statement reads the file: a corrupt one fails here.
  KINEMO_RETURN_IF_ERROR(exec("PRAGMA journal_mode=WAL"));
  KINEMO_RETURN_IF_ERROR(exec("PRAGMA synchronous=NORMAL"));
  {
    sqlite3_stmt* st = nullptr;
    int version = -1;
    if (sqlite3_prepare_v2(store->db_, "PRAGMA user_version", -1, &st, nullptr) == SQLITE_OK &&
        sqlite3_step(st) == SQLITE_ROW) {
      version = sqlite3_column_int(st, 0);
    }
    sqlite3_finalize(st);
    if (version != 0 && version != kSchemaVersion) {
      return bad(kinemo::StrCat("sessions.db has schema version ", version, ", this coordinator reads ",
                                kSchemaVersion));
    }
    st = nullptr;
    std::string check;
    if (sqlite3_prepare_v2(store->db_, "PRAGMA quick_check", -1, &st, nullptr) == SQLITE_OK &&
        sqlite3_step(st) == SQLITE_ROW) {
      check = ColumnBytes(st, 0);
    } else {
      check = sqlite3_errmsg(store->db_);
    }
    sqlite3_finalize(st);
    if (check != "ok") return bad(kinemo::StrCat("sessions.db is corrupt (", check, ")"));
  }
  KINEMO_RETURN_IF_ERROR(exec(kSchema));
  KINEMO_RETURN_IF_ERROR(exec(kinemo::StrCat("PRAGMA user_version=", kSchemaVersion).c_str()));
  const std::string put = kinemo::StrCat("INSERT OR REPLACE INTO sessions (", kColumns,
                                         ") VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
  if (sqlite3_prepare_v3(store->db_, put.c_str(), -1, SQLITE_PREPARE_PERSISTENT, &store->put_,
                         nullptr) != SQLITE_OK ||
      sqlite3_prepare_v3(store->db_, "DELETE FROM sessions WHERE session_id = ?", -1,
                         SQLITE_PREPARE_PERSISTENT, &store->delete_, nullptr) != SQLITE_OK) {
    return bad(kinemo::StrCat("sessions.db: ", sqlite3_errmsg(store->db_)));
  }
  return store;
}

SqliteSessionStore::~SqliteSessionStore() {
  sqlite3_finalize(put_);
  sqlite3_finalize(delete_);
  sqlite3_close(db_);
}

Status SqliteSessionStore::Put(const StoredSession& s) {
  std::lock_guard<std::mutex> l(mu_);
  sqlite3_stmt* st = put_;
  sqlite3_reset(st);
  sqlite3_clear_bindings(st);
  BindText(st, 1, s.session_id);
  BindText(st, 2, s.robot_id);
  sqlite3_bind_int(st, 3, s.vleo);
  BindText(st, 4, s.vleo_name);
  sqlite3_bind_int64(st, 5, s.open_wall_ns);
  sqlite3_bind_int64(st, 6, static_cast<sqlite3_int64>(s.order));
  sqlite3_bind_double(st, 7, s.valence);
  sqlite3_bind_int(st, 8, s.emotion);
  sqlite3_bind_int(st, 9, s.action);
  sqlite3_bind_double(st, 10, s.intensity);
  sqlite3_bind_int64(st, 11, s.model_wall_ns);
  sqlite3_bind_int64(st, 12, static_cast<sqlite3_int64>(s.acts));
  BindBlob(st, 13, s.cube_source);
  BindBlob(st, 14, s.cube_config);
  sqlite3_bind_int(st, 15, s.robot_emotion);
  sqlite3_bind_int64(st, 16, s.robot_sequence);
  const int rc = sqlite3_step(st);
  sqlite3_reset(st);
  if (rc != SQLITE_DONE) return Error("cannot write");
  return absl::OkStatus();
}

Status SqliteSessionStore::Delete(const std::string& session_id) {
  std::lock_guard<std::mutex> l(mu_);
  sqlite3_reset(delete_);
  BindText(delete_, 1, session_id);
  const int rc = sqlite3_step(delete_);
  sqlite3_reset(delete_);
  if (rc != SQLITE_DONE) return Error("cannot delete from");
  return absl::OkStatus();
}

StatusOr<std::vector<StoredSession>> SqliteSessionStore::LoadAll() {
  std::lock_guard<std::mutex> l(mu_);
  sqlite3_stmt* st = nullptr;
  const std::string sql = kinemo::StrCat("SELECT ", kColumns, " FROM sessions ORDER BY open_order");
  if (sqlite3_prepare_v2(db_, sql.c_str(), -1, &st, nullptr) != SQLITE_OK) {
    return Error("cannot read");
  }
  std::vector<StoredSession> out;
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    StoredSession s;
    s.session_id = ColumnBytes(st, 0);
    s.robot_id = ColumnBytes(st, 1);
    s.vleo = sqlite3_column_int(st, 2);
    s.vleo_name = ColumnBytes(st, 3);
    s.open_wall_ns = sqlite3_column_int64(st, 4);
    s.order = static_cast<std::uint64_t>(sqlite3_column_int64(st, 5));
    s.valence = sqlite3_column_double(st, 6);
    s.emotion = sqlite3_column_int(st, 7);
    s.action = sqlite3_column_int(st, 8);
    s.intensity = sqlite3_column_double(st, 9);
    s.model_wall_ns = sqlite3_column_int64(st, 10);
    s.acts = static_cast<std::uint64_t>(sqlite3_column_int64(st, 11));
    s.cube_source = ColumnBytes(st, 12);
    s.cube_config = ColumnBytes(st, 13);
    s.robot_emotion = sqlite3_column_int(st, 14);
    s.robot_sequence = static_cast<std::uint32_t>(sqlite3_column_int64(st, 15));
    out.push_back(std::move(s));
  }
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return Error("cannot read");
  return out;
}

}  // namespace kinemo::coordinator
