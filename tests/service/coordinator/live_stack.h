// The real live stack of the coordinator's service tests: the prosody
// service, the inference service with a remapped CRF "crf" it trained on a
// synthetic corpus of real speech and real gesture capture (gc_models.h),
// and the planner with a controller "ctrl" built from it, hosted on one
// loopback server (made once per test binary: training takes seconds).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "common/server/service_host.h"
#include "common/testing/process.h"
#include "kinemo/inference/v1/options.pb.h"
#include "kinemo/planner/v1/options.pb.h"
#include "kinemo/prosody/v1/options.pb.h"
#include "services/inference/corpus/corpus.h"
#include "services/inference/inference_service.h"
#include "services/planner/rpc/planner_service.h"
#include "services/prosody/prosody_service.h"
#include "tests/service/coordinator/face_store.h"
#include "tests/service/coordinator/gc_models.h"

namespace kinemo::coordinator {

inline const std::string kData = KINEMO_TEST_DATA_DIR;

// A loopback server on an ephemeral port (messages up to
// `max_message_bytes`, 0 = the default 16 MiB).
inline std::unique_ptr<server::ServiceHost> Host(std::vector<server::HostedService> services,
                                                 std::uint32_t max_message_bytes = 0) {
  common::v1::ServerOptions o;
  o.set_host("127.0.0.1");
  o.set_port(0);
  o.set_shutdown_grace_s(0.5);
  o.set_max_message_bytes(max_message_bytes);
  auto h = server::ServiceHost::Start(o, "test", std::move(services));
  EXPECT_TRUE(h.ok()) << h.status();
  return h.ok() ? std::move(*h) : nullptr;
}

// Prosody, inference and planner with a trained model "crf" and a
// controller "ctrl", shared by the tests (training takes seconds). Made on
// first use and ended after the last test (`LiveStackCleanup`), so its
// services stop and its scratch directory, the planner's store included,
// goes: it outlived every test process before, 3 MiB of /tmp each.
class LiveStack {
  // Declared first, so it is removed after the services that write to it stop.
  kinemo::testing::TempDir dir_;

 public:
  static LiveStack& Get() {
    static LiveStack* stack = Made(new LiveStack(0));
    return *stack;
  }
  // The same stack on a server whose messages are at most 1 MiB (the
  // chunked calls of long recordings: tests/service/coordinator/
  // animate_chunked_test.cc); with the gesture graph "graph" too.
  static LiveStack& SmallMessages() {
    static LiveStack* stack = Made(new LiveStack(1 << 20));
    return *stack;
  }
  // Every stack made in this process, ended by LiveStackCleanup.
  static std::vector<std::unique_ptr<LiveStack>>& All() {
    static auto* all = new std::vector<std::unique_ptr<LiveStack>>;
    return *all;
  }
  std::uint32_t max_message_bytes = 0;
  std::string error;  // why the stack could not be made
  std::shared_ptr<prosody::ProsodyServiceImpl> prosody;
  std::unique_ptr<server::ServiceHost> services;

 private:
  static LiveStack* Made(LiveStack* stack) {
    All().emplace_back(stack);
    return stack;
  }
  explicit LiveStack(std::uint32_t message_bytes) : max_message_bytes(message_bytes) {
    inference::SyntheticCorpusOptions co;
    for (const char* s : {"0880", "0890", "0920", "0930"}) {
      co.speech_files.push_back(kData + "/speech/sense_and_sensibility_01_austen_64kb-" + s + ".wav");
    }
    for (const char* g : {"bow_normal", "bye_normal", "guide_happy", "guide_normal"}) {
      co.gesture_files.push_back(kData + "/planner_controller/dataset-1_" + g + "_001.bvh");
    }
    co.out_dir = dir_.File("corpora/tiny");
    co.renditions = 2;
    if (auto r = inference::BuildSyntheticCorpus(co); !r.ok()) {
      error = std::string(r.status().message());
      return;
    }
    // The face: a model trained on a real take in the prosody service's store.
    if (std::string e = MakeFaceStore(dir_.File("prosody-store")); !e.empty()) {
      error = "face model: " + e;
      return;
    }
    prosody::v1::ProsodyOptions pro;
    pro.set_store_dir(dir_.File("prosody-store"));
    prosody = std::make_shared<prosody::ProsodyServiceImpl>(pro);
    inference::v1::InferenceOptions io;
    io.set_store_dir(dir_.File("inference-store"));
    io.set_corpus_root(dir_.File("corpora"));
    auto inf = inference::InferenceServiceImpl::Create(io);
    planner::v1::PlannerOptions po;
    po.set_store_dir(dir_.File("planner-store"));
    po.set_library_root(kData + "/planner_controller");
    auto* preload = po.add_preload();
    preload->set_library_id("gestures");
    preload->add_paths("manifest.json");
    if (message_bytes > 0) {
      auto* graph = po.add_preload_gesture_graphs();
      graph->set_graph_id("graph");
      graph->set_library_id("gestures");
      graph->mutable_params()->set_stroke_phrases(true);
    }
    auto pl = planner::PlannerServiceImpl::Create(po);
    if (!inf.ok() || !pl.ok()) {
      error = std::string(!inf.ok() ? inf.status().message() : pl.status().message());
      return;
    }
    services = Host({{prosody, prosody::v1::ProsodyService::service_full_name()},
                     {*inf, inference::v1::InferenceService::service_full_name()},
                     {*pl, planner::v1::PlannerService::service_full_name()}},
                    message_bytes);
    auto channel = grpc::CreateCustomChannel(services->address(), grpc::InsecureChannelCredentials(),
                                             server::ChannelArgsForMessageLimit(message_bytes));
    auto inference_stub = inference::v1::InferenceService::NewStub(channel);
    auto planner_stub = planner::v1::PlannerService::NewStub(channel);
    Status s = testing::TrainModel(inference_stub.get(), "crf", "tiny");
    if (s.ok()) s = testing::BuildController(inference_stub.get(), planner_stub.get(), "crf", "ctrl", "gestures");
    if (!s.ok()) error = std::string(s.message());
  }
};

// Ends the stacks after the last test of the process (before static
// destruction, while gRPC is still whole).
class LiveStackCleanup : public ::testing::Environment {
 public:
  void TearDown() override { LiveStack::All().clear(); }
};
inline ::testing::Environment* const kLiveStackCleanup = ::testing::AddGlobalTestEnvironment(new LiveStackCleanup);

}  // namespace kinemo::coordinator
