// Where the session manager keeps what it told clients: one record per open
// session, written before the answer and read back at start (durable
// sessions, docs/coordinator.md). Plain C++: no gRPC, no SQLite here; the
// SQLite implementation is in sqlite_session_store.h, and a SessionManager
// without a store keeps its sessions in memory only.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/status/status.h"
#include "kinemo/common/v1/vleo.pb.h"

namespace kinemo::coordinator {

// One session as stored. Times are wall-clock (Unix nanoseconds) so that the
// emotion model can be advanced over the time the coordinator was down.
struct StoredSession {
  std::string session_id;
  std::string robot_id;
  int vleo = 0;                 // coordinator.v1.VleoKind
  std::string vleo_name;
  std::int64_t open_wall_ns = 0;
  std::uint64_t order = 0;      // opening order
  // The emotion model: its state at model_wall_ns, from which the current
  // action and intensity apply.
  double valence = 0;
  int emotion = 0;              // common.v1.Emotion
  int action = 0;               // common.v1.Action
  double intensity = 0;
  std::int64_t model_wall_ns = 0;
  // Acts acknowledged with OK (client and cube).
  std::uint64_t acts = 0;
  // The cube attachment: serialized cube_tracker.v1.VideoSource and
  // TrackConfig; empty source = no cube attached.
  std::string cube_source;
  std::string cube_config;
  // The last command the bridge acknowledged for this session.
  int robot_emotion = 0;        // common.v1.Emotion
  std::uint32_t robot_sequence = 0;
};

class SessionStore {
 public:
  virtual ~SessionStore() = default;
  // Inserts or replaces the session; committed when it returns OK.
  virtual Status Put(const StoredSession& session) = 0;
  // Removes the session (no error if it is absent); committed on OK.
  virtual Status Delete(const std::string& session_id) = 0;
  // Every stored session, in opening order.
  virtual StatusOr<std::vector<StoredSession>> LoadAll() = 0;
};

}  // namespace kinemo::coordinator
