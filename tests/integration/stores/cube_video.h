// A real cube video for the store tests: the Vleo cube
// (tests/data/cube/vleo.cube) rendered over a real photograph along
// tests/data/cube/lift_rotate_place.json, written to DIR/seq.avi with its
// ground truth (truth.json) and the camera's intrinsics (camera.yaml).
#pragma once

#include <string>

#include "common/testing/process.h"
#include "services/cube_tracker/core/cube_model.h"
#include "services/cube_tracker/render/renderer.h"

namespace kinemo::stores_test {

struct CubeVideo {
  cube::CubeModel model;
  cube::RenderScript script;
};

inline StatusOr<CubeVideo> RenderCubeVideo(const std::string& data_dir, const testing::TempDir& dir) {
  KINEMO_ASSIGN_OR_RETURN(cube::CubeModel model, cube::LoadCubeModel(data_dir + "/cube/vleo.cube"));
  KINEMO_ASSIGN_OR_RETURN(cube::RenderScript script,
                          cube::LoadRenderScript(data_dir + "/cube/lift_rotate_place.json"));
  KINEMO_RETURN_IF_ERROR(cube::SequenceRenderer::RenderToFiles(
      model, script, dir.File("seq.avi"), dir.File("truth.json"), dir.File("camera.yaml")));
  return CubeVideo{std::move(model), std::move(script)};
}

}  // namespace kinemo::stores_test
