// The planner's GMG/BodySpeech RPCs in process (ServiceHost + InProcessChannel)
// on real Bandai-Namco gesture clips (tests/data/planner_gesture) and pitch
// accents of real LibriVox speech (tests/data/speech) from the prosody
// pipeline.
#include <chrono>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "common/audio/decode.h"
#include "common/motion/bvh.h"
#include "common/server/service_host.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "services/planner/rpc/planner_service.h"
#include "services/prosody/core/pipeline.h"
#include "tests/service/planner_gesture/speech_accents.h"

namespace kinemo::planner {
namespace {

const std::string kData = KINEMO_TEST_DATA_DIR;

class GestureServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    common::v1::ServerOptions server;
    server.set_host("127.0.0.1");
    server.set_port(0);
    v1::PlannerOptions options;
    options.set_library_root(kData);
    auto service = PlannerServiceImpl::Create(options);
    ASSERT_TRUE(service.ok()) << service.status();
    auto host = server::ServiceHost::Start(server, "planner", {{*service, v1::PlannerService::service_full_name()}});
    ASSERT_TRUE(host.ok()) << host.status();
    host_ = *std::move(host);
    stub_ = v1::PlannerService::NewStub(host_->InProcessChannel());
  }
  void TearDown() override { host_->Shutdown(); }

  static void SetDeadline(grpc::ClientContext* ctx, int seconds = 60) {
    ctx->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(seconds));
  }

  void LoadAndBuild() {
    v1::LoadLibraryRequest load;
    load.set_library_id("gestures");
    load.add_paths("planner_gesture");
    v1::LoadLibraryResponse loaded;
    grpc::ClientContext c1;
    SetDeadline(&c1);
    ASSERT_TRUE(stub_->LoadLibrary(&c1, load, &loaded).ok());
    EXPECT_GT(loaded.library().phrases(), 4u);
    for (const auto& c : loaded.library().clips()) EXPECT_GE(c.phrases(), 1u) << c.name();

    v1::BuildGestureGraphRequest build;
    build.set_graph_id("gmg");
    build.set_library_id("gestures");
    for (double st : {0.3, 1.0, 3.0}) build.add_sweep_thresholds(st);
    grpc::ClientContext c2;
    SetDeadline(&c2);
    const grpc::Status s = stub_->BuildGestureGraph(&c2, build, &graph_);
    ASSERT_TRUE(s.ok()) << s.error_message();
  }

  static std::vector<common::v1::PitchAccent> SpeechAccents(double* duration_s) {
    return testing::SpeechAccents(duration_s);
  }

  std::unique_ptr<server::ServiceHost> host_;
  std::unique_ptr<v1::PlannerService::Stub> stub_;
  v1::BuildGestureGraphResponse graph_;
};

// Well-formed LoadLibrary requests with numbers out of bounds, or two inline
// clips of one name, are refused naming the field and store nothing.
TEST_F(GestureServiceTest, LoadLibraryRefusesOutOfBoundsValuesNamingTheField) {
  std::ifstream in(kData + "/planner_gesture/dataset-1_bye_angry_001.bvh");
  std::stringstream bvh;
  bvh << in.rdbuf();
  ASSERT_FALSE(bvh.str().empty());
  struct Case {
    std::function<void(v1::LoadLibraryRequest&)> mutate;
    std::string field;
  };
  const std::vector<Case> cases = {
      {[](v1::LoadLibraryRequest& r) { r.set_meters_per_unit(1e308); }, "meters_per_unit: "},
      {[](v1::LoadLibraryRequest& r) { r.set_meters_per_unit(-0.01); }, "meters_per_unit: "},
      {[](v1::LoadLibraryRequest& r) { r.mutable_segmentation()->set_interruption_frames(4294967295u); },
       "segmentation.interruption_frames: "},
      {[](v1::LoadLibraryRequest& r) { r.mutable_segmentation()->set_min_segment_s(1e308); },
       "segmentation.min_segment_s: "},
      {[&](v1::LoadLibraryRequest& r) {
         for (int i = 0; i < 2; ++i) {
           auto* c = r.add_clips();
           c->set_name("wave");
           c->set_bvh(bvh.str());
         }
       },
       "clips[1].name: "},
  };
  for (const Case& c : cases) {
    v1::LoadLibraryRequest load;
    load.set_library_id("bounded");
    load.add_paths("planner_gesture");
    c.mutate(load);
    v1::LoadLibraryResponse loaded;
    grpc::ClientContext ctx;
    SetDeadline(&ctx);
    const grpc::Status st = stub_->LoadLibrary(&ctx, load, &loaded);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << c.field;
    EXPECT_EQ(st.error_message().rfind(c.field, 0), 0u) << st.error_message();
  }
  // Nothing was stored: the id is still free (no overwrite needed).
  v1::LoadLibraryRequest load;
  load.set_library_id("bounded");
  load.add_paths("planner_gesture");
  load.set_meters_per_unit(0.01);
  v1::LoadLibraryResponse loaded;
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  const grpc::Status st = stub_->LoadLibrary(&ctx, load, &loaded);
  EXPECT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(loaded.library().version(), 1u);
}

