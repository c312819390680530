// Credentials from PEM files: plaintext when nothing is named, and errors that
// name the field (a flag, an option path) for every inconsistent or unreadable
// input. Handshakes with real certificates are tested in
// tests/service/server (ServiceHost) and tests/integration/tls.
#include "common/grpc/tls_credentials.h"

#include <gtest/gtest.h>

#include <fstream>

#include "common/testing/process.h"

namespace kinemo {
namespace {

class TlsCredentials : public ::testing::Test {
 protected:
  void SetUp() override {
    std::ofstream(dir_.File("a.pem"))
        << "-----BEGIN CERTIFICATE-----\nAAAA\n-----END CERTIFICATE-----\n";
    std::ofstream(dir_.File("junk.pem")) << "not a certificate";
  }
  kinemo::testing::TempDir dir_;
};

TEST_F(TlsCredentials, NothingNamedIsPlaintext) {
  ClientTlsFiles files;
  EXPECT_TRUE(files.plaintext());
  EXPECT_TRUE(MakeChannelCredentials(files).ok());
  EXPECT_TRUE(MakeServerCredentials(common::v1::TlsOptions()).ok());
}

TEST_F(TlsCredentials, ErrorsNameTheField) {
  auto error = [](const ClientTlsFiles& files) {
    auto c = MakeChannelCredentials(files);
    EXPECT_FALSE(c.ok());
    EXPECT_EQ(c.status().code(), absl::StatusCode::kInvalidArgument);
    return std::string(c.status().message());
  };
  ClientTlsFiles f =
      ClientTlsFilesAt("services.prosody", dir_.File("a.pem"), dir_.File("a.pem"), "");
  EXPECT_EQ(error(f).rfind("services.prosody.key_file: ", 0), 0u) << error(f);
  f = ClientTlsFilesAt("services.prosody", dir_.File("a.pem"), "", dir_.File("a.pem"));
  EXPECT_EQ(error(f).rfind("services.prosody.cert_file: ", 0), 0u) << error(f);
  f = ClientTlsFilesAt("services.planner", dir_.File("missing.pem"), "", "");
  EXPECT_EQ(error(f).rfind("services.planner.ca_file: cannot read", 0), 0u) << error(f);
  ClientTlsFiles flags;
  flags.ca_field = "--ca";
  flags.ca_file = dir_.File("junk.pem");
  EXPECT_EQ(error(flags).rfind("--ca: ", 0), 0u) << error(flags);
  EXPECT_NE(error(flags).find("not a PEM file"), std::string::npos);
}

TEST_F(TlsCredentials, ServerErrorsNameTheOptionPath) {
  common::v1::TlsOptions tls;
  tls.set_cert_file(dir_.File("a.pem"));
  tls.set_key_file(dir_.File("junk.pem"));
  auto s = MakeServerCredentials(tls);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(std::string(s.status().message()).rfind("server.tls.key_file: ", 0), 0u) << s.status();
  tls.set_key_file(dir_.File("a.pem"));
  tls.set_client_ca_file(dir_.File("missing.pem"));
  s = MakeServerCredentials(tls);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(std::string(s.status().message()).rfind("server.tls.client_ca_file: ", 0), 0u)
      << s.status();
}

}  // namespace
}  // namespace kinemo
