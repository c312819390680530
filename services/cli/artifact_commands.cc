// The artifact commands `kinemo <noun> push|ls|rm`, one implementation for
// every noun (artifact_commands.h says how the two families print).
#include "services/cli/artifact_commands.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <iostream>
#include <memory>

#include "absl/strings/str_join.h"
#include "services/cli/commands.h"
#include "services/cli/proto_json.h"

namespace kinemo::cli {
namespace {
namespace artifact_commands {  // this file's own helpers (the unity build puts files together)

namespace cv1 = ::kinemo::common::v1;

bool OneFile(ArtifactStyle style) { return style == ArtifactStyle::kOneFile; }

// Who errors name: "model ls" (kOneFile) or "library" (kBundle).
std::string CommandOf(const std::string& noun, const char* subcommand, ArtifactStyle style) {
  return OneFile(style) ? noun + " " + subcommand : noun;
}

// The help texts of each family's flags.
struct Words {
  const char* server;
  const char* all;
  const char* json;
  const char* id;
};
const Words& WordsOf(ArtifactStyle style) {
  static const Words one_file{"address of the stack (default $KINEMO_SERVER or localhost:50050)", "every version",
                              "print a JSON array of ArtifactInfo", "id, or id@version"};
  static const Words bundle{"Address of the planner or a coordinator (default $KINEMO_SERVER or localhost:50050)",
                            "Every version, not only the newest", "Print a JSON array of ArtifactInfo",
                            "ID or ID@VERSION"};
  return OneFile(style) ? one_file : bundle;
}

StatusOr<cv1::ArtifactRef> ParseRef(const std::string& kind, const std::string& text, std::string_view field,
                                    ArtifactStyle style) {
  cv1::ArtifactRef ref;
  ref.set_kind(kind);
  const std::size_t at = text.find('@');
  ref.set_id(text.substr(0, at));
  if (at != std::string::npos) {
    const std::string v = text.substr(at + 1);
    if (v.empty() || v.size() > 9 || v.find_first_not_of("0123456789") != std::string::npos || std::stoul(v) == 0) {
      if (OneFile(style)) return InvalidField("ID@VERSION", "'", text, "': the version must be a number from 1");
      return InvalidField(field, "'", text, "': the version after @ must be a number >= 1");
    }
    ref.set_version(static_cast<std::uint32_t>(std::stoul(v)));
  }
  // kOneFile leaves an empty id to the service, which names ref.id.
  if (ref.id().empty() && !OneFile(style)) return InvalidField(field, "'", text, "' has no id");
  return ref;
}

// "Quaternius Man.glb" -> "quaternius-man".
std::string IdFromFileStem(const std::string& file) {
  std::string id = std::filesystem::path(file).stem().string();
  for (char& c : id) {
    c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    if (!((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '-')) c = '-';
  }
  return id.substr(0, 64);
}

struct ListFlags {
  std::string server = DefaultServer();
  bool all_versions = false, json = false;
};

struct RemoveFlags {
  std::string server = DefaultServer();
  std::string ref, kind;
};

void RunList(const std::string& command, const std::vector<std::string>& kinds, ArtifactStyle style,
             const ListFlags& f) {
  auto channel = ServerChannel(f.server);
  cv1::ListArtifactsResponse all;
  for (const auto& kind : kinds) {
    auto list = ListArtifacts(channel, kind, f.all_versions);
    if (!list.ok()) FailArtifactCommand(command, list.status(), style);
    if (!f.json && kinds.size() > 1) {
      std::printf("%s:\n", kind.c_str());
      PrintArtifacts(*list, false);
    }
    for (const auto& a : list->artifacts()) *all.add_artifacts() = a;
    all.set_in_memory(all.in_memory() || list->in_memory());
  }
  if (f.json || kinds.size() == 1) PrintArtifacts(all, f.json);
}

void RunRemove(const std::string& command, const std::vector<std::string>& kinds, ArtifactStyle style,
               const RemoveFlags& f) {
  auto channel = ServerChannel(f.server);
  std::string kind = kinds.front();
  if (kinds.size() > 1) {
    // The kind holding the id (--kind when several do).
    std::vector<std::string> holders;
    auto probe = ParseRef(kinds.front(), f.ref, "ID", style);
    if (!probe.ok()) FailArtifactCommand(command, probe.status(), style);
    for (const auto& k : kinds) {
      if (!f.kind.empty() && k.rfind(f.kind, 0) != 0) continue;
      auto list = ListArtifacts(channel, k, false);
      if (!list.ok()) FailArtifactCommand(command, list.status(), style);
      for (const auto& a : list->artifacts()) {
        if (a.ref().id() == probe->id()) holders.push_back(k);
      }
    }
    if (holders.empty()) {
      FailArtifactCommand(command, absl::NotFoundError(kinemo::StrCat("ID: no '", probe->id(), "'")), style);
    }
    if (holders.size() > 1) {
      FailArtifactCommand(command, InvalidField("--kind", "'", probe->id(), "' is in ", holders[0], " and ",
                                                holders[1], "; say which"), style);
    }
    kind = holders.front();
  }
  auto ref = ParseRef(kind, f.ref, "ID", style);
  if (!ref.ok()) FailArtifactCommand(command, ref.status(), style);
  auto deleted = DeleteArtifact(channel, *ref);
  if (!deleted.ok()) FailArtifactCommand(command, deleted.status(), style);
  for (const auto& d : deleted->deleted()) {
    std::printf(OneFile(style) ? "deleted %s/%s version %u\n" : "deleted %s/%s/%u\n", d.ref().kind().c_str(),
                d.ref().id().c_str(), d.ref().version());
  }
}

}  // namespace artifact_commands
}  // namespace

void FailArtifactCommand(const std::string& command, const Status& status, ArtifactStyle style) {
  using namespace artifact_commands;
  if (OneFile(style)) {
    FailCommand(command, status,
                {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound, absl::StatusCode::kAlreadyExists,
                 absl::StatusCode::kFailedPrecondition, absl::StatusCode::kResourceExhausted});
  }
  FailCommand(command, status,
              {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound, absl::StatusCode::kAlreadyExists,
               absl::StatusCode::kFailedPrecondition});
}

StatusOr<common::v1::ArtifactRef> ParseArtifactRef(const std::string& kind, const std::string& text,
                                                   std::string_view field) {
  using namespace artifact_commands;
  return ParseRef(kind, text, field, ArtifactStyle::kBundle);
}

void RunArtifactPush(const std::string& noun, const PushSpec& spec, const std::string& server, bool json,
                     ArtifactStyle style) {
  using namespace artifact_commands;
  const std::string command = CommandOf(noun, "push", style);
  auto pushed = PushArtifact(ServerChannel(server), spec);
  if (!pushed.ok()) FailArtifactCommand(command, pushed.status(), style);
  if (!OneFile(style)) {
    for (const auto& w : pushed->warnings()) std::fprintf(stderr, "kinemo %s: warning: %s\n", noun.c_str(), w.c_str());
  }
  const cv1::ArtifactInfo& a = pushed->artifact();
  if (json) {
    std::printf("%s\n", ProtoJson(a).c_str());
  } else if (OneFile(style)) {
    std::printf("stored %s/%s version %u (%.1f kB) at %s\n", a.ref().kind().c_str(), a.ref().id().c_str(),
                a.ref().version(), static_cast<double>(a.size_bytes()) / 1000.0, server.c_str());
  } else {
    std::printf("stored %s/%s/%u (%zu files, %.1f kB)", a.ref().kind().c_str(), a.ref().id().c_str(),
                a.ref().version(), static_cast<size_t>(a.files_size()), static_cast<double>(a.size_bytes()) / 1000.0);
    for (const auto& d : a.depends_on()) {
      std::printf(" on %s/%s/%u", d.kind().c_str(), d.id().c_str(), d.version());
    }
    std::printf("\n");
  }
  if (OneFile(style)) {
    for (const auto& w : pushed->warnings()) std::cerr << "warning: " << w << "\n";
  }
}

void AddArtifactListAndRemove(CLI::App* parent, const std::string& noun, const std::vector<std::string>& kinds,
                              ArtifactStyle style) {
  using namespace artifact_commands;
  const Words& words = WordsOf(style);
  std::string what;
  for (const auto& k : kinds) what += (what.empty() ? "" : " and ") + k;
  auto lf = std::make_shared<ListFlags>();
  CLI::App* ls = parent->add_subcommand(
      "ls", "List the stored " + what + (OneFile(style) ? " (the newest" : " (newest") + " version of each id)");
  ls->add_option("--server", lf->server, words.server);
  ls->add_flag("--all", lf->all_versions, words.all);
  if (!OneFile(style)) AddDeprecatedOption(ls, "--all-versions", "--all", lf->all_versions);
  ls->add_flag("--json", lf->json, words.json);
  ls->callback([command = CommandOf(noun, "ls", style), kinds, style, lf] { RunList(command, kinds, style, *lf); });

  auto rf = std::make_shared<RemoveFlags>();
  CLI::App* rm = parent->add_subcommand(
      "rm", OneFile(style) ? "Delete a " + noun + " (every version, or ID@VERSION)"
                           : std::string("Delete a stored version (ID@V) or every version (ID)"));
  rm->add_option("ID", rf->ref, words.id)->required();
  rm->add_option("--server", rf->server, words.server);
  if (kinds.size() > 1) rm->add_option("--kind", rf->kind, "Which kind when the id is in several (prefix: gesture, locomotion)");
  rm->callback([command = CommandOf(noun, "rm", style), kinds, style, rf] { RunRemove(command, kinds, style, *rf); });
}

void PrintArtifacts(const common::v1::ListArtifactsResponse& list, bool json, bool show_kind) {
  if (json) {
    std::printf("[");
    for (int i = 0; i < list.artifacts_size(); ++i) {
      std::printf("%s%s", i ? ",\n " : "", ProtoJson(list.artifacts(i)).c_str());
    }
    std::printf("]\n");
    return;
  }
  for (const auto& a : list.artifacts()) {
    char when[32] = "";
    const std::time_t t = static_cast<std::time_t>(a.created_unix_ms() / 1000);
    std::tm tm{};
    if (gmtime_r(&t, &tm) != nullptr) std::strftime(when, sizeof when, "%Y-%m-%d %H:%M:%SZ", &tm);
    const std::string name = show_kind ? a.ref().kind() + "/" + a.ref().id() : a.ref().id();
    std::printf("%-32s v%-3u %10.1f kB  %s  %s\n", name.c_str(), a.ref().version(),
                static_cast<double>(a.size_bytes()) / 1000.0, when, a.description().c_str());
  }
  if (list.in_memory()) std::printf("(the service has no store_dir: these live in memory only)\n");
}

void AddArtifactCommands(CLI::App* parent, const ArtifactCommandSpec& spec) {
  using namespace artifact_commands;
  struct Flags {
    std::string server = DefaultServer(), file, id, description;
    bool overwrite = false, json = false;
  };
  auto f = std::make_shared<Flags>();
  const Words& words = WordsOf(ArtifactStyle::kOneFile);
  CLI::App* push = parent->add_subcommand("push", "Upload a " + spec.noun + " to the service that owns it");
  push->add_option("FILE", f->file, spec.file_help)->required();
  auto* id = push->add_option(spec.id_option, f->id, "the id it is stored and called by ([a-z0-9_-]{1,64})" +
                                                       std::string(spec.id_from_file_stem ? "; default: FILE's stem" : ""));
  if (!spec.id_from_file_stem) id->required();
  push->add_option("--server", f->server, words.server);
  push->add_flag("--overwrite", f->overwrite, "store a new version when the id exists");
  push->add_option("--description", f->description, "stored with it");
  push->add_flag("--json", f->json, "print the stored version's ArtifactInfo as JSON");
  push->callback([f, spec] {
    if (!spec.file_extensions.empty()) {
      std::string ext = std::filesystem::path(f->file).extension().string();
      for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      if (std::find(spec.file_extensions.begin(), spec.file_extensions.end(), ext) == spec.file_extensions.end()) {
        FailArtifactCommand(spec.noun + " push",
                            InvalidField("FILE", f->file, " must end in ", absl::StrJoin(spec.file_extensions, " or ")),
                            ArtifactStyle::kOneFile);
      }
    }
    PushSpec p;
    p.kind = spec.kind;
    p.id = f->id.empty() ? IdFromFileStem(f->file) : f->id;
    p.files = {{spec.file_name, f->file}};
    p.overwrite = f->overwrite;
    p.description = f->description;
    RunArtifactPush(spec.noun, p, f->server, f->json, ArtifactStyle::kOneFile);
  });
  AddArtifactListAndRemove(parent, spec.noun, {spec.kind}, ArtifactStyle::kOneFile);
}

}  // namespace kinemo::cli
