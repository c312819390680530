// The Vleo -> Pleo demo behind `kinemo demo vleo`: renders a scripted cube
// video over a real photo (the cube_tracker renderer), plays it in real time
// through the cube tracker into a cube session of the coordinator, which
// drives a simulated Pleo (pleo_sim, a child process on loopback Modbus TCP)
// through the robot bridge. The cube tracker, bridge and coordinator run in
// this process, each on its own loopback gRPC server.
#pragma once

#include <functional>
#include <string>

#include "common/status/status.h"
#include "kinemo/coordinator/v1/coordinator.pb.h"

namespace kinemo::coordinator {

struct VleoDemoOptions {
  std::string pleo_sim;      // pleo_sim binary
  std::string cube_model;    // cube model text proto (tests/data/cube/vleo.cube)
  std::string script;        // render script (tests/data/cube/vleo_scenario.json)
  std::string work_dir;      // where the video is rendered ("" = a temp dir)
  double rate_per_s = 0.4;   // emotion model rate (the scenario is short)
  common::v1::Emotion initial = common::v1::EMOTION_ANGRY;
};

struct VleoDemoResult {
  common::v1::Emotion final_emotion = common::v1::EMOTION_UNSPECIFIED;  // the model's
  common::v1::Emotion robot_shows = common::v1::EMOTION_UNSPECIFIED;    // pleo_sim's, via the bridge
  std::string video;  // the rendered video
};

// Calls `on_event` for every session event (in order) while the video plays.
StatusOr<VleoDemoResult> RunVleoDemo(const VleoDemoOptions& options,
                                     const std::function<void(const v1::SessionEvent&)>& on_event);

}  // namespace kinemo::coordinator
