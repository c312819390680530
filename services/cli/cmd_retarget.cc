// kinemo retarget IN.bvh|IN.vrma --to RIG.glb -o OUT.glb|OUT.bvh [--map MAP.json] [--json]
//
// Motion on any kinemo skeleton (SMPL-X, Bandai, CMU, iClone, ...) onto a
// character's rig (glTF/GLB/VRM, or a BVH skeleton): common/retarget. A GLB
// output is the character with the motion as its first animation; a BVH
// output is the motion on the rig's skeleton (its rest = bind pose); a VRMA
// output (VRM characters) is a VRM Animation any VRM app plays.

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>

#include "common/face/face_json.h"
#include "common/motion/bvh.h"
#include "common/motion/motion_check.h"
#include "common/retarget/measures.h"
#include "common/retarget/face_map.h"
#include "common/retarget/fbx.h"
#include "common/retarget/gltf.h"
#include "common/retarget/retarget.h"
#include "common/retarget/rig.h"
#include "common/retarget/rig_info.h"
#include "services/cli/artifact_commands.h"
#include "services/cli/commands.h"
#include "services/cli/retarget_files.h"

namespace kinemo::cli {
namespace {
namespace cmd_retarget {  // this file's own helpers (the unity build puts files together)

bool HasExtension(const std::string& path, std::initializer_list<std::string_view> exts) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  for (std::string_view e : exts) {
    if (ext == e) return true;
  }
  return false;
}

StatusOr<std::string> ReadText(const std::string& path, std::string_view field) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(kinemo::StrCat(field, ": cannot read ", path));
  std::stringstream ss;
  ss << in.rdbuf();
  if (ss.str().size() > (size_t{1} << 20)) return InvalidField(field, "larger than 1 MiB");
  return ss.str();
}

}  // namespace cmd_retarget
}  // namespace

Status ValidateRetargetFiles(const RetargetFiles& f) {
  using namespace cmd_retarget;
  if (!HasExtension(f.input, {".bvh", ".vrma"})) {
    return InvalidField(f.input_option, "must be a .bvh file or a VRM Animation (.vrma), got ", f.input);
  }
  if (!HasExtension(f.rig, {".glb", ".gltf", ".vrm", ".fbx", ".bvh"})) {
    return InvalidField(f.rig_field, "must be a .glb, .gltf, .vrm, .fbx or .bvh rig, got ", f.rig);
  }
  std::error_code ec;
  if (!std::filesystem::exists(f.rig, ec)) return absl::NotFoundError(kinemo::StrCat(f.rig_field, ": ", f.rig, ": no such file"));
  if (!HasExtension(f.output, {".glb", ".fbx", ".bvh", ".vrma"})) {
    return InvalidField(f.output_option, "must end in .glb, .fbx, .bvh or .vrma, got ", f.output);
  }
  if (HasExtension(f.output, {".vrma"}) && !HasExtension(f.rig, {".vrm", ".glb", ".gltf"})) {
    return InvalidField(f.output_option, "a VRM Animation (.vrma) needs a VRM character (", f.rig_field,
                        " RIG.vrm): its humanoid and T-pose");
  }
  if (HasExtension(f.output, {".fbx"}) && !HasExtension(f.rig, {".fbx"})) {
    return InvalidField(f.output_option, "an FBX needs an FBX rig (", f.rig_field,
                        "); write .glb for glTF/VRM characters");
  }
  if (HasExtension(f.output, {".glb"}) && HasExtension(f.rig, {".bvh"})) {
    return InvalidField(f.output_option, "a GLB needs a glTF/VRM/FBX rig (", f.rig_field,
                        "); write .bvh for a BVH skeleton");
  }
  if (f.source_meters_per_unit < 0 || f.source_meters_per_unit > 10) {
    return InvalidField("--source-meters-per-unit", "must be in 0..10 (0 = estimate), got ", f.source_meters_per_unit);
  }
  return absl::OkStatus();
}

