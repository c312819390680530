#include "services/cli/channel.h"

#include <grpcpp/create_channel.h>
#include <grpcpp/support/channel_arguments.h>

#include <cstdlib>
#include <iostream>

#include "services/cli/commands.h"

namespace kinemo::cli {
namespace {

struct TlsOptions {
  std::string ca, cert, key;
};

TlsOptions& Options() {
  static TlsOptions options;
  return options;
}

std::string Env(const char* name) {
  const char* value = std::getenv(name);
  return value == nullptr ? "" : value;
}

grpc::ChannelArguments LargeMessages() {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(512 << 20);
  args.SetMaxSendMessageSize(512 << 20);
  return args;
}

}  // namespace

void AddTlsOptions(CLI::App& app) {
  TlsOptions& o = Options();
  // Environment first; an option on the command line replaces it.
  o.ca = Env("KINEMO_TLS_CA");
  o.cert = Env("KINEMO_TLS_CERT");
  o.key = Env("KINEMO_TLS_KEY");
  auto* group =
      app.add_option_group("TLS", "Channel security of every command that calls a service");
  group->add_option("--ca", o.ca,
                    "CA bundle (PEM) that verifies the server; TLS (default $KINEMO_TLS_CA)");
  group->add_option("--cert", o.cert,
                    "client certificate (PEM) for mutual TLS (default $KINEMO_TLS_CERT)");
  group->add_option("--key", o.key, "private key (PEM) of --cert (default $KINEMO_TLS_KEY)");
  // Subcommands inherit fallthrough when created after this; set it on
  // those created before as well, so options they do not know reach the top.
  app.fallthrough();
  std::vector<CLI::App*> pending = app.get_subcommands([](CLI::App*) { return true; });
  while (!pending.empty()) {
    CLI::App* sub = pending.back();
    pending.pop_back();
    sub->fallthrough();
    for (CLI::App* child : sub->get_subcommands([](CLI::App*) { return true; }))
      pending.push_back(child);
  }
}

ClientTlsFiles CliTlsFiles() {
  const TlsOptions& o = Options();
  ClientTlsFiles files;
  files.ca_file = o.ca;
  files.cert_file = o.cert;
  files.key_file = o.key;
  files.ca_field = "--ca";
  files.cert_field = "--cert";
  files.key_field = "--key";
  return files;
}

std::shared_ptr<grpc::Channel> ServerChannel(const std::string& address) {
  auto credentials = MakeChannelCredentials(CliTlsFiles());
  if (!credentials.ok()) {
    std::cerr << "kinemo: " << credentials.status().message() << "\n";
    throw CliExit{2};
  }
  return grpc::CreateCustomChannel(address, *credentials, LargeMessages());
}

std::shared_ptr<grpc::Channel> LocalChannel(const std::string& address) {
  return grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), LargeMessages());
}

}  // namespace kinemo::cli
