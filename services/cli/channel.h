// The channels of the kinemo tools (kinemo, kinemo-vision, kinemo-health):
// every command that calls a service opens its channel here, so that one set
// of options decides plaintext, TLS or mutual TLS for all of them:
//   --ca FILE    CA bundle (PEM) that verifies the server  ($KINEMO_TLS_CA)
//   --cert FILE  client certificate (PEM), for mutual TLS  ($KINEMO_TLS_CERT)
//   --key FILE   its private key (PEM)                     ($KINEMO_TLS_KEY)
// None given = plaintext. deploy/certs.sh makes cli.pem / cli.key and ca.pem.
#pragma once

#include <CLI/CLI.hpp>
#include <memory>
#include <string>

#include "common/grpc/tls_credentials.h"

// Declared, not included: <grpcpp/grpcpp.h> is the heaviest header of the
// tool, and most commands that include this file only pass channels on.
namespace grpc {
class Channel;
}  // namespace grpc

namespace kinemo::cli {

// Adds --ca, --cert and --key to `app` (the top-level command) and lets every
// subcommand, added before or after this call, accept them after its own
// arguments (`kinemo session get ID --ca ca.pem ...`). Values default to the
// environment variables above.
void AddTlsOptions(CLI::App& app);

// The TLS files the options (or the environment) name; field names are the
// flags ("--ca", "--cert", "--key").
ClientTlsFiles CliTlsFiles();

// A channel to `address` with the TLS the options name and 512 MiB message
// limits. Bad TLS options (an unreadable or non-PEM file, a certificate
// without its key) print "kinemo: --cert: ..." and end the command with exit
// code 2.
std::shared_ptr<grpc::Channel> ServerChannel(const std::string& address);

// A plaintext channel (512 MiB limits) to a server this process started
// itself on loopback (e.g. the embedded kinemo_allinone of `kinemo animate`).
std::shared_ptr<grpc::Channel> LocalChannel(const std::string& address);

}  // namespace kinemo::cli