StatusOr<retarget::Rig> LoadTargetRig(const RetargetFiles& f) {
  using namespace cmd_retarget;
  retarget::RoleMapChoice choice;
  if (!f.map.empty()) {
    KINEMO_ASSIGN_OR_RETURN(choice.map_json, ReadText(f.map, "--map"));
    choice.map_source = f.map;
  }
  if (HasExtension(f.rig, {".bvh"})) {
    auto rig_clip = motion::ReadBvhFile(f.rig);
    if (!rig_clip.ok()) return Annotate(rig_clip.status(), f.rig_field);
    KINEMO_ASSIGN_OR_RETURN(retarget::Rig target, retarget::RigFromSkeleton(rig_clip->skeleton, 1.0, f.rig, choice));
    target.meters_per_unit = retarget::EstimateMetersPerUnit(target);
    return target;
  }
  auto target = retarget::LoadGltfRig(f.rig, choice);
  if (!target.ok()) return Annotate(target.status(), f.rig_field);
  return target;
}

StatusOr<retarget::FaceMap> LoadFaceMap(const RetargetFiles& f, const retarget::Rig& rig) {
  using namespace cmd_retarget;
  retarget::FaceMapOptions options;
  if (!f.face_map.empty()) {
    KINEMO_ASSIGN_OR_RETURN(options.map_json, ReadText(f.face_map, "--face-map"));
    options.map_source = "--face-map " + f.face_map;
  }
  auto map = retarget::FaceMap::Create(rig, options);
  if (!map.ok()) return f.face_map.empty() ? Annotate(map.status(), f.rig_field) : map.status();
  return map;
}

StatusOr<face::FaceTrack> ReadFaceFile(const std::string& path, std::string_view field) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) return absl::NotFoundError(kinemo::StrCat(field, ": cannot read ", path));
  if (size > (std::uintmax_t{256} << 20)) return InvalidField(field, path, " is larger than 256 MiB");
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  auto track = face::FaceTrackFromJson(ss.str(), path);
  if (!track.ok()) return Annotate(track.status(), field);
  return track;
}

