// grpc.reflection.v1 served beside v1alpha by every ServiceHost: a v1 client
// (stubs compiled from proto/grpc/reflection/v1/reflection.proto) lists the
// services, fetches descriptors and gets errors on one stream, as from v1alpha.
#include <google/protobuf/descriptor.pb.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <thread>

#include "common/server/service_host.h"
#include "grpc/reflection/v1/reflection.grpc.pb.h"
#include "kinemo/prosody/v1/prosody.grpc.pb.h"

namespace kinemo::server {
namespace {

namespace refl = ::grpc::reflection::v1;
using kinemo::prosody::v1::ProsodyService;

class ReflectionV1 : public ::testing::Test {
 protected:
  void SetUp() override {
    common::v1::ServerOptions o;
    o.set_host("127.0.0.1");
    o.set_port(0);
    o.set_shutdown_grace_s(1);
    auto host = ServiceHost::Start(
        o, "reflection",
        {{std::make_shared<ProsodyService::Service>(), ProsodyService::service_full_name()}});
    ASSERT_TRUE(host.ok()) << host.status();
    host_ = std::move(*host);
    stub_ = refl::ServerReflection::NewStub(
        grpc::CreateChannel(host_->address(), grpc::InsecureChannelCredentials()));
  }
  // Sends `requests` on one stream; returns the responses, in order.
  std::vector<refl::ServerReflectionResponse> Ask(
      const std::vector<refl::ServerReflectionRequest>& requests, grpc::Status* status) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    auto stream = stub_->ServerReflectionInfo(&ctx);
    std::vector<refl::ServerReflectionResponse> responses;
    for (const auto& request : requests) {
      refl::ServerReflectionResponse response;
      if (!stream->Write(request) || !stream->Read(&response)) break;
      responses.push_back(response);
    }
    stream->WritesDone();
    *status = stream->Finish();
    return responses;
  }
  std::unique_ptr<ServiceHost> host_;
  std::unique_ptr<refl::ServerReflection::Stub> stub_;
};

refl::ServerReflectionRequest ListServices() {
  refl::ServerReflectionRequest r;
  r.set_list_services("*");
  return r;
}

std::vector<std::string> Names(const refl::ServerReflectionResponse& response) {
  std::vector<std::string> names;
  for (const auto& s : response.list_services_response().service()) names.push_back(s.name());
  std::sort(names.begin(), names.end());
  return names;
}

TEST_F(ReflectionV1, ListsTheServicesBesideV1Alpha) {
  grpc::Status status;
  const auto responses = Ask({ListServices()}, &status);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_EQ(responses.size(), 1u);
  EXPECT_TRUE(responses[0].has_list_services_response());
  EXPECT_EQ(responses[0].original_request().list_services(), "*");
  EXPECT_EQ(Names(responses[0]),
            (std::vector<std::string>{
                "grpc.health.v1.Health", "grpc.reflection.v1.ServerReflection",
                "grpc.reflection.v1alpha.ServerReflection", "kinemo.prosody.v1.ProsodyService"}));
}

TEST_F(ReflectionV1, AnswersEveryQuestionOfAStreamInOrder) {
  refl::ServerReflectionRequest by_symbol;
  by_symbol.set_file_containing_symbol(ProsodyService::service_full_name());
  refl::ServerReflectionRequest by_name;
  by_name.set_file_by_filename("kinemo/prosody/v1/prosody.proto");
  refl::ServerReflectionRequest missing;
  missing.set_file_containing_symbol("kinemo.no.such.Service");
  grpc::Status status;
  const auto responses = Ask({by_symbol, missing, by_name, ListServices()}, &status);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_EQ(responses.size(), 4u);
  // The file that defines the service, with the files it imports.
  ASSERT_TRUE(responses[0].has_file_descriptor_response());
  std::vector<std::string> files;
  for (const std::string& bytes : responses[0].file_descriptor_response().file_descriptor_proto()) {
    google::protobuf::FileDescriptorProto file;
    ASSERT_TRUE(file.ParseFromString(bytes));
    files.push_back(file.name());
    if (file.name() == "kinemo/prosody/v1/prosody.proto") {
      ASSERT_GE(file.service_size(), 1);
      EXPECT_EQ(file.service(0).name(), "ProsodyService");
    }
  }
  EXPECT_NE(std::find(files.begin(), files.end(), "kinemo/prosody/v1/prosody.proto"), files.end());
  EXPECT_GT(files.size(), 1u);
  // An unknown symbol: an error answer on the stream, which goes on.
  ASSERT_TRUE(responses[1].has_error_response());
  EXPECT_EQ(responses[1].error_response().error_code(),
            static_cast<int>(grpc::StatusCode::NOT_FOUND));
  EXPECT_EQ(responses[1].original_request().file_containing_symbol(), "kinemo.no.such.Service");
  ASSERT_TRUE(responses[2].has_file_descriptor_response());
  // Each service once, also late in a stream (gRPC 1.51's v1alpha would
  // repeat what earlier answers of the stream held).
  EXPECT_EQ(Names(responses[3]), Names(Ask({ListServices()}, &status)[0]));
  EXPECT_EQ(Names(responses[3]).size(), 4u);
}

TEST_F(ReflectionV1, ConcurrentStreamsAndAClientThatGoesAway) {
  std::vector<std::thread> clients;
  std::atomic<int> answered{0};
  for (int i = 0; i < 8; ++i) {
    clients.emplace_back([&] {
      grpc::Status status;
      for (int round = 0; round < 5; ++round) {
        const auto responses = Ask({ListServices(), ListServices()}, &status);
        if (status.ok() && responses.size() == 2 && Names(responses[1]).size() == 4u) ++answered;
      }
    });
  }
  // A client that cancels its stream with a question outstanding.
  {
    grpc::ClientContext ctx;
    auto stream = stub_->ServerReflectionInfo(&ctx);
    ASSERT_TRUE(stream->Write(ListServices()));
    ctx.TryCancel();
    EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::CANCELLED);
  }
  for (auto& t : clients) t.join();
  EXPECT_EQ(answered.load(), 40);
  // The server shuts down cleanly with the relay's streams gone.
  host_->Shutdown();
}

TEST(ReflectionV1InProcess, ServedOnInProcessServersToo) {
  auto host = ServiceHost::StartInProcess("in_process", {}, 0);
  ASSERT_TRUE(host.ok()) << host.status();
  auto stub = refl::ServerReflection::NewStub((*host)->InProcessChannel());
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  auto stream = stub->ServerReflectionInfo(&ctx);
  refl::ServerReflectionResponse response;
  ASSERT_TRUE(stream->Write(ListServices()));
  ASSERT_TRUE(stream->Read(&response));
  stream->WritesDone();
  EXPECT_TRUE(stream->Finish().ok());
  EXPECT_EQ(Names(response), (std::vector<std::string>{
                                 "grpc.health.v1.Health", "grpc.reflection.v1.ServerReflection",
                                 "grpc.reflection.v1alpha.ServerReflection"}));
}

}  // namespace
}  // namespace kinemo::server
