#include "services/coordinator/client/cube_session.h"

#include <chrono>
#include <fstream>
#include <sstream>

#include <google/protobuf/text_format.h>
#include <grpcpp/grpcpp.h>

#include "common/grpc/status_mapping.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"

namespace kinemo::coordinator {
namespace {

void SetDeadline(grpc::ClientContext* ctx, double s) {
  ctx->set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(static_cast<long long>(s * 1000)));
}

}  // namespace

StatusOr<std::string> OpenCubeSession(const std::shared_ptr<grpc::Channel>& channel, const CubeSessionOptions& o) {
  auto stub = v1::CoordinatorService::NewStub(channel);
  v1::AttachCubeRequest attach;
  if (!o.cube_model_file.empty()) {
    std::ifstream in(o.cube_model_file);
    std::stringstream ss;
    ss << in.rdbuf();
    if (!in || !google::protobuf::TextFormat::ParseFromString(ss.str(), attach.mutable_config()->mutable_cube_model()))
      return InvalidField("cube_model_file", "'", o.cube_model_file, "' is not a readable CubeModel text proto");
  }
  v1::OpenSessionRequest open;
  open.set_session_id(o.session_id);
  open.set_robot_id(o.robot_id);
  open.set_vleo(v1::VLEO_KIND_CUBE);
  open.set_vleo_name("cube video");
  open.set_initial_emotion(o.initial);
  v1::OpenSessionResponse opened;
  {
    grpc::ClientContext ctx;
    SetDeadline(&ctx, o.timeout_s);
    const grpc::Status s = stub->OpenSession(&ctx, open, &opened);
    if (!s.ok()) return Annotate(FromGrpcStatus(s, "coordinator"), "OpenSession");
  }
  const std::string id = opened.session().session_id();
  attach.set_session_id(id);
  attach.mutable_source()->set_video_file(o.video);
  attach.mutable_source()->set_realtime(o.realtime);
  if (!o.camera.empty()) attach.mutable_config()->set_intrinsics_file(o.camera);
  {
    grpc::ClientContext ctx;
    SetDeadline(&ctx, o.timeout_s);
    v1::AttachCubeResponse r;
    const grpc::Status s = stub->AttachCube(&ctx, attach, &r);
    if (!s.ok()) {
      (void)CloseCubeSession(channel, id);
      return Annotate(FromGrpcStatus(s, "coordinator"), "AttachCube");
    }
  }
  return id;
}

StatusOr<v1::Session> GetCubeSession(const std::shared_ptr<grpc::Channel>& channel, const std::string& session_id) {
  grpc::ClientContext ctx;
  SetDeadline(&ctx, 10);
  v1::GetSessionRequest g;
  g.set_session_id(session_id);
  v1::Session s;
  const grpc::Status st = v1::CoordinatorService::NewStub(channel)->GetSession(&ctx, g, &s);
  if (!st.ok()) return Annotate(FromGrpcStatus(st, "coordinator"), "GetSession");
  return s;
}

Status CloseCubeSession(const std::shared_ptr<grpc::Channel>& channel, const std::string& session_id) {
  grpc::ClientContext ctx;
  SetDeadline(&ctx, 10);
  v1::CloseSessionRequest c;
  c.set_session_id(session_id);
  v1::CloseSessionResponse r;
  const grpc::Status st = v1::CoordinatorService::NewStub(channel)->CloseSession(&ctx, c, &r);
  if (!st.ok()) return Annotate(FromGrpcStatus(st, "coordinator"), "CloseSession");
  return absl::OkStatus();
}

}  // namespace kinemo::coordinator
