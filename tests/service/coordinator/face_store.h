// A prosody store with a face model ("bundled") trained on one real BEAT2
// take (its captured jaw and TextGrid phones), for the coordinator's tests
// of the face (docs/face.md).
#pragma once

#include <string>

#include "common/store/artifact_store.h"
#include "services/prosody/core/face_corpus.h"
#include "services/prosody/core/face_model.h"

namespace kinemo::coordinator {

// Trains the model and commits it under `dir`; "" on success, else why not.
inline std::string MakeFaceStore(const std::string& dir) {
  auto take = prosody::ReadFaceTake(std::string(KINEMO_TEST_DATA_DIR) + "/paired/beat2", "2_scott_0_2_2");
  if (!take.ok()) return std::string(take.status().message());
  auto model = prosody::TrainFaceModel(std::span(&*take, 1), {});
  if (!model.ok()) return std::string(model.status().message());
  auto store = store::ArtifactStore::Open(dir);
  if (!store.ok()) return std::string(store.status().message());
  auto draft = (*store)->Begin("face_models", "bundled");
  if (!draft.ok()) return std::string(draft.status().message());
  if (Status s = draft->WriteFile("face_model.json", prosody::FaceModelToJson(*model)); !s.ok()) {
    return std::string(s.message());
  }
  auto done = (*store)->Commit(*std::move(draft), {}, false);
  return done.ok() ? "" : std::string(done.status().message());
}

}  // namespace kinemo::coordinator
