// Shared by the planner store tests (service and integration): artifact
// calls over a real PlannerService stub, real clips of tests/data, and the
// state model / beliefs a controller needs.
#pragma once

#include <chrono>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "tests/service/planner_gesture/speech_accents.h"
#include "tests/unit/planner_controller/test_util.h"

namespace kinemo::planner::store_test {

namespace cv1 = ::kinemo::common::v1;

inline const std::string kData = KINEMO_TEST_DATA_DIR;

inline std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

inline std::unique_ptr<grpc::ClientContext> Ctx(int seconds = 120) {
  auto c = std::make_unique<grpc::ClientContext>();
  c->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(seconds));
  return c;
}

struct PushFile {
  std::string name, bytes;
};

// PushArtifact with the files sent in chunks of `chunk_bytes`.
inline grpc::Status Push(v1::PlannerService::Stub* stub, const std::string& kind, const std::string& id,
                         const std::vector<PushFile>& files, const std::vector<cv1::ArtifactRef>& depends_on,
                         cv1::PushArtifactResponse* response, size_t chunk_bytes = 1 << 20, bool overwrite = false) {
  auto ctx = Ctx();
  auto writer = stub->PushArtifact(ctx.get(), response);
  cv1::PushArtifactRequest header;
  header.mutable_header()->mutable_ref()->set_kind(kind);
  header.mutable_header()->mutable_ref()->set_id(id);
  header.mutable_header()->set_overwrite(overwrite);
  for (const auto& f : files) {
    auto* hf = header.mutable_header()->add_files();
    hf->set_name(f.name);
    hf->set_size_bytes(f.bytes.size());
  }
  for (const auto& d : depends_on) *header.mutable_header()->add_depends_on() = d;
  bool ok = writer->Write(header);
  for (size_t i = 0; ok && i < files.size(); ++i) {
    for (size_t off = 0; ok && off < files[i].bytes.size(); off += chunk_bytes) {
      cv1::PushArtifactRequest chunk;
      chunk.mutable_chunk()->set_file_index(static_cast<uint32_t>(i));
      chunk.mutable_chunk()->set_offset(off);
      chunk.mutable_chunk()->set_data(files[i].bytes.substr(off, chunk_bytes));
      ok = writer->Write(chunk);
    }
  }
  if (ok) writer->WritesDone();
  return writer->Finish();
}

inline cv1::ArtifactRef Ref(const std::string& kind, const std::string& id, uint32_t version = 0) {
  cv1::ArtifactRef r;
  r.set_kind(kind);
  r.set_id(id);
  r.set_version(version);
  return r;
}

inline cv1::ListArtifactsResponse List(v1::PlannerService::Stub* stub, const std::string& kind = "",
                                       bool all_versions = false) {
  cv1::ListArtifactsRequest req;
  req.set_kind(kind);
  req.set_all_versions(all_versions);
  cv1::ListArtifactsResponse resp;
  auto ctx = Ctx();
  const grpc::Status s = stub->ListArtifacts(ctx.get(), req, &resp);
  EXPECT_TRUE(s.ok()) << s.error_message();
  return resp;
}

// "kind/id/version" of each listed artifact, in order.
inline std::vector<std::string> Refs(const cv1::ListArtifactsResponse& list) {
  std::vector<std::string> out;
  for (const auto& a : list.artifacts()) {
    out.push_back(a.ref().kind() + "/" + a.ref().id() + "/" + std::to_string(a.ref().version()));
  }
  return out;
}

inline grpc::Status Delete(v1::PlannerService::Stub* stub, const std::string& kind, const std::string& id,
                           uint32_t version, cv1::DeleteArtifactResponse* response = nullptr) {
  cv1::DeleteArtifactRequest req;
  *req.mutable_ref() = Ref(kind, id, version);
  cv1::DeleteArtifactResponse ignored;
  auto ctx = Ctx();
  return stub->DeleteArtifact(ctx.get(), req, response != nullptr ? response : &ignored);
}

// The clips of tests/data/planner_controller as a push: manifest.json (tones
// from the file names, keywords) and the BVH files it names.
inline std::vector<PushFile> ControllerLibraryFiles() {
  std::vector<PushFile> files{{"manifest.json", ReadFile(kData + "/planner_controller/manifest.json")}};
  for (const char* clip : {"dataset-1_bow_normal_001", "dataset-1_bye_normal_001", "dataset-1_guide_normal_001",
                           "dataset-1_byebye_angry_001", "dataset-1_guide_happy_001", "dataset-1_bow_tired_001",
                           "dataset-1_guide_tired_001"}) {
    const std::string name = std::string(clip) + ".bvh";
    files.push_back({name, ReadFile(kData + "/planner_controller/" + name)});
  }
  return files;
}

// The same clips as LoadLibrary inline clips (keywords as in the manifest).
inline void AddControllerClips(v1::LoadLibraryRequest* req) {
  const std::vector<std::pair<std::string, std::string>> clips = {
      {"dataset-1_bow_normal_001", "bow"},  {"dataset-1_bye_normal_001", "bye"},
      {"dataset-1_guide_normal_001", "this"}, {"dataset-1_byebye_angry_001", "bye"},
      {"dataset-1_guide_happy_001", ""},      {"dataset-1_bow_tired_001", ""},
      {"dataset-1_guide_tired_001", ""}};
  for (const auto& [name, keyword] : clips) {
    auto* c = req->add_clips();
    c->set_name(name);
    c->set_bvh(ReadFile(kData + "/planner_controller/" + name + ".bvh"));
    if (!keyword.empty()) c->add_keywords(keyword);
  }
}

// SynthesizeGestures with graph `id` on the pitch accents of real speech.
inline grpc::Status SynthesizeGestures(v1::PlannerService::Stub* stub, const std::string& id,
                                       v1::SynthesizeGesturesResponse* resp) {
  v1::SynthesizeGesturesRequest req;
  req.set_graph_id(id);
  for (const auto& a : testing::SpeechAccents()) *req.add_accents() = a;
  auto ctx = Ctx();
  return stub->SynthesizeGestures(ctx.get(), req, resp);
}

// Synthesize with controller `id` over 4 s of drifting beliefs.
inline grpc::Status Synthesize(v1::PlannerService::Stub* stub, const std::string& id, int states,
                               v1::SynthesizeResponse* resp) {
  v1::SynthesizeRequest req;
  req.set_controller_id(id);
  for (const auto& b : controller::testing::DriftingBeliefs(states, 4.0)) *req.add_beliefs() = b;
  auto ctx = Ctx();
  return stub->Synthesize(ctx.get(), req, resp);
}

}  // namespace kinemo::planner::store_test
