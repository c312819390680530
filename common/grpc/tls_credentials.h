// TLS credentials from PEM files, for both ends of every kinemo hop: the
// server bootstrap (ServerOptions.tls), the coordinator's channels
// (ServiceEndpoint ca_file / cert_file / key_file), the kinemo tools
// (--ca / --cert / --key) and kinemo-health. Material is made by
// deploy/certs.sh.
#pragma once

#include <grpcpp/security/credentials.h>
#include <grpcpp/security/server_credentials.h>

#include <memory>
#include <string>
#include <string_view>

#include "common/status/status.h"
#include "kinemo/common/v1/server.pb.h"

namespace kinemo {

// What a client presents and trusts, as paths to PEM files, each with the
// name errors give it (a request field, an option path or a flag).
struct ClientTlsFiles {
  std::string ca_file;    // CA bundle that verifies the server; "" = the system's roots
  std::string cert_file;  // client certificate chain (mutual TLS); "" = none
  std::string key_file;   // its private key
  std::string ca_field = "ca_file", cert_field = "cert_file", key_field = "key_file";
  // True when no file is named: the channel is plaintext.
  bool plaintext() const { return ca_file.empty() && cert_file.empty() && key_file.empty(); }
};

// The same files named "<prefix>.ca_file", "<prefix>.cert_file", "<prefix>.key_file".
ClientTlsFiles ClientTlsFilesAt(std::string_view prefix, std::string ca_file, std::string cert_file,
                                std::string key_file);

// Reads a PEM file (at most 1 MiB). INVALID_ARGUMENT naming `field` when it
// cannot be read or holds no PEM block.
StatusOr<std::string> ReadPemFile(const std::string& path, std::string_view field);

// Plaintext when `files.plaintext()`; else TLS that verifies the server with
// ca_file (or the system's roots) and, with cert_file and key_file, presents
// that client certificate (mutual TLS). INVALID_ARGUMENT naming the field when
// only one of cert_file / key_file is given or a file is unreadable.
StatusOr<std::shared_ptr<grpc::ChannelCredentials>> MakeChannelCredentials(
    const ClientTlsFiles& files);

// Plaintext when `tls` has no cert_file; else TLS with that certificate, and
// mutual TLS when client_ca_file is set: a client without a certificate
// signed by that CA is refused during the handshake. Errors name
// "server.tls.<field>".
StatusOr<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(
    const common::v1::TlsOptions& tls);

}  // namespace kinemo
