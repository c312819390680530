// The end-to-end benchmark behind `kinemo bench e2e`: pleo_sim (a child
// process on loopback Modbus TCP), the robot bridge and the coordinator (each
// on its own loopback gRPC server in this process), driven like a cube or a
// client Vleo drives a session:
//   - cube event -> robot register written: an action (Act, the same call a
//     cube event makes) that flips the emotion, until the bridge reports the
//     command acknowledged by the robot (APPLIED_SEQUENCE read back), as the
//     watch stream shows it to the client;
//   - live speech -> motion: StreamAnimate against a coordinator with models
//     (`coordinator`, `model_id`, `controller_id`; the CLI starts the embedded
//     all-in-one when none is given), real speech in 20 ms chunks at real-time
//     pace, measured on the client's clock (client/live_client.h):
//       motion_lag: frame received − the chunk holding the frame's time sent
//                   (per frame; p50, p99),
//       first_frame: first frame received − first chunk sent,
//       max_frame_gap: longest gap between frame batches received, first
//                   frame to the last chunk's frames, pauses included,
//       audio_to_frame: a batch received − the chunk its last_chunk_sequence
//                   names sent (server processing only; the older figure);
//   - sessions: how many sessions the coordinator holds and keeps running.
#pragma once

#include <optional>
#include <string>

#include "common/grpc/tls_credentials.h"
#include "common/status/status.h"

namespace kinemo::coordinator {

struct E2eBenchOptions {
  std::string pleo_sim;        // pleo_sim binary
  int actions = 200;           // emotion flips measured
  int sessions = 1000;         // sessions opened at once
  // StreamAnimate: a running coordinator with the models, and a recording.
  std::string coordinator;     // "" = skip the live figures
  ClientTlsFiles coordinator_tls;  // how to reach it (plaintext when empty)
  std::string model_id, controller_id;
  std::string speech_file;
};

struct E2eBenchResult {
  double cube_to_register_p50_ms = 0, cube_to_register_p99_ms = 0;
  double bridge_round_trip_p50_ms = 0, bridge_round_trip_p99_ms = 0;  // trigger -> ack, coordinator side
  std::optional<double> audio_to_frame_p50_ms, audio_to_frame_p99_ms;
  std::optional<double> motion_lag_p50_ms, motion_lag_p99_ms, first_frame_ms, max_frame_gap_ms;
  std::optional<double> max_chunk_late_ms;  // the client's own lateness (see live_client.h)
  double speech_s = 0;         // audio streamed
  int sessions = 0;            // sessions held and running
  double sessions_open_s = 0;  // time to open them all
  std::string audio_note;      // why the live figures are missing
};

StatusOr<E2eBenchResult> RunE2eBench(const E2eBenchOptions& options);

}  // namespace kinemo::coordinator