TEST_F(GestureServiceTest, BuildsTheGraphWithSweep) {
  LoadAndBuild();
  const auto& g = graph_.graph();
  EXPECT_EQ(g.graph_id(), "gmg");
  EXPECT_EQ(g.version(), 1u);
  ASSERT_EQ(graph_.sweep_size(), 3);
  EXPECT_LE(graph_.sweep(0).branching_factor(), graph_.sweep(1).branching_factor());
  EXPECT_EQ(g.stats().scc_size(), graph_.sweep(1).scc_size());
  ASSERT_GT(g.phrases_size(), 1);
  EXPECT_TRUE(g.phrases(g.phrases_size() - 1).rest_pose());
  for (int i = 0; i + 1 < g.phrases_size(); ++i) {
    const auto& p = g.phrases(i);
    EXPECT_LT(p.start_s(), p.end_s());
    EXPECT_GE(p.gsi(), 0);
    EXPECT_LE(p.gsi(), 1);
    EXPECT_FALSE(p.phases().empty());
  }
  // Same id again needs overwrite.
  v1::BuildGestureGraphRequest again;
  again.set_graph_id("gmg");
  again.set_library_id("gestures");
  v1::BuildGestureGraphResponse r;
  grpc::ClientContext c;
  EXPECT_EQ(stub_->BuildGestureGraph(&c, again, &r).error_code(), grpc::StatusCode::ALREADY_EXISTS);
}

TEST_F(GestureServiceTest, SynthesizesGesturesAndVisemes) {
  LoadAndBuild();
  double duration = 0;
  auto accents = SpeechAccents(&duration);
  ASSERT_GE(accents.size(), 3u);
  for (auto alg : {v1::GESTURE_ALGORITHM_GMG, v1::GESTURE_ALGORITHM_BODYSPEECH}) {
    v1::SynthesizeGesturesRequest req;
    req.set_graph_id("gmg");
    for (const auto& a : accents) *req.add_accents() = a;
    req.set_duration_s(duration);
    req.set_algorithm(alg);
    // Phones with the timing of the speech's syllables: real times.
    common::v1::Phone ph;
    ph.set_phone("AH");
    ph.set_start_s(accents[0].syllable_start_s());
    ph.set_end_s(accents[0].syllable_end_s());
    *req.add_phones() = ph;
    req.set_include_visemes(true);
    v1::SynthesizeGesturesResponse resp;
    grpc::ClientContext ctx;
    SetDeadline(&ctx);
    const grpc::Status s = stub_->SynthesizeGestures(&ctx, req, &resp);
    ASSERT_TRUE(s.ok()) << s.error_message();
    ASSERT_EQ(resp.report_size(), static_cast<int>(accents.size()));
    int placed = 0;
    std::string reasons;
    for (const auto& r : resp.report()) {
      if (!r.placed()) {
        EXPECT_FALSE(r.skipped_reason().empty());
        reasons += r.skipped_reason() + "; ";
        continue;
      }
      ++placed;
      EXPECT_GE(r.papt_s() - r.apex_s(), -0.03 - 1e-9);
      EXPECT_LE(r.papt_s() - r.apex_s(), 0.22 + 1e-9);
      EXPECT_NE(r.edge().kind(), v1::GESTURE_EDGE_KIND_UNSPECIFIED);
    }
    EXPECT_GT(placed, 0) << reasons;
    auto clip = motion::ParseBvh(resp.motion().bvh(), "response");
    ASSERT_TRUE(clip.ok()) << clip.status();
    EXPECT_GE(clip->duration_s(), duration - clip->frame_time_s);
    EXPECT_GT(resp.visemes().frames_size(), 0);
    EXPECT_EQ(resp.visemes().categories_size(), 15);
  }
}

