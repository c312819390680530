// `kinemo motion check`: plausibility measures of BVH motion (see
// common/motion/motion_check.h and docs/feet.md).
//
//   kinemo motion check FILE.bvh [FILE.bvh...] [--reference DIR|FILE...] [--json]
//       [--meters-per-unit M] [--floor-height M] [--quantile Q]
//
// Per clip: foot slide during contact (p95, m/s), the lowest sole height over
// the clip (negative = penetration), the largest height of the lowest contact
// sole (floating), the pelvis's horizontal path and net drift, the fraction of
// foot-frames in contact, and, with --reference, the frames in which some
// joint turns faster than the reference clips' Q-quantile (default p99.9) for
// that joint, and the worst joint. --json prints one object for one file, an
// array for several. Exit code 0; 2 for bad input (unreadable BVH, no legs,
// a reference without clips or joints in common).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "common/motion/body_regions.h"
#include "common/motion/bvh.h"
#include "common/motion/motion_check.h"
#include "services/cli/commands.h"
#include "services/planner/library/library.h"

namespace kinemo::cli {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

constexpr size_t kMaxReferenceFiles = 10000;

[[noreturn]] void Fail(const Status& status) {
  FailCommand("motion check", status,
              {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound, absl::StatusCode::kFailedPrecondition});
}

struct CheckArgs {
  std::vector<std::string> files;
  std::vector<std::string> reference;
  bool json = false;
  double meters_per_unit = 0;
  double floor_height_m = 0;
  double quantile = 0.999;
};

// BVH files named or found (recursively, sorted) in the folders named.
StatusOr<std::vector<std::string>> ReferenceFiles(const std::vector<std::string>& paths) {
  std::vector<std::string> out;
  for (const std::string& p : paths) {
    std::error_code ec;
    if (fs::is_directory(p, ec)) {
      std::vector<std::string> found;
      for (const auto& e : fs::recursive_directory_iterator(p, ec)) {
        if (e.is_regular_file() && e.path().extension() == ".bvh") found.push_back(e.path().string());
      }
      if (found.empty()) return InvalidField("--reference", "no .bvh file in ", p);
      std::sort(found.begin(), found.end());
      out.insert(out.end(), found.begin(), found.end());
    } else if (fs::is_regular_file(p, ec)) {
      out.push_back(p);
    } else {
      return absl::NotFoundError(kinemo::StrCat("--reference: no such file or folder: ", p));
    }
    if (out.size() > kMaxReferenceFiles) {
      return InvalidField("--reference", "more than ", kMaxReferenceFiles, " BVH files");
    }
  }
  return out;
}

Json ToJson(const std::string& file, const motion::MotionCheck& m, const motion::JointSpeedLimits* ref) {
  Json j = {{"file", file},
            {"frames", m.num_frames},
            {"duration_s", m.duration_s},
            {"meters_per_unit", m.meters_per_unit},
            {"ground_height_m", m.ground_height_m},
            {"foot_slide_p95_m_s", m.foot_slide_p95_m_s},
            {"ankle_slide_p95_m_s", m.ankle_slide_p95_m_s},
            {"toe_slide_p95_m_s", m.toe_slide_p95_m_s},
            {"foot_slide_max_m_s", m.foot_slide_max_m_s},
            {"contact_samples", m.contact_samples},
            {"min_foot_height_m", m.min_foot_height_m},
            {"max_float_m", m.max_float_m},
            {"hips_path_m", m.hips_path_m},
            {"hips_drift_m", m.hips_drift_m},
            {"contact_fraction", m.contact_fraction}};
  if (ref != nullptr) {
    j["reference_clips"] = ref->clips;
    j["reference_quantile"] = ref->quantile;
    j["compared_joints"] = m.compared_joints;
    j["speed_outlier_frames"] = m.speed_outlier_frames;
    j["worst_joint"] = m.worst_joint;
    j["worst_joint_dps"] = m.worst_joint_dps;
    j["worst_joint_limit_dps"] = m.worst_joint_limit_dps;
  }
  return j;
}

void PrintText(const std::string& file, const motion::MotionCheck& m, const motion::JointSpeedLimits* ref) {
  std::printf("%s: %d frames, %.2f s, %.4g m/unit, contacts measured from %.3f m\n", file.c_str(), m.num_frames,
              m.duration_s, m.meters_per_unit, m.ground_height_m);
  std::printf("  foot slide in contact  p95 %.4f m/s (ankle %.4f, toe %.4f), max %.4f, %d samples\n",
              m.foot_slide_p95_m_s, m.ankle_slide_p95_m_s, m.toe_slide_p95_m_s, m.foot_slide_max_m_s,
              m.contact_samples);
  std::printf("  lowest sole            %.4f m   largest contact float %.4f m\n", m.min_foot_height_m, m.max_float_m);
  std::printf("  hips                   path %.3f m, net drift %.3f m\n", m.hips_path_m, m.hips_drift_m);
  std::printf("  contact fraction       %.3f\n", m.contact_fraction);
  if (ref != nullptr) {
    std::printf("  joint speed outliers   %d frames above the reference p%.4g (%d clips, %d joints); worst %s %.1f deg/s "
                "(limit %.1f)\n",
                m.speed_outlier_frames, 100 * ref->quantile, ref->clips, m.compared_joints, m.worst_joint.c_str(),
                m.worst_joint_dps, m.worst_joint_limit_dps);
  }
}

void RunCheck(const CheckArgs& a) {
  std::unique_ptr<motion::JointSpeedLimits> limits;
  if (!a.reference.empty()) {
    StatusOr<std::vector<std::string>> files = ReferenceFiles(a.reference);
    if (!files.ok()) Fail(files.status());
    std::vector<motion::Clip> clips;
    for (const std::string& f : *files) {
      StatusOr<motion::Clip> c = motion::ReadBvhFile(f);
      if (!c.ok()) Fail(Annotate(c.status(), "--reference"));
      clips.push_back(*std::move(c));
    }
    std::vector<const motion::Clip*> ptrs;
    for (const auto& c : clips) ptrs.push_back(&c);
    StatusOr<motion::JointSpeedLimits> l = motion::BuildJointSpeedLimits(ptrs, a.quantile);
    if (!l.ok()) Fail(l.status());
    limits = std::make_unique<motion::JointSpeedLimits>(*std::move(l));
  }
  Json all = Json::array();
  for (const std::string& file : a.files) {
    StatusOr<motion::Clip> clip = motion::ReadBvhFile(file);
    if (!clip.ok()) Fail(clip.status());
    motion::MotionCheckParams p;
    p.floor_height_m = a.floor_height_m;
    p.contact.meters_per_unit =
        a.meters_per_unit > 0 ? a.meters_per_unit : planner::EstimateMetersPerUnit(clip->skeleton);
    StatusOr<motion::MotionCheck> m =
        motion::CheckMotion(*clip, motion::MapBodyRegions(clip->skeleton), p, limits.get());
    if (!m.ok()) Fail(Annotate(m.status(), file));
    if (a.json) {
      all.push_back(ToJson(file, *m, limits.get()));
    } else {
      PrintText(file, *m, limits.get());
    }
  }
  if (a.json) std::cout << (all.size() == 1 ? all[0] : all).dump(1) << "\n";
}

}  // namespace

