#include "common/grpc/tls_credentials.h"

#include <fstream>
#include <sstream>

namespace kinemo {
namespace {

constexpr std::streamoff kMaxPemBytes = 1 << 20;

}  // namespace

ClientTlsFiles ClientTlsFilesAt(std::string_view prefix, std::string ca_file, std::string cert_file,
                                std::string key_file) {
  ClientTlsFiles files;
  files.ca_file = std::move(ca_file);
  files.cert_file = std::move(cert_file);
  files.key_file = std::move(key_file);
  files.ca_field = kinemo::StrCat(prefix, ".ca_file");
  files.cert_field = kinemo::StrCat(prefix, ".cert_file");
  files.key_field = kinemo::StrCat(prefix, ".key_file");
  return files;
}

StatusOr<std::string> ReadPemFile(const std::string& path, std::string_view field) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return InvalidField(field, "cannot read '", path, "'");
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0 || size > kMaxPemBytes) {
    return InvalidField(field, "'", path, "' is not a PEM file of at most ", kMaxPemBytes,
                        " bytes");
  }
  in.seekg(0);
  std::stringstream text;
  text << in.rdbuf();
  if (text.str().find("-----BEGIN") == std::string::npos) {
    return InvalidField(field, "'", path, "' is not a PEM file");
  }
  return text.str();
}

StatusOr<std::shared_ptr<grpc::ChannelCredentials>> MakeChannelCredentials(
    const ClientTlsFiles& files) {
  if (files.plaintext()) return grpc::InsecureChannelCredentials();
  if (files.cert_file.empty() != files.key_file.empty()) {
    return InvalidField(files.cert_file.empty() ? files.cert_field : files.key_field,
                        "a client certificate needs both ", files.cert_field, " and ",
                        files.key_field);
  }
  grpc::SslCredentialsOptions ssl;
  if (!files.ca_file.empty()) {
    KINEMO_ASSIGN_OR_RETURN(ssl.pem_root_certs, ReadPemFile(files.ca_file, files.ca_field));
  }
  if (!files.cert_file.empty()) {
    KINEMO_ASSIGN_OR_RETURN(ssl.pem_cert_chain, ReadPemFile(files.cert_file, files.cert_field));
    KINEMO_ASSIGN_OR_RETURN(ssl.pem_private_key, ReadPemFile(files.key_file, files.key_field));
  }
  return grpc::SslCredentials(ssl);
}

StatusOr<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(
    const common::v1::TlsOptions& tls) {
  if (tls.cert_file().empty()) return grpc::InsecureServerCredentials();
  grpc::SslServerCredentialsOptions ssl;
  KINEMO_ASSIGN_OR_RETURN(std::string cert, ReadPemFile(tls.cert_file(), "server.tls.cert_file"));
  KINEMO_ASSIGN_OR_RETURN(std::string key, ReadPemFile(tls.key_file(), "server.tls.key_file"));
  ssl.pem_key_cert_pairs.push_back({key, cert});
  if (!tls.client_ca_file().empty()) {
    KINEMO_ASSIGN_OR_RETURN(ssl.pem_root_certs,
                            ReadPemFile(tls.client_ca_file(), "server.tls.client_ca_file"));
    ssl.client_certificate_request = GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY;
  }
  return grpc::SslServerCredentials(ssl);
}

}  // namespace kinemo
