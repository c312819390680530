// The `push`, `ls` and `rm` subcommands that every artifact command shares
// (`kinemo library|controller|graph ...`): flags --server ADDR (default
// DefaultServer()), --json, ID[@VERSION] arguments, and how results print.
#pragma once

#include <CLI/CLI.hpp>

#include <string>
#include <vector>

#include "common/status/status.h"
#include "services/cli/artifact_client.h"

namespace kinemo::cli {

// Ends `command` with its error (exit 2 for bad input, NOT_FOUND,
// ALREADY_EXISTS and refused deletions; 1 otherwise).
[[noreturn]] void FailArtifactCommand(const std::string& command, const Status& status);

// "bundled" -> version 0 (the newest); "bundled@2" -> version 2.
StatusOr<common::v1::ArtifactRef> ParseArtifactRef(const std::string& kind, const std::string& text,
                                                   std::string_view field);

// Pushes `spec` to `server` and prints the stored version: one line, or its
// ArtifactInfo as JSON with `json`.
void RunArtifactPush(const std::string& command, const PushSpec& spec, const std::string& server, bool json);

// Adds `ls` (every id of `kinds`, newest version or --all; a table
// or --json) and `rm ID[@V]` (with several kinds, --kind picks one when the
// id is in more than one) to `parent`. `command` names it in messages
// ("library", "graph").
void AddArtifactListAndRemove(CLI::App* parent, const std::string& command, const std::vector<std::string>& kinds);

}  // namespace kinemo::cli
