// Client side of the artifact RPCs for `kinemo <kind> push|ls|rm`: chunked
// uploads of local files, listings, deletion, against any address that serves
// the kind's owner (the service itself, or a coordinator, which forwards).
#pragma once

#include <CLI/CLI.hpp>

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "common/status/status.h"
#include "services/cli/channel.h"
#include "kinemo/common/v1/artifact.pb.h"

namespace kinemo::cli {

// $KINEMO_SERVER, else "localhost:50050" (the local stack's coordinator, or
// the all-in-one).
std::string DefaultServer();

struct PushSpec {
  std::string kind, id;
  // (name in the artifact, local path) per file.
  std::vector<std::pair<std::string, std::string>> files;
  bool overwrite = false;
  std::string description;
  std::vector<common::v1::ArtifactRef> depends_on;
  double timeout_s = 0;  // 0 = 60 s + 1 s per 10 MB
};

// Uploads the files in 1 MiB chunks to the service that owns spec.kind.
StatusOr<common::v1::PushArtifactResponse> PushArtifact(const std::shared_ptr<grpc::Channel>& channel,
                                                        const PushSpec& spec);
StatusOr<common::v1::ListArtifactsResponse> ListArtifacts(const std::shared_ptr<grpc::Channel>& channel,
                                                          const std::string& kind, bool all_versions,
                                                          double timeout_s = 10);
StatusOr<common::v1::DeleteArtifactResponse> DeleteArtifact(const std::shared_ptr<grpc::Channel>& channel,
                                                            const common::v1::ArtifactRef& ref,
                                                            double timeout_s = 10);

// Every kind one owner ("inference", "planner", "cube_tracker") holds.
StatusOr<common::v1::ListArtifactsResponse> ListOwnerArtifacts(const std::shared_ptr<grpc::Channel>& channel,
                                                               const std::string& owner, bool all_versions,
                                                               double timeout_s = 10);

// One line per artifact ("id  vN  size  created  description"; "kind/id"
// with `show_kind`), or a JSON array of the ArtifactInfo JSON mapping with
// `json`.
void PrintArtifacts(const common::v1::ListArtifactsResponse& list, bool json, bool show_kind = false);

// `kinemo <noun> push|ls|rm` for a kind whose artifact is one file:
//   push FILE --id ID [--server ADDR] [--overwrite] [--description T] [--json]
//   ls [--server ADDR] [--all] [--json]
//   rm ID[@VERSION] [--server ADDR]
struct ArtifactCommandSpec {
  std::string noun;       // "model": the command, and "kinemo model push: ..." in errors
  std::string kind;       // "models"
  std::string file_name;  // "model.kmodel": the name FILE is pushed under
  std::string file_help;  // "model file (kinemo crf train --out)"
  // The id option ("--id"; "--name,--id" for two spellings) and whether it
  // may be left out: then the id is FILE's stem, lower-cased, other
  // characters than [a-z0-9_-] as '-' ("Quaternius Man.glb" -> quaternius-man).
  std::string id_option = "--id";
  bool id_from_file_stem = false;
  // FILE must end in one of these (lower-case, with the dot); empty = any.
  std::vector<std::string> file_extensions;
};
void AddArtifactCommands(CLI::App* parent, const ArtifactCommandSpec& spec);

}  // namespace kinemo::cli
