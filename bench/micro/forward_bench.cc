// The cost of the coordinator's front door: the same calls to a cube tracker
// service over loopback TCP, directly and through the forwarder
// (services/coordinator/forwarder.h) on a second loopback server.
//   ListArtifacts: a unary call answering 20 stored cube models;
//   PushArtifact: a client stream pushing the Vleo cube (tests/data/cube/vleo.cube)
//                 as a new version (validated, committed with fsync).
#include <benchmark/benchmark.h>
#include <stdlib.h>

#include <filesystem>
#include <fstream>

#include <grpcpp/grpcpp.h>

#include "common/server/service_host.h"
#include "services/coordinator/forwarder.h"
#include "services/cube_tracker/cube_tracker_service.h"

namespace kinemo::coordinator {
namespace {

namespace cv1 = ::kinemo::common::v1;
namespace ct = ::kinemo::cube_tracker;

struct Stack {
  std::string store;
  std::unique_ptr<server::ServiceHost> tracker, front;
  std::unique_ptr<ct::v1::CubeTrackerService::Stub> direct, forwarded;
  std::string cube_text;
  bool ok = false;

  Stack() {
    std::string dir = (std::filesystem::temp_directory_path() / "kinemo-forward-bench-XXXXXX").string();
    if (::mkdtemp(dir.data()) == nullptr) return;
    store = dir;
    std::ifstream in(std::string(KINEMO_TEST_DATA_DIR) + "/cube/vleo.cube");
    cube_text.assign(std::istreambuf_iterator<char>(in), {});
    ct::v1::CubeTrackerOptions o;
    o.set_store_dir(store);
    auto svc = ct::CubeTrackerService::Create(o);
    if (!svc.ok()) return;
    common::v1::ServerOptions so;
    so.set_host("127.0.0.1");
    so.set_port(0);
    so.set_shutdown_grace_s(1);
    auto t = server::ServiceHost::Start(so, "tracker", {{*svc, ct::v1::CubeTrackerService::service_full_name()}});
    if (!t.ok()) return;
    tracker = *std::move(t);
    auto channel = grpc::CreateChannel(tracker->address(), grpc::InsecureChannelCredentials());
    auto forwarder = std::make_shared<Forwarder>(
        std::map<std::string, ForwardTarget>{{ct::v1::CubeTrackerService::service_full_name(), {channel, ""}}},
        std::map<std::string, std::string>{}, false);
    auto f = server::ServiceHost::Start(so, "front", {{.generic = forwarder}});
    if (!f.ok()) return;
    front = *std::move(f);
    direct = ct::v1::CubeTrackerService::NewStub(channel);
    forwarded = ct::v1::CubeTrackerService::NewStub(
        grpc::CreateChannel(front->address(), grpc::InsecureChannelCredentials()));
    for (int i = 0; i < 20; ++i) {
      if (!Push(*direct, "cube" + std::to_string(i))) return;
    }
    ok = true;
  }
  ~Stack() {
    if (front) front->Shutdown();
    if (tracker) tracker->Shutdown();
    std::error_code ec;
    if (!store.empty()) std::filesystem::remove_all(store, ec);
  }

  bool Push(ct::v1::CubeTrackerService::Stub& stub, const std::string& id) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    cv1::PushArtifactResponse response;
    auto writer = stub.PushArtifact(&ctx, &response);
    cv1::PushArtifactRequest req;
    auto* h = req.mutable_header();
    h->mutable_ref()->set_kind("cubes");
    h->mutable_ref()->set_id(id);
    h->set_overwrite(true);
    auto* file = h->add_files();
    file->set_name("cube.textproto");
    file->set_size_bytes(cube_text.size());
    writer->Write(req);
    req.Clear();
    req.mutable_chunk()->set_data(cube_text);
    writer->Write(req);
    writer->WritesDone();
    return writer->Finish().ok();
  }
};

Stack& GetStack() {
  static Stack* stack = new Stack();
  return *stack;
}

void BM_ListArtifacts(benchmark::State& state) {
  Stack& s = GetStack();
  if (!s.ok) {
    state.SkipWithError("the stack did not start");
    return;
  }
  auto& stub = state.range(0) == 0 ? *s.direct : *s.forwarded;
  cv1::ListArtifactsRequest req;
  cv1::ListArtifactsResponse resp;
  for (auto _ : state) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    resp.Clear();
    if (!stub.ListArtifacts(&ctx, req, &resp).ok() || resp.artifacts_size() != 20) {
      state.SkipWithError("ListArtifacts failed");
      return;
    }
  }
  state.SetLabel(state.range(0) == 0 ? "direct" : "through the forwarder");
}
BENCHMARK(BM_ListArtifacts)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond)->UseRealTime();

void BM_PushArtifact(benchmark::State& state) {
  Stack& s = GetStack();
  if (!s.ok) {
    state.SkipWithError("the stack did not start");
    return;
  }
  auto& stub = state.range(0) == 0 ? *s.direct : *s.forwarded;
  for (auto _ : state) {
    if (!s.Push(stub, "pushed")) {
      state.SkipWithError("PushArtifact failed");
      return;
    }
  }
  state.SetLabel(state.range(0) == 0 ? "direct" : "through the forwarder");
}
BENCHMARK(BM_PushArtifact)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond)->UseRealTime()->Iterations(200);

}  // namespace
}  // namespace kinemo::coordinator
