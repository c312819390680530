// `kinemo model push|ls|rm` (inference models in the inference service's
// store) and `kinemo artifacts ls` (every kind from every owner reachable at
// an address), against a service, a coordinator (which forwards) or the
// all-in-one. See docs/store.md.
//
//   kinemo model push MODEL.kmodel --id ID [--server ADDR] [--overwrite] [--description T] [--json]
//   kinemo model ls [--server ADDR] [--all] [--json]
//   kinemo model rm ID[@VERSION] [--server ADDR]
//   kinemo artifacts ls [--server ADDR] [--all] [--json]
#include <CLI/CLI.hpp>

#include <cstdio>
#include <iostream>

#include "services/cli/artifact_commands.h"
#include "services/cli/commands.h"

namespace kinemo::cli {

void RegisterArtifactCommands(CLI::App& app) {
  CLI::App* model = app.add_subcommand("model", "Inference models in the stack's store: push, ls, rm");
  model->require_subcommand(1);
  AddArtifactCommands(model, {.noun = "model",
                              .kind = "models",
                              .file_name = "model.kmodel",
                              .file_help = "model file (as `kinemo crf train --out` writes)"});

  struct Flags {
    std::string server = DefaultServer();
    bool all = false, json = false;
  };
  auto f = std::make_shared<Flags>();
  CLI::App* artifacts = app.add_subcommand("artifacts", "Every stored artifact of every service at an address");
  artifacts->require_subcommand(1);
  CLI::App* ls = artifacts->add_subcommand("ls", "List models, libraries, controllers, graphs and cubes");
  ls->add_option("--server", f->server, "address of the stack (default $KINEMO_SERVER or localhost:50050)");
  ls->add_flag("--all", f->all, "every version");
  ls->add_flag("--json", f->json, "print a JSON array of ArtifactInfo");
  ls->callback([f] {
    auto channel = ServerChannel(f->server);
    common::v1::ListArtifactsResponse all;
    int answered = 0;
    for (const char* owner : {"inference", "planner", "cube_tracker"}) {
      auto r = ListOwnerArtifacts(channel, owner, f->all);
      if (!r.ok()) {
        std::cerr << "kinemo artifacts ls: " << r.status().message() << "\n";
        continue;
      }
      ++answered;
      for (auto& a : *r->mutable_artifacts()) *all.add_artifacts() = std::move(a);
      if (r->in_memory() && !f->json) std::cerr << owner << ": no store_dir, its artifacts live in memory only\n";
    }
    if (answered == 0) throw CliExit{1};
    PrintArtifacts(all, f->json, /*show_kind=*/true);
  });
}

}  // namespace kinemo::cli