StatusOr<nlohmann::json> RetargetFile(const RetargetFiles& f) {
  using namespace cmd_retarget;
  KINEMO_RETURN_IF_ERROR(ValidateRetargetFiles(f));
  retarget::RoleMapChoice source_choice;
  if (!f.source_map.empty()) {
    KINEMO_ASSIGN_OR_RETURN(source_choice.map_json, ReadText(f.source_map, "--source-map"));
    source_choice.map_source = f.source_map;
  }
  // A VRM Animation: its humanoid's motion, the roles from its bone names, metres.
  double source_meters_per_unit = f.source_meters_per_unit;
  StatusOr<motion::Clip> read = absl::UnknownError("");
  if (HasExtension(f.input, {".vrma"})) {
    auto vrma = retarget::ReadVrmAnimation(f.input);
    if (!vrma.ok()) return Annotate(vrma.status(), f.input_option);
    if (source_choice.map_json.empty()) {
      source_choice.map_json = vrma->role_map_json;
      source_choice.map_source = f.input + " (its humanoid)";
    }
    if (source_meters_per_unit <= 0) source_meters_per_unit = 1;
    read = std::move(vrma->clip);
  } else {
    read = motion::ReadBvhFile(f.input);
    if (!read.ok()) return Annotate(read.status(), f.input_option);
  }
  motion::Clip& clip = *read;
  KINEMO_ASSIGN_OR_RETURN(retarget::Rig target, LoadTargetRig(f));
  KINEMO_ASSIGN_OR_RETURN(retarget::FaceMap face_map, LoadFaceMap(f, target));
  const auto start = std::chrono::steady_clock::now();
  KINEMO_ASSIGN_OR_RETURN(retarget::Rig source,
                          retarget::RigFromSkeleton(clip.skeleton, 1.0, f.input, source_choice));
  source.meters_per_unit =
      source_meters_per_unit > 0 ? source_meters_per_unit : retarget::EstimateMetersPerUnit(source);
  retarget::RetargetOptions options;
  options.fingers = f.fingers;
  KINEMO_ASSIGN_OR_RETURN(retarget::Retargeter rt, retarget::Retargeter::Create(clip.skeleton, source, target, options));
  KINEMO_ASSIGN_OR_RETURN(motion::Clip out, rt.RetargetClip(clip));
  // The face: morph weights per frame and the jaw bone.
  std::optional<retarget::FaceAnimation> face;
  if (f.face != nullptr) {
    auto sampled = retarget::SampleFace(face_map, *f.face, out.num_frames(), out.frame_time_s);
    if (!sampled.ok()) return Annotate(sampled.status(), f.face_field);
    face = *std::move(sampled);
    KINEMO_RETURN_IF_ERROR(retarget::ApplyJawToClip(face_map, *face, &out));
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (HasExtension(f.output, {".glb", ".vrma"})) {
    const bool vrma = HasExtension(f.output, {".vrma"});
    auto written = retarget::WriteCharacterAnimation(target, out, f.output, vrma, face ? &face_map : nullptr,
                                                     face ? &*face : nullptr);
    if (!written.ok()) return vrma ? Annotate(written, f.rig_field) : written;  } else if (HasExtension(f.output, {".fbx"})) {
    // assimp's FBX exporter: the skeleton's motion (the jaw included), no
    // morph weights (docs/retarget.md).
    KINEMO_RETURN_IF_ERROR(retarget::WriteAnimatedFbx(target, out, f.output));
  } else {
    KINEMO_RETURN_IF_ERROR(motion::WriteBvhFile(out, f.output, {.significant_digits = 9}));
  }
  nlohmann::json report{{"mapped_roles", rt.MappedRoles()},
                        {"unmapped_roles", rt.UnmappedRoles()},
                        {"frames", out.num_frames()},
                        {"root_scale", rt.root_scale()},
                        {"seconds", seconds},
                        {"duration_s", out.duration_s()},
                        {"source_family", std::string(retarget::RigFamilyName(source.roles.family))},
                        {"target_family", std::string(retarget::RigFamilyName(target.roles.family))},
                        {"target_format", retarget::RigFormat(target)},
                        {"output", f.output}};
  // The face channels the rig's map drives ("mesh/morph" or the VRM
  // expression's name), and what was written.
  nlohmann::json mapped = nlohmann::json::array();
  for (const retarget::FaceControl& c : face_map.controls()) {
    if (!c.driven()) continue;
    mapped.push_back(c.kind == retarget::FaceControlKind::kMorphTarget ? c.mesh + "/" + c.name : c.name);
  }
  report["face_channels_mapped"] = mapped;
  report["face_mouth_family"] = face_map.mouth_family();
  report["jaw_bone"] = face_map.jaw().joint >= 0 ? nlohmann::json(face_map.jaw().name) : nlohmann::json(nullptr);
  report["face_frames"] = f.face != nullptr ? f.face->frames.size() : 0;
  if (face) {
    int written = 0;
    for (const auto& m : face_map.morph_meshes()) written += m.nodes.empty() ? 0 : m.num_targets;
    report["morph_weights_written"] = HasExtension(f.output, {".glb"}) ? written : 0;
    // A .vrma carries the driven VRM expressions instead of morph weights.
    int expressions = 0;
    for (const retarget::FaceControl& c : face_map.controls()) {
      expressions += c.kind == retarget::FaceControlKind::kVrmExpression && c.driven();
    }
    report["expressions_written"] = HasExtension(f.output, {".vrma"}) ? expressions : 0;
    double jaw_max = 0;
    for (double d : face->jaw_deg) jaw_max = std::max(jaw_max, d);
    report["jaw_max_deg"] = jaw_max;
  }
  // Feet (common/motion/motion_check.h): slide in contact, p95, of the input
  // and of the output, and the output's lowest sole. Left out for rigs
  // without legs.
  auto feet = [](const motion::Clip& c, const retarget::Rig& rig) -> StatusOr<motion::MotionCheck> {
    motion::MotionCheckParams params;
    params.contact = retarget::ContactParamsFor(rig);  // scaled to the character's size
    return motion::CheckMotion(c, retarget::RegionsFromRoles(rig), params, nullptr);
  };
  auto in_feet = feet(clip, source);
  auto out_feet = feet(out, target);
  if (in_feet.ok() && out_feet.ok()) {
    report["source_foot_slide_p95_m_s"] = in_feet->foot_slide_p95_m_s;
    report["foot_slide_p95_m_s"] = out_feet->foot_slide_p95_m_s;
    report["foot_contact_fraction"] = out_feet->contact_fraction;
    report["min_foot_height_m"] = out_feet->min_foot_height_m;
  }
  // Trunk and head (common/retarget/measures.h CompareFacings): angle
  // errors between the input's and the output's axes, p95 over frames.
  if (auto e = retarget::CompareFacings(clip, source, out, target, rt.world_axes()); e.ok()) {
    nlohmann::json facing;
    for (int part = 0; part < retarget::kNumFacingParts; ++part) {
      facing[retarget::FacingPartName(part)] = {{"up", e->up_p95_deg[part]}, {"forward", e->forward_p95_deg[part]}};
    }
    facing["pelvis_left"] = e->pelvis_left_p95_deg;
    facing["shoulder_left"] = e->shoulder_left_p95_deg;
    facing["neck_to_head"] = e->neck_to_head_p95_deg;
    report["facing_p95_deg"] = facing;
  }
  return report;
}

void RegisterRetargetCommands(CLI::App& app) {
  using namespace cmd_retarget;
  // kinemo rig push RIG.glb [--name ID] | ls | rm ID[@V]: the user's
  // characters as "rigs" artifacts of the planner (Animate and StreamAnimate
  // answer on one with models.rig_id).
  CLI::App* rig = app.add_subcommand("rig", "Characters (GLB/VRM rigs) in the stack's store: push, ls, rm");
  rig->require_subcommand(1);
  AddArtifactCommands(rig, {.noun = "rig",
                            .kind = "rigs",
                            .file_name = "rig.glb",
                            .file_help = "character: a .glb or .vrm (VRM 0.x/1.0) with a skin",
                            .id_option = "--name,--id",
                            .id_from_file_stem = true,
                            .file_extensions = {".glb", ".vrm"}});

  // kinemo rig info RIG [--map M] [--face-map F] [--json]: the rig's format,
  // skeleton, morph targets and face channels with how each is driven.
  {
    auto* info = rig->add_subcommand("info", "What a character offers: format, skeleton roles, morph targets, "
                                             "face channels and how kinemo drives each, jaw bone");
    auto files = std::make_shared<RetargetFiles>();
    files->rig_field = "rig";
    auto as_json = std::make_shared<bool>(false);
    info->add_option("rig", files->rig, "character: .glb/.gltf/.vrm (VRM 0.x/1.0), .fbx, or a .bvh skeleton")->required();
    info->add_option("--map", files->map, "JSON role map of the rig {\"hips\": \"joint\", ...}");
    info->add_option("--face-map", files->face_map, "JSON face map (docs/retarget.md \"Face map files\")");
    info->add_flag("--json", *as_json, "print {format, face_channels, jaw_bone, morph_targets, ...} as JSON");
    info->callback([files, as_json] {
      auto run = [&]() -> StatusOr<nlohmann::json> {
        if (!HasExtension(files->rig, {".glb", ".gltf", ".vrm", ".fbx", ".bvh"})) {
          return InvalidField("rig", "must be a .glb, .gltf, .vrm, .fbx or .bvh file, got ", files->rig);
        }
        KINEMO_ASSIGN_OR_RETURN(retarget::Rig rig, LoadTargetRig(*files));
        KINEMO_ASSIGN_OR_RETURN(retarget::FaceMap face, LoadFaceMap(*files, rig));
        return retarget::RigInfoJson(rig, face);
      };
      auto report = run();
      if (!report.ok()) {
        FailCommand("rig info", report.status(), {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound});
      }
      const nlohmann::json& r = *report;
      if (*as_json) {
        std::printf("%s\n", r.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace).c_str());
        return;
      }
      std::printf("%s: %s, %d joints (%s), %zu roles mapped, legs %.2f m%s\n", files->rig.c_str(),
                  r["format"].get<std::string>().c_str(), r["joints"].get<int>(),
                  r["family"].get<std::string>().c_str(), r["mapped_roles"].size(), r["leg_length_m"].get<double>(),
                  r["compression"].empty() ? "" : kinemo::StrCat(", decoded ", r["compression"].dump()).c_str());
      if (!r["unmapped_roles"].empty()) std::printf("unmapped roles: %s\n", r["unmapped_roles"].dump().c_str());
      std::printf("jaw bone: %s\n", r["jaw_bone"].is_null() ? "none" : r["jaw_bone"]["name"].get<std::string>().c_str());
      const double vowel = r["vowel_open_deg"].get<double>();
      std::printf("jaw input 1 at %g deg; vowels %s\n", r["jaw_full_open_deg"].get<double>(),
                  vowel > 0 ? kinemo::StrCat("open with the jaw, full at ", vowel, " deg").c_str()
                            : "at their viseme weights");
      std::printf("face channels: %d driven of %zu (mouth by %s)\n", r["face_channels_driven"].get<int>(),
                  r["face_channels"].size(),
                  r["mouth_family"].get<std::string>().empty() ? "nothing" : r["mouth_family"].get<std::string>().c_str());
      for (const auto& c : r["face_channels"]) {
        const std::string where = c.contains("mesh") ? c["mesh"].get<std::string>() + "/" : "expression ";
        std::printf("  %-8s %-40s %s\n", c["driven"].get<bool>() ? "driven" : "-",
                    (where + c["name"].get<std::string>()).c_str(), c["driven_by"].get<std::string>().c_str());
      }
    });
  }

  auto* cmd = app.add_subcommand(
      "retarget",
      "Motion onto a character's rig: kinemo retarget IN.bvh --to RIG.glb -o OUT.glb|OUT.bvh|OUT.vrma [--map MAP.json]");
  auto f = std::make_shared<RetargetFiles>();
  auto json = std::make_shared<bool>(false);
  auto no_fingers = std::make_shared<bool>(false);
  cmd->add_option("input", f->input,
                  "motion: a BVH on any kinemo skeleton (SMPL-X, Bandai, CMU, iClone, Mixamo, ...) or a VRM "
                  "Animation (.vrma: its humanoid's motion)")
      ->required();
  cmd->add_option("--to", f->rig, "target rig: .glb/.gltf/.vrm character (VRM 0.x/1.0 humanoid), .fbx, or a .bvh skeleton")
      ->required();
  cmd->add_option("-o,--out", f->output,
                  ".glb (the character with the animation), .fbx (an FBX rig with the animation), .bvh (motion on "
                  "its skeleton) or .vrma (with a VRM character: a VRM Animation, the body and the face's "
                  "expressions, for any VRM app)");
  AddDeprecatedOption(cmd, "--output", "--out", f->output);
  cmd->add_option("--map", f->map, "JSON role map of the rig {\"hips\": \"joint\", \"left_upper_arm\": ...}");
  cmd->add_option("--source-map", f->source_map, "JSON role map of the input's skeleton");
  cmd->add_option("--visemes", f->visemes,
                  "face track to put on the rig (the viseme file of kinemo animate --visemes: OVR visemes, jaw, "
                  "blinks, brows, expression): morph weight animation and the jaw bone in OUT.glb (the jaw in OUT.bvh)");
  cmd->add_option("--face-map", f->face_map,
                  "JSON face map of the rig: which morph targets / VRM expressions the face drives and how "
                  "(default: by name family, kinemo rig info shows it)");
  cmd->add_option("--source-meters-per-unit", f->source_meters_per_unit,
                  "input's unit in metres (default: estimated from its legs)");
  cmd->add_flag("--no-fingers", *no_fingers, "leave the rig's fingers at rest");
  cmd->add_flag("--json", *json, "print {mapped_roles, unmapped_roles, frames, root_scale, seconds, ...} as JSON");
  cmd->callback([f, json, no_fingers] {
    if (f->output.empty()) {
      std::cerr << "kinemo retarget: -o/--out is required (OUT.glb or OUT.bvh)\n";
      throw CliExit{2};
    }
    f->fingers = !*no_fingers;
    std::optional<face::FaceTrack> face;
    if (!f->visemes.empty()) {
      auto read = ReadFaceFile(f->visemes, "--visemes");
      if (!read.ok()) {
        FailCommand("retarget", read.status(), {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound});
      }
      face = *std::move(read);
      f->face = &*face;
    }
    auto report = RetargetFile(*f);
    if (!report.ok()) {
      FailCommand("retarget", report.status(),
                  {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound});
    }
    const nlohmann::json& r = *report;
    if (*json) {
      std::printf("%s\n", r.dump().c_str());
    } else {
      std::printf("%s (%s) -> %s (%s): %d frames, %zu roles mapped, %zu unmapped, root scale %.3f, %.3f s\n",
                  f->input.c_str(), r["source_family"].get<std::string>().c_str(), f->output.c_str(),
                  r["target_family"].get<std::string>().c_str(), r["frames"].get<int>(), r["mapped_roles"].size(),
                  r["unmapped_roles"].size(), r["root_scale"].get<double>(), r["seconds"].get<double>());
    }
  });
}

}  // namespace kinemo::cli