TEST_F(GestureServiceTest, VisemesAndErrors) {
  v1::VisemesRequest vr;
  const char* phones[] = {"SIL", "HH", "EH", "L", "OW", "SIL"};
  for (int i = 0; i < 6; ++i) {
    auto* p = vr.add_phones();
    p->set_phone(phones[i]);
    p->set_start_s(0.1 * i);
    p->set_end_s(0.1 * (i + 1));
  }
  v1::VisemesResponse resp;
  grpc::ClientContext c1;
  ASSERT_TRUE(stub_->Visemes(&c1, vr, &resp).ok());
  EXPECT_EQ(resp.track().frames_size(), 19);
  for (const auto& f : resp.track().frames()) {
    double s = 0;
    for (double w : f.weights()) s += w;
    EXPECT_NEAR(s, 1, 1e-9);
  }
  // Out-of-order phones name the field.
  vr.mutable_phones(3)->set_start_s(0.05);
  grpc::ClientContext c2;
  auto st = stub_->Visemes(&c2, vr, &resp);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(st.error_message().find("phones[3]"), std::string::npos);
  // A track of 1e9 s is refused, not allocated.
  vr.mutable_phones(3)->set_start_s(0.3);
  vr.set_duration_s(1e9);
  grpc::ClientContext c5;
  st = stub_->Visemes(&c5, vr, &resp);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(st.error_message(), "duration_s: 1e+09 is not in [0, 7200] s");
  vr.set_duration_s(0);
  vr.mutable_phones(5)->set_end_s(1e7);
  grpc::ClientContext c6;
  st = stub_->Visemes(&c6, vr, &resp);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(st.error_message().rfind("phones[5].end_s: ", 0), 0u) << st.error_message();
  // Unknown graph.
  v1::SynthesizeGesturesRequest sr;
  sr.set_graph_id("nope");
  v1::SynthesizeGesturesResponse sresp;
  grpc::ClientContext c3;
  EXPECT_EQ(stub_->SynthesizeGestures(&c3, sr, &sresp).error_code(), grpc::StatusCode::NOT_FOUND);
  // Unknown library.
  v1::BuildGestureGraphRequest br;
  br.set_graph_id("g");
  br.set_library_id("nope");
  v1::BuildGestureGraphResponse bresp;
  grpc::ClientContext c4;
  EXPECT_EQ(stub_->BuildGestureGraph(&c4, br, &bresp).error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(GestureServiceTest, RejectsAccentsOutOfOrder) {
  LoadAndBuild();
  v1::SynthesizeGesturesRequest req;
  req.set_graph_id("gmg");
  req.add_accents()->set_time_s(2.0);
  req.add_accents()->set_time_s(1.0);
  v1::SynthesizeGesturesResponse resp;
  grpc::ClientContext ctx;
  auto st = stub_->SynthesizeGestures(&ctx, req, &resp);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(st.error_message().find("accents[1]"), std::string::npos) << st.error_message();
}

}  // namespace
}  // namespace kinemo::planner
