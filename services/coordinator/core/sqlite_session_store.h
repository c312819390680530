// SessionStore on an embedded SQLite database, <store_dir>/sessions.db, in
// WAL mode: a write is one transaction (a WAL append; synchronous=NORMAL
// keeps it through a crash or SIGKILL of the process, and the operating
// system's crash loses at most the last transactions, never consistency).
#pragma once

#include <memory>
#include <mutex>
#include <string>

#include "services/coordinator/core/session_store.h"

struct sqlite3;
struct sqlite3_stmt;

namespace kinemo::coordinator {

class SqliteSessionStore final : public SessionStore {
 public:
  // Creates `dir` if missing and opens (or creates) dir/sessions.db. Errors
  // (INVALID_ARGUMENT, starting with `field`, e.g. "store_dir: ...") for a
  // directory that cannot be made or written, or a file that is not a
  // session store (corrupt, or another database).
  static StatusOr<std::unique_ptr<SqliteSessionStore>> Open(const std::string& dir,
                                                            const std::string& field = "store_dir");
  ~SqliteSessionStore() override;

  Status Put(const StoredSession& session) override;
  Status Delete(const std::string& session_id) override;
  StatusOr<std::vector<StoredSession>> LoadAll() override;

  const std::string& path() const { return path_; }

 private:
  SqliteSessionStore() = default;
  Status Error(const char* what) const;

  std::string path_;
  std::string field_;
  std::mutex mu_;
  sqlite3* db_ = nullptr;
  sqlite3_stmt* put_ = nullptr;
  sqlite3_stmt* delete_ = nullptr;
};

}  // namespace kinemo::coordinator
