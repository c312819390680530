// `kinemo bvh ...`: inspect and convert BVH motion files.
//
//   kinemo bvh info FILE [--json]
//   kinemo bvh convert IN OUT [--fps N] [--digits D]
//
// Errors go to stderr and the command exits non-zero through CliExit: 2 for
// bad input (unreadable or malformed BVH, bad options), 1 for other failures
// (e.g. the output cannot be written).

#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "common/motion/body_regions.h"
#include "common/motion/bvh.h"
#include "common/motion/resample.h"
#include "common/motion/skeleton.h"
#include "services/cli/commands.h"

namespace kinemo::cli {
namespace {

using motion::BodyRegionMap;
using motion::Clip;

[[noreturn]] void Fail(const Status& status) {
  FailCommand("bvh", status, {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound});
}

std::string ChannelList(const motion::Joint& joint) {
  std::string s;
  for (motion::ChannelType t : joint.channels) {
    if (!s.empty()) s += ' ';
    s += motion::ChannelTypeName(t);
  }
  return s;
}

nlohmann::json Vec(const Eigen::Vector3d& v) {
  return nlohmann::json::array({v.x(), v.y(), v.z()});
}

void PrintInfoJson(const std::string& path, const Clip& clip, const BodyRegionMap& regions) {
  const motion::Skeleton& sk = clip.skeleton;
  nlohmann::json j;
  j["file"] = path;
  j["skeleton_family"] = std::string(motion::SkeletonFamilyName(regions.family));
  j["num_joints"] = sk.num_joints();
  j["num_end_sites"] = sk.num_end_sites();
  j["num_channels"] = sk.num_channels();
  j["num_frames"] = clip.num_frames();
  j["frame_time_s"] = clip.frame_time_s;
  j["fps"] = clip.fps();
  j["duration_s"] = clip.duration_s();
  nlohmann::json joints = nlohmann::json::array();
  for (int i = 0; i < sk.num_joints(); ++i) {
    const motion::Joint& joint = sk.joint(i);
    nlohmann::json jj;
    jj["name"] = joint.name;
    jj["parent"] = joint.parent;
    jj["offset"] = Vec(joint.offset);
    nlohmann::json channels = nlohmann::json::array();
    for (motion::ChannelType t : joint.channels)
      channels.push_back(std::string(motion::ChannelTypeName(t)));
    jj["channels"] = channels;
    jj["end_site"] = joint.end_site ? Vec(*joint.end_site) : nlohmann::json(nullptr);
    jj["region"] = std::string(motion::BodyRegionName(regions.region[static_cast<size_t>(i)]));
    joints.push_back(std::move(jj));
  }
  j["joints"] = std::move(joints);
  std::cout << j.dump(2) << "\n";
}

void PrintInfoText(const std::string& path, const Clip& clip, const BodyRegionMap& regions) {
  const motion::Skeleton& sk = clip.skeleton;
  std::printf("file:        %s\n", path.c_str());
  std::printf("skeleton:    %s\n", std::string(motion::SkeletonFamilyName(regions.family)).c_str());
  std::printf("joints:      %d (+%d end sites)\n", sk.num_joints(), sk.num_end_sites());
  std::printf("channels:    %d\n", sk.num_channels());
  std::printf("frames:      %d\n", clip.num_frames());
  std::printf("frame time:  %.9g s\n", clip.frame_time_s);
  std::printf("fps:         %.6g\n", clip.fps());
  std::printf("duration:    %.6g s\n", clip.duration_s());
  std::printf("hierarchy:\n");
  for (int i = 0; i < sk.num_joints(); ++i) {
    const motion::Joint& joint = sk.joint(i);
    std::printf("  %*s%s  [%s] %d ch: %s%s\n", 2 * sk.depth(i), "", joint.name.c_str(),
                std::string(motion::BodyRegionName(regions.region[static_cast<size_t>(i)])).c_str(),
                joint.num_channels(), ChannelList(joint).c_str(),
                joint.end_site ? "  (End Site)" : "");
  }
  std::fflush(stdout);
}

}  // namespace

void RegisterBvhCommands(CLI::App& app) {
  CLI::App* bvh = app.add_subcommand("bvh", "Inspect and convert BVH motion files");
  bvh->require_subcommand(1);

  // kinemo bvh info FILE [--json]
  {
    CLI::App* info =
        bvh->add_subcommand("info", "Print skeleton, frames, fps and duration of a BVH file");
    auto file = std::make_shared<std::string>();
    auto json = std::make_shared<bool>(false);
    info->add_option("FILE", *file, "BVH file")->required();
    info->add_flag("--json", *json, "Print JSON instead of text");
    info->callback([file, json]() {
      StatusOr<Clip> clip = motion::ReadBvhFile(*file);
      if (!clip.ok()) Fail(clip.status());
      const BodyRegionMap regions = motion::MapBodyRegions(clip->skeleton);
      if (*json) {
        PrintInfoJson(*file, *clip, regions);
      } else {
        PrintInfoText(*file, *clip, regions);
      }
    });
  }

  // kinemo bvh convert IN -o OUT [--fps N] [--digits D]
  {
    CLI::App* convert =
        bvh->add_subcommand("convert", "Read a BVH file and write it again (optionally resampled)");
    struct Args {
      std::string in;
      std::string out;
      double fps = 0.0;
      int digits = 0;
    };
    auto args = std::make_shared<Args>();
    convert->add_option("IN", args->in, "Input BVH file")->required();
    convert->add_option("-o,--out", args->out, "Output BVH file (required)");
    // The old spelling, `bvh convert IN OUT`, for one release (docs/cli.md,
    // "One spelling per concept").
    convert->add_option("OUT", args->out, "deprecated: use -o OUT")->group("")->each([](const std::string&) {
      std::cerr << "kinemo: bvh convert IN OUT is deprecated and will be removed in the next release; use "
                   "bvh convert IN -o OUT\n";
    });
    convert->add_option("--fps", args->fps, "Resample to this frame rate (frames per second)")
        ->check(CLI::PositiveNumber);
    convert
        ->add_option("--digits", args->digits,
                     "Significant digits per value (default: shortest exact representation)")
        ->check(CLI::Range(1, 17));
    convert->callback([args]() {
      if (args->out.empty()) Fail(InvalidField("-o/--out", "is required: the BVH file to write"));
      StatusOr<Clip> clip = motion::ReadBvhFile(args->in);
      if (!clip.ok()) Fail(clip.status());
      if (args->fps > 0.0) {
        StatusOr<Clip> resampled = motion::Resample(*clip, args->fps);
        if (!resampled.ok()) Fail(resampled.status());
        clip = std::move(resampled);
      }
      motion::BvhWriteOptions options;
      options.significant_digits = args->digits;
      if (const Status s = motion::WriteBvhFile(*clip, args->out, options); !s.ok()) Fail(s);
      std::printf("wrote %s: %d joints, %d frames at %.6g fps (%.6g s)\n", args->out.c_str(),
                  clip->skeleton.num_joints(), clip->num_frames(), clip->fps(), clip->duration_s());
      std::fflush(stdout);
    });
  }
}

}  // namespace kinemo::cli