void RegisterMotionCommands(CLI::App& app) {
  CLI::App* motion = app.add_subcommand("motion", "Measure motion: planted feet, floor, hips drift, joint speeds");
  motion->require_subcommand(1);
  CLI::App* check = motion->add_subcommand(
      "check", "Foot slide during contact, sole heights, hips drift and joint-speed outliers of BVH clips");
  auto a = std::make_shared<CheckArgs>();
  check->add_option("FILE", a->files, "BVH files")->required();
  check->add_option("--reference", a->reference,
                    "Reference clips (BVH files or folders) for joint-speed outliers, e.g. tests/data/planner_gesture");
  check->add_flag("--json", a->json, "Print JSON: one object per file (an array for several)");
  check->add_option("--meters-per-unit", a->meters_per_unit, "Skeleton scale (default: estimated from the skeleton)")
      ->check(CLI::PositiveNumber);
  check->add_option("--floor-height", a->floor_height_m, "Height of the floor in metres (default 0: y = 0)")
      ->check(CLI::Range(-1000.0, 1000.0));
  check->add_option("--quantile", a->quantile, "Reference joint-speed quantile (default 0.999)")
      ->check(CLI::Range(0.5, 1.0));
  check->callback([a] { RunCheck(*a); });
}

}  // namespace kinemo::cli
