// ServiceHost on real sockets: health, reflection, unix sockets, TLS and
// mutual TLS (certificates made with the openssl tool), bind failures.
#include "common/server/service_host.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <sstream>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/dynamic_message.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/support/byte_buffer.h>

#include "common/testing/process.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "kinemo/prosody/v1/prosody.grpc.pb.h"

namespace kinemo::server {
namespace {

using grpc::health::v1::Health;
using grpc::health::v1::HealthCheckRequest;
using grpc::health::v1::HealthCheckResponse;

common::v1::ServerOptions Loopback() {
  common::v1::ServerOptions o;
  o.set_host("127.0.0.1");
  o.set_port(0);
  o.set_shutdown_grace_s(1);
  return o;
}

grpc::Status Check(const std::shared_ptr<grpc::Channel>& ch, const std::string& service,
                   HealthCheckResponse* out) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  HealthCheckRequest req;
  req.set_service(service);
  return Health::NewStub(ch)->Check(&ctx, req, out);
}

// Lists services through server reflection, speaking the protocol with
// messages built from the descriptors gRPC's reflection library registers.
std::vector<std::string> ListServicesByReflection(const std::shared_ptr<grpc::Channel>& ch) {
  namespace pb = google::protobuf;
  const pb::DescriptorPool* pool = pb::DescriptorPool::generated_pool();
  const pb::Descriptor* req_d = pool->FindMessageTypeByName("grpc.reflection.v1alpha.ServerReflectionRequest");
  const pb::Descriptor* resp_d = pool->FindMessageTypeByName("grpc.reflection.v1alpha.ServerReflectionResponse");
  EXPECT_NE(req_d, nullptr);
  EXPECT_NE(resp_d, nullptr);
  if (req_d == nullptr || resp_d == nullptr) return {};
  pb::DynamicMessageFactory factory(pool);
  std::unique_ptr<pb::Message> req(factory.GetPrototype(req_d)->New());
  req->GetReflection()->SetString(req.get(), req_d->FindFieldByName("list_services"), "*");
  std::string wire;
  req->SerializeToString(&wire);

  grpc::GenericStub stub(ch);
  grpc::CompletionQueue cq;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  auto call = stub.PrepareCall(&ctx, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", &cq);
  void* tag;
  bool ok;
  call->StartCall(reinterpret_cast<void*>(1));
  cq.Next(&tag, &ok);
  grpc::Slice slice(wire);
  grpc::ByteBuffer out_buf(&slice, 1);
  call->Write(out_buf, reinterpret_cast<void*>(2));
  cq.Next(&tag, &ok);
  call->WritesDone(reinterpret_cast<void*>(3));
  cq.Next(&tag, &ok);
  grpc::ByteBuffer in_buf;
  call->Read(&in_buf, reinterpret_cast<void*>(4));
  cq.Next(&tag, &ok);
  std::vector<std::string> names;
  if (ok) {
    std::vector<grpc::Slice> slices;
    (void)in_buf.Dump(&slices);
    std::string data;
    for (const auto& s : slices) data.append(reinterpret_cast<const char*>(s.begin()), s.size());
    std::unique_ptr<pb::Message> resp(factory.GetPrototype(resp_d)->New());
    resp->ParseFromString(data);
    const auto* list_f = resp_d->FindFieldByName("list_services_response");
    const pb::Message& list = resp->GetReflection()->GetMessage(*resp, list_f);
    const auto* svc_f = list.GetDescriptor()->FindFieldByName("service");
    for (int i = 0; i < list.GetReflection()->FieldSize(list, svc_f); ++i) {
      const pb::Message& svc = list.GetReflection()->GetRepeatedMessage(list, svc_f, i);
      names.push_back(svc.GetReflection()->GetString(svc, svc.GetDescriptor()->FindFieldByName("name")));
    }
  }
  grpc::Status status;
  call->Finish(&status, reinterpret_cast<void*>(5));
  cq.Next(&tag, &ok);
  cq.Shutdown();
  while (cq.Next(&tag, &ok)) {
  }
  return names;
}

TEST(ServiceHost, EphemeralPortHealthAndReflection) {
  auto host = ServiceHost::Start(Loopback(), "test", {});
  ASSERT_TRUE(host.ok()) << host.status();
  EXPECT_GT((*host)->port(), 0);
  EXPECT_EQ((*host)->address(), "127.0.0.1:" + std::to_string((*host)->port()));
  auto ch = grpc::CreateChannel((*host)->address(), grpc::InsecureChannelCredentials());
  HealthCheckResponse resp;
  ASSERT_TRUE(Check(ch, "", &resp).ok());
  EXPECT_EQ(resp.status(), HealthCheckResponse::SERVING);
  // An unknown service name is NOT_FOUND, as the health protocol says.
  EXPECT_EQ(Check(ch, "no.such.Service", &resp).error_code(), grpc::StatusCode::NOT_FOUND);

  const auto names = ListServicesByReflection(ch);
  EXPECT_NE(std::find(names.begin(), names.end(), "grpc.health.v1.Health"), names.end());
  EXPECT_NE(std::find(names.begin(), names.end(), "grpc.reflection.v1alpha.ServerReflection"),
            names.end());
}

using kinemo::prosody::v1::ProsodyService;

TEST(ServiceHost, HostedServicesReportTheirOwnHealth) {
  // The generated base class of a kinemo service (every method answers
  // UNIMPLEMENTED): enough to check that the host registers it and reports
  // its health under its full name.
  auto svc = std::make_shared<ProsodyService::Service>();
  auto host = ServiceHost::Start(Loopback(), "test",
                                 {{svc, ProsodyService::service_full_name()}});
  ASSERT_TRUE(host.ok()) << host.status();
  auto ch = (*host)->InProcessChannel();
  HealthCheckResponse resp;
  ASSERT_TRUE(Check(ch, "kinemo.prosody.v1.ProsodyService", &resp).ok());
  EXPECT_EQ(resp.status(), HealthCheckResponse::SERVING);
  const auto names = ListServicesByReflection(ch);
  EXPECT_NE(std::find(names.begin(), names.end(), "kinemo.prosody.v1.ProsodyService"), names.end());
}

TEST(ServiceHost, MessagesOverTheLimitAreRefusedBeforeAnyHandler) {
  auto svc = std::make_shared<ProsodyService::Service>();
  auto opts = Loopback();
  opts.set_max_message_bytes(64 * 1024);
  auto host = ServiceHost::Start(opts, "limit", {{svc, ProsodyService::service_full_name()}});
  ASSERT_TRUE(host.ok());
  auto ch = grpc::CreateChannel((*host)->address(), grpc::InsecureChannelCredentials());
  auto stub = ProsodyService::NewStub(ch);
  auto call = [&](std::size_t bytes) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
    kinemo::prosody::v1::AnalyzeRequest req;
    req.mutable_audio()->set_data(std::string(bytes, '\x01'));
    kinemo::prosody::v1::AnalyzeResponse resp;
    return stub->Analyze(&ctx, req, &resp).error_code();
  };
  // Under the limit the call reaches the (unimplemented) handler...
  EXPECT_EQ(call(1000), grpc::StatusCode::UNIMPLEMENTED);
  // ...over it, the server refuses the message itself.
  EXPECT_EQ(call(200 * 1024), grpc::StatusCode::RESOURCE_EXHAUSTED);
}

TEST(ServiceHost, TwoServersCannotShareAPort) {
  auto first = ServiceHost::Start(Loopback(), "first", {});
  ASSERT_TRUE(first.ok());
  auto opts = Loopback();
  opts.set_port(static_cast<uint32_t>((*first)->port()));
  auto second = ServiceHost::Start(opts, "second", {});
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(second.status().message().find("server.host/server.port"), std::string::npos);
}

TEST(ServiceHost, InvalidOptionsAreRefusedBeforeStarting) {
  auto opts = Loopback();
  opts.set_log_level("shouty");
  auto host = ServiceHost::Start(opts, "bad", {});
  ASSERT_FALSE(host.ok());
  EXPECT_EQ(host.status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(ServiceHost, UnixSocket) {
  kinemo::testing::TempDir dir;
  auto opts = Loopback();
  opts.set_host("unix:" + dir.File("s.sock"));
  auto host = ServiceHost::Start(opts, "unix", {});
  ASSERT_TRUE(host.ok()) << host.status();
  EXPECT_EQ((*host)->port(), 0);
  auto ch = grpc::CreateChannel((*host)->address(), grpc::InsecureChannelCredentials());
  HealthCheckResponse resp;
  ASSERT_TRUE(Check(ch, "", &resp).ok());
  EXPECT_EQ(resp.status(), HealthCheckResponse::SERVING);
}

TEST(ServiceHost, ShutdownReportsNotServingThenStops) {
  auto host = ServiceHost::Start(Loopback(), "stop", {});
  ASSERT_TRUE(host.ok());
  const std::string addr = (*host)->address();
  (*host)->Shutdown();
  (*host)->Shutdown();  // idempotent
  auto ch = grpc::CreateChannel(addr, grpc::InsecureChannelCredentials());
  HealthCheckResponse resp;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(500));
  HealthCheckRequest req;
  EXPECT_FALSE(Health::NewStub(ch)->Check(&ctx, req, &resp).ok());
}

// --- TLS ------------------------------------------------------------------

std::string ReadAll(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

class TlsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (std::system("command -v openssl >/dev/null 2>&1") != 0) {
      GTEST_SKIP() << "openssl tool not installed";
    }
    const std::string d = dir_.path();
    // A CA, a server certificate for localhost/127.0.0.1, a client certificate.
    const std::string script =
        "cd " + d + " && "
        "openssl req -x509 -newkey rsa:2048 -nodes -keyout ca.key -out ca.pem -days 2 "
        "  -subj /CN=kinemo-test-ca >/dev/null 2>&1 && "
        "printf 'subjectAltName=DNS:localhost,IP:127.0.0.1\\n' > san.ext && "
        "openssl req -newkey rsa:2048 -nodes -keyout server.key -out server.csr -subj /CN=localhost "
        "  >/dev/null 2>&1 && "
        "openssl x509 -req -in server.csr -CA ca.pem -CAkey ca.key -CAcreateserial -out server.pem "
        "  -days 2 -extfile san.ext >/dev/null 2>&1 && "
        "openssl req -newkey rsa:2048 -nodes -keyout client.key -out client.csr -subj /CN=client "
        "  >/dev/null 2>&1 && "
        "openssl x509 -req -in client.csr -CA ca.pem -CAkey ca.key -CAcreateserial -out client.pem "
        "  -days 2 >/dev/null 2>&1";
    ASSERT_EQ(std::system(script.c_str()), 0);
  }
  std::shared_ptr<grpc::Channel> Channel(const std::string& addr, bool with_client_cert) {
    grpc::SslCredentialsOptions o;
    o.pem_root_certs = ReadAll(dir_.File("ca.pem"));
    if (with_client_cert) {
      o.pem_private_key = ReadAll(dir_.File("client.key"));
      o.pem_cert_chain = ReadAll(dir_.File("client.pem"));
    }
    grpc::ChannelArguments args;
    args.SetSslTargetNameOverride("localhost");
    return grpc::CreateCustomChannel(addr, grpc::SslCredentials(o), args);
  }
  kinemo::testing::TempDir dir_;
};

TEST_F(TlsTest, ServerTls) {
  auto opts = Loopback();
  opts.mutable_tls()->set_cert_file(dir_.File("server.pem"));
  opts.mutable_tls()->set_key_file(dir_.File("server.key"));
  auto host = ServiceHost::Start(opts, "tls", {});
  ASSERT_TRUE(host.ok()) << host.status();
  HealthCheckResponse resp;
  EXPECT_TRUE(Check(Channel((*host)->address(), false), "", &resp).ok());
  // A plaintext client cannot talk to a TLS server.
  auto plain = grpc::CreateChannel((*host)->address(), grpc::InsecureChannelCredentials());
  EXPECT_FALSE(Check(plain, "", &resp).ok());
}

TEST_F(TlsTest, MutualTlsRefusesClientsWithoutCertificate) {
  auto opts = Loopback();
  opts.mutable_tls()->set_cert_file(dir_.File("server.pem"));
  opts.mutable_tls()->set_key_file(dir_.File("server.key"));
  opts.mutable_tls()->set_client_ca_file(dir_.File("ca.pem"));
  auto host = ServiceHost::Start(opts, "mtls", {});
  ASSERT_TRUE(host.ok()) << host.status();
  HealthCheckResponse resp;
  EXPECT_TRUE(Check(Channel((*host)->address(), true), "", &resp).ok());
  EXPECT_FALSE(Check(Channel((*host)->address(), false), "", &resp).ok());
}

TEST_F(TlsTest, GarbageCertificateIsAClearError) {
  std::ofstream(dir_.File("junk.pem")) << "not a certificate";
  auto opts = Loopback();
  opts.mutable_tls()->set_cert_file(dir_.File("junk.pem"));
  opts.mutable_tls()->set_key_file(dir_.File("server.key"));
  auto host = ServiceHost::Start(opts, "junk", {});
  ASSERT_FALSE(host.ok());
  EXPECT_NE(host.status().message().find("server.tls.cert_file"), std::string::npos);
}

}  // namespace
}  // namespace kinemo::server
