#include "services/cli/artifact_commands.h"

#include <cstdio>
#include <memory>

#include "services/cli/commands.h"
#include "services/cli/proto_json.h"

namespace kinemo::cli {
namespace {
namespace artifact_commands {  // this file's own helpers (the unity build puts files together)

namespace cv1 = ::kinemo::common::v1;

struct ListFlags {
  std::string server = DefaultServer();
  bool all_versions = false, json = false;
};

struct RemoveFlags {
  std::string server = DefaultServer();
  std::string ref, kind;
};

void RunList(const std::string& command, const std::vector<std::string>& kinds, const ListFlags& f) {
  auto channel = ServerChannel(f.server);
  cv1::ListArtifactsResponse all;
  for (const auto& kind : kinds) {
    auto list = ListArtifacts(channel, kind, f.all_versions);
    if (!list.ok()) FailArtifactCommand(command, list.status());
    if (!f.json && kinds.size() > 1) {
      std::printf("%s:\n", kind.c_str());
      PrintArtifacts(*list, false);
    }
    for (const auto& a : list->artifacts()) *all.add_artifacts() = a;
    all.set_in_memory(all.in_memory() || list->in_memory());
  }
  if (f.json || kinds.size() == 1) PrintArtifacts(all, f.json);
}

void RunRemove(const std::string& command, const std::vector<std::string>& kinds, const RemoveFlags& f) {
  auto channel = ServerChannel(f.server);
  std::string kind = kinds.front();
  if (kinds.size() > 1) {
    // The kind holding the id (--kind when several do).
    std::vector<std::string> holders;
    auto probe = ParseArtifactRef(kinds.front(), f.ref, "ID");
    if (!probe.ok()) FailArtifactCommand(command, probe.status());
    for (const auto& k : kinds) {
      if (!f.kind.empty() && k.rfind(f.kind, 0) != 0) continue;
      auto list = ListArtifacts(channel, k, false);
      if (!list.ok()) FailArtifactCommand(command, list.status());
      for (const auto& a : list->artifacts()) {
        if (a.ref().id() == probe->id()) holders.push_back(k);
      }
    }
    if (holders.empty()) FailArtifactCommand(command, absl::NotFoundError(kinemo::StrCat("ID: no '", probe->id(), "'")));
    if (holders.size() > 1) {
      FailArtifactCommand(command, InvalidField("--kind", "'", probe->id(), "' is in ", holders[0], " and ",
                                                holders[1], "; say which"));
    }
    kind = holders.front();
  }
  auto ref = ParseArtifactRef(kind, f.ref, "ID");
  if (!ref.ok()) FailArtifactCommand(command, ref.status());
  auto deleted = DeleteArtifact(channel, *ref);
  if (!deleted.ok()) FailArtifactCommand(command, deleted.status());
  for (const auto& d : deleted->deleted()) {
    std::printf("deleted %s/%s/%u\n", d.ref().kind().c_str(), d.ref().id().c_str(), d.ref().version());
  }
}

}  // namespace artifact_commands
}  // namespace

void FailArtifactCommand(const std::string& command, const Status& status) {
  FailCommand(command, status,
              {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound, absl::StatusCode::kAlreadyExists,
               absl::StatusCode::kFailedPrecondition});
}

StatusOr<common::v1::ArtifactRef> ParseArtifactRef(const std::string& kind, const std::string& text,
                                                   std::string_view field) {
  using namespace artifact_commands;
  cv1::ArtifactRef ref;
  ref.set_kind(kind);
  const auto at = text.find('@');
  ref.set_id(text.substr(0, at));
  if (at != std::string::npos) {
    const std::string v = text.substr(at + 1);
    char* end = nullptr;
    const unsigned long version = std::strtoul(v.c_str(), &end, 10);
    if (v.empty() || *end != '\0' || version == 0 || version > 999999999ul) {
      return InvalidField(field, "'", text, "': the version after @ must be a number >= 1");
    }
    ref.set_version(static_cast<std::uint32_t>(version));
  }
  if (ref.id().empty()) return InvalidField(field, "'", text, "' has no id");
  return ref;
}

void RunArtifactPush(const std::string& command, const PushSpec& spec, const std::string& server, bool json) {
  using namespace artifact_commands;
  auto pushed = PushArtifact(ServerChannel(server), spec);
  if (!pushed.ok()) FailArtifactCommand(command, pushed.status());
  for (const auto& w : pushed->warnings()) std::fprintf(stderr, "kinemo %s: warning: %s\n", command.c_str(), w.c_str());
  const cv1::ArtifactInfo& a = pushed->artifact();
  if (json) {
    std::printf("%s\n", ProtoJson(a).c_str());
    return;
  }
  std::printf("stored %s/%s/%u (%zu files, %.1f kB)", a.ref().kind().c_str(), a.ref().id().c_str(),
              a.ref().version(), static_cast<size_t>(a.files_size()), static_cast<double>(a.size_bytes()) / 1000.0);
  for (const auto& d : a.depends_on()) {
    std::printf(" on %s/%s/%u", d.kind().c_str(), d.id().c_str(), d.version());
  }
  std::printf("\n");
}

void AddArtifactListAndRemove(CLI::App* parent, const std::string& command, const std::vector<std::string>& kinds) {
  using namespace artifact_commands;
  std::string what;
  for (const auto& k : kinds) what += (what.empty() ? "" : " and ") + k;
  auto lf = std::make_shared<ListFlags>();
  CLI::App* ls = parent->add_subcommand("ls", "List the stored " + what + " (newest version of each id)");
  ls->add_option("--server", lf->server, "Address of the planner or a coordinator (default $KINEMO_SERVER or localhost:50050)");
  ls->add_flag("--all", lf->all_versions, "Every version, not only the newest");
  AddDeprecatedOption(ls, "--all-versions", "--all", lf->all_versions);
  ls->add_flag("--json", lf->json, "Print a JSON array of ArtifactInfo");
  ls->callback([command, kinds, lf] { RunList(command, kinds, *lf); });

  auto rf = std::make_shared<RemoveFlags>();
  CLI::App* rm = parent->add_subcommand("rm", "Delete a stored version (ID@V) or every version (ID)");
  rm->add_option("ID", rf->ref, "ID or ID@VERSION")->required();
  rm->add_option("--server", rf->server, "Address of the planner or a coordinator (default $KINEMO_SERVER or localhost:50050)");
  if (kinds.size() > 1) rm->add_option("--kind", rf->kind, "Which kind when the id is in several (prefix: gesture, locomotion)");
  rm->callback([command, kinds, rf] { RunRemove(command, kinds, *rf); });
}

}  // namespace kinemo::cli
