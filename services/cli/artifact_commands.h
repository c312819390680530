// The one implementation of the artifact commands `kinemo <noun> push|ls|rm`
// (model, rig, cube, library, controller, graph): their flags (--server ADDR,
// default DefaultServer(); --json; --all; ID[@VERSION]), the calls through
// artifact_client.h, and how results and errors print. `kinemo artifacts ls`
// prints with PrintArtifacts.
#pragma once

#include <CLI/CLI.hpp>

#include <string>
#include <string_view>
#include <vector>

#include "common/status/status.h"
#include "services/cli/artifact_client.h"

namespace kinemo::cli {

// How a family of artifact commands words its lines and errors. Two families,
// each kept as its users and scripts know it:
//  - kOneFile: `model`, `rig`, `cube` (AddArtifactCommands: an artifact of
//    one file). Errors name the subcommand ("kinemo model push: ..."); "stored
//    K/ID version N (X kB) at ADDR", "deleted K/ID version N"; a bad
//    ID@VERSION names `ID@VERSION`, an empty id is left to the service; a push
//    the store refuses as too large (RESOURCE_EXHAUSTED) is bad input.
//  - kBundle: `library`, `controller`, `graph` (their own push with
//    RunArtifactPush, then AddArtifactListAndRemove). Errors name the noun
//    ("kinemo library: ..."); "stored K/ID/N (F files, X kB) on DEP ...",
//    "deleted K/ID/N"; several kinds may share the noun (`graph`: gesture and
//    locomotion graphs; `rm --kind` picks one); `ls --all-versions` still
//    parses (deprecated).
enum class ArtifactStyle { kOneFile, kBundle };

// Ends `command` ("library", "model push") with its error: exit 2 for bad
// input, NOT_FOUND, ALREADY_EXISTS and refused deletions (and, kOneFile,
// RESOURCE_EXHAUSTED); 1 otherwise.
[[noreturn]] void FailArtifactCommand(const std::string& command, const Status& status,
                                      ArtifactStyle style = ArtifactStyle::kBundle);

// "bundled" -> version 0 (the newest); "bundled@2" -> version 2; errors name
// `field`.
StatusOr<common::v1::ArtifactRef> ParseArtifactRef(const std::string& kind, const std::string& text,
                                                   std::string_view field);

// Pushes `spec` to `server` and prints the stored version: one line, or its
// ArtifactInfo as JSON with `json`. `noun` names the command ("library").
void RunArtifactPush(const std::string& noun, const PushSpec& spec, const std::string& server, bool json,
                     ArtifactStyle style = ArtifactStyle::kBundle);

// Adds `ls` (every id of `kinds`, newest version or --all; a table or --json)
// and `rm ID[@V]` (with several kinds, --kind picks one when the id is in more
// than one) to `parent`. `noun` names it in messages ("library", "graph").
void AddArtifactListAndRemove(CLI::App* parent, const std::string& noun, const std::vector<std::string>& kinds,
                              ArtifactStyle style = ArtifactStyle::kBundle);

// One line per artifact ("id  vN  size  created  description"; "kind/id"
// with `show_kind`), or a JSON array of the ArtifactInfo JSON mapping with
// `json`.
void PrintArtifacts(const common::v1::ListArtifactsResponse& list, bool json, bool show_kind = false);

// `kinemo <noun> push|ls|rm` for a kind whose artifact is one file (kOneFile):
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
