// `kinemo motion check`: plausibility measures of BVH motion (see
// common/motion/motion_check.h and docs/feet.md); `kinemo motion compare`:
// generated motion judged against natural references (see
// common/evaluation/motion_compare.h and docs/evaluation.md).
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
//
//   kinemo motion compare GEN.bvh --reference REF.bvh [--reference ...]
//       [--audio WAV] [--library DIR|FILE|MANIFEST ...] [--json]
//       [--meters-per-unit M] [--reference-meters-per-unit M]
//
// The field's published measures against the references (GENEA's wrist
// speed / acceleration Hellinger distances, AIST++'s FID_k, with --audio
// BEAT/EMAGE's beat consistency; EMAGE's L1 diversity), kinemo's own
// (Hellinger distances of its own bins, its kinetic Fréchet distance, jerk,
// hand speed, moving and raised hands, ankle lift, foot slide, fastest joint,
// hand-speed envelope correlations, accents with an apex in the synchrony
// window), with --library the near copies of the library (blends and time
// warps included) and the longest exact copy. Scales: given, else estimated
// from the body and snapped to a standard unit (SnapMetersPerUnit). Exit
// code 0; 2 for bad input. docs/evaluation.md defines every field.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "common/audio/decode.h"
#include "common/audio/resample.h"
#include "common/evaluation/motion_compare.h"
#include "common/motion/body_regions.h"
#include "common/motion/bvh.h"
#include "common/motion/motion_check.h"
#include "services/cli/commands.h"
#include "services/planner/library/library.h"
#include "services/prosody/core/pipeline.h"

namespace kinemo::cli {
namespace {
namespace cmd_motion {  // this file's own helpers (the unity build puts files together)

namespace fs = std::filesystem;
using Json = nlohmann::json;

constexpr size_t kMaxReferenceFiles = 10000;

[[noreturn]] void Fail(const Status& status, const char* command = "motion check") {
  FailCommand(command, status,
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

// ---- kinemo motion compare

namespace ev = kinemo::evaluation;

struct CompareArgs {
  std::string file;
  std::vector<std::string> reference;
  std::vector<std::string> library;
  std::string audio;
  bool json = false;
  double meters_per_unit = 0;
  double reference_meters_per_unit = 0;
};

[[noreturn]] void FailCompare(const Status& s) { Fail(s, "motion compare"); }

double ScaleOf(const motion::Skeleton& skeleton, double given) {
  return given > 0 ? given : ev::SnapMetersPerUnit(planner::EstimateMetersPerUnit(skeleton));
}

// Reads a BVH and reduces it to its role track; *clip keeps the motion.
ev::RoleTrack ReadTrack(const std::string& file, double given_scale, std::string_view field, motion::Clip* clip,
                        double* scale) {
  StatusOr<motion::Clip> c = motion::ReadBvhFile(file);
  if (!c.ok()) FailCompare(Annotate(c.status(), field));
  *scale = ScaleOf(c->skeleton, given_scale);
  StatusOr<ev::RoleTrack> t = ev::ExtractRoleTrack(*c, *scale);
  if (!t.ok()) FailCompare(Annotate(t.status(), kinemo::StrCat(field, " ", file)));
  *clip = *std::move(c);
  return *std::move(t);
}

ev::AudioEvents AnalyzeAudio(const std::string& path) {
  StatusOr<audio::DecodedAudio> decoded = audio::DecodeAudioFile(path);
  if (!decoded.ok()) FailCompare(Annotate(decoded.status(), "--audio"));
  prosody::PipelineRequest req;
  StatusOr<prosody::PipelineResult> r = prosody::RunPipeline(decoded->samples, decoded->sample_rate_hz, req, nullptr);
  if (!r.ok()) FailCompare(Annotate(r.status(), "--audio"));
  ev::AudioEvents e;
  for (const auto& s : r->prosody.syllables) e.onsets_s.push_back(s.start_s);
  for (const auto& a : r->prosody.accents) e.accents_s.push_back(a.time_s);
  std::sort(e.onsets_s.begin(), e.onsets_s.end());
  std::sort(e.accents_s.begin(), e.accents_s.end());
  // BEAT/EMAGE's onsets: librosa's detector on the speech at 16 kHz.
  constexpr int kOnsetRate = 16000;
  StatusOr<std::vector<float>> y = audio::Resample(decoded->samples, decoded->sample_rate_hz, kOnsetRate);
  if (!y.ok()) FailCompare(Annotate(y.status(), "--audio"));
  StatusOr<std::vector<double>> onsets = ev::AudioOnsets(*y, kOnsetRate);
  if (!onsets.ok()) FailCompare(Annotate(onsets.status(), "--audio"));
  e.audio_onsets_s = *std::move(onsets);
  e.loudness_db = ev::LoudnessEnvelope(decoded->samples, decoded->sample_rate_hz, ev::CompareOptions{}.envelope_s);
  return e;
}

Json MeasuresJson(const ev::ClipMeasures& m, bool audio) {
  Json j = {{"duration_s", m.duration_s},
            {"jerk_mean_m_s3", m.jerk_mean_m_s3},
            {"knee_jerk_mean_m_s3", m.knee_jerk_mean_m_s3},
            {"accel_mean_m_s2", m.accel_mean_m_s2},
            {"hand_speed_mean_m_s", m.hand_speed_mean_m_s},
            {"hand_speed_p95_m_s", m.hand_speed_p95_m_s},
            {"hands_moving_fraction", m.hands_moving_fraction},
            {"hands_raised_fraction", m.hands_raised_fraction},
            {"hand_height_mean_m", m.hand_height_mean_m},
            {"max_joint_speed_m_s", m.max_joint_speed_m_s},
            {"kinematic_beats", m.kinematic_beats},
            {"l1_div", m.l1_div},
            {"ankle_lift_share", m.ankle_lift_share}};
  if (audio) {
    j["kinemo_beat_alignment"] = m.kinemo_beat_alignment;
    j["kinemo_beat_alignment_chance"] = m.kinemo_beat_alignment_chance;
    j["accent_sync_fraction"] = m.accent_sync_fraction;
    j["accent_sync_chance"] = m.accent_sync_chance;
    j["accents"] = m.accents;
  }
  return j;
}

double FootSlideP95(const motion::Clip& clip, double scale) {
  motion::MotionCheckParams p;
  p.contact.meters_per_unit = scale;
  StatusOr<motion::MotionCheck> m = motion::CheckMotion(clip, motion::MapBodyRegions(clip.skeleton), p, nullptr);
  return m.ok() ? m->foot_slide_p95_m_s : -1;
}

void RunCompare(const CompareArgs& a) {
  motion::Clip gen_clip;
  double gen_scale = 0;
  const ev::RoleTrack gen = ReadTrack(a.file, a.meters_per_unit, "FILE", &gen_clip, &gen_scale);
  StatusOr<std::vector<std::string>> ref_files = ReferenceFiles(a.reference);
  if (!ref_files.ok()) FailCompare(ref_files.status());
  std::vector<ev::RoleTrack> refs;
  double ref_slide = 0;
  for (const std::string& f : *ref_files) {
    motion::Clip c;
    double scale = 0;
    refs.push_back(ReadTrack(f, a.reference_meters_per_unit, "--reference", &c, &scale));
    ref_slide = std::max(ref_slide, FootSlideP95(c, scale));
  }
  std::vector<ev::RoleTrack> lib_tracks;
  if (!a.library.empty()) {
    planner::LibrarySources src;
    src.paths = a.library;
    StatusOr<std::shared_ptr<planner::Library>> lib = planner::LoadLibrary("compare", src);
    if (!lib.ok()) FailCompare(Annotate(lib.status(), "--library"));
    const double scale = ev::SnapMetersPerUnit((*lib)->meters_per_unit);
    for (const auto& lc : (*lib)->clips) {
      StatusOr<ev::RoleTrack> t = ev::ExtractRoleTrack(lc.clip, scale);
      if (!t.ok()) FailCompare(Annotate(t.status(), kinemo::StrCat("--library ", lc.source)));
      lib_tracks.push_back(*std::move(t));
    }
  }
  ev::AudioEvents audio;
  if (!a.audio.empty()) audio = AnalyzeAudio(a.audio);
  StatusOr<ev::Comparison> c = ev::Compare(gen, refs, a.audio.empty() ? nullptr : &audio, lib_tracks);
  if (!c.ok()) FailCompare(c.status());
  const bool has_audio = !a.audio.empty();
  Json j = MeasuresJson(c->generated, has_audio);
  j["file"] = a.file;
  j["meters_per_unit"] = gen_scale;
  j["hellinger_speed"] = c->hellinger_speed;
  j["hellinger_accel"] = c->hellinger_accel;
  j["hellinger_speed_elbows"] = c->hellinger_speed_elbows;
  j["hellinger_accel_elbows"] = c->hellinger_accel_elbows;
  j["fd_kinetic"] = c->fd_kinetic;
  j["windows"] = c->windows;
  j["genea_hellinger_speed"] = c->genea_hellinger_speed;
  j["genea_hellinger_accel"] = c->genea_hellinger_accel;
  j["fid_k"] = std::isfinite(c->fid_k) ? Json(c->fid_k) : Json(nullptr);
  j["fid_k_bailando"] = std::isfinite(c->fid_k_bailando) ? Json(c->fid_k_bailando) : Json(nullptr);
  j["fid_windows"] = c->fid_windows;
  j["envelope_correlation"] = c->envelope_correlation;
  j["foot_slide_p95_m_s"] = FootSlideP95(gen_clip, gen_scale);
  if (has_audio) {
    j["beat_consistency"] = c->beat_consistency;
    j["beat_consistency_chance"] = c->beat_consistency_chance;
    j["audio_onsets"] = c->audio_onsets;
    j["speech_envelope_correlation"] = c->speech_envelope_correlation;
  } else {
    j["beat_consistency"] = nullptr;
    j["accent_sync_fraction"] = nullptr;
  }
  j["longest_copy_s"] = c->has_library ? Json(c->longest_copy_s) : Json(nullptr);
  j["near_copy_share_over_2s"] = c->has_library ? Json(c->near_copy_share_over_2s) : Json(nullptr);
  j["longest_near_copy_s"] = c->has_library ? Json(c->longest_near_copy_s) : Json(nullptr);
  j["library_repeat_share"] = c->has_library ? Json(c->library_repeat_share) : Json(nullptr);
  if (c->has_library) {
    j["longest_copy_fraction"] = c->longest_copy_fraction;
    j["copied_fraction"] = c->copied_fraction;
    j["copy_frame_fraction"] = c->copy_frame_fraction;
    j["library_clips"] = lib_tracks.size();
  }
  Json ref = MeasuresJson(c->reference, has_audio);
  ref["clips"] = refs.size();
  ref["windows"] = c->reference_windows;
  ref["fid_windows"] = c->fid_reference_windows;
  ref["foot_slide_p95_m_s"] = ref_slide;
  if (has_audio) {
    ref["beat_consistency"] = c->reference_beat_consistency;
    ref["beat_consistency_chance"] = c->reference_beat_consistency_chance;
    ref["speech_envelope_correlation"] = c->reference_speech_envelope_correlation;
  }
  j["reference"] = ref;
  if (a.json) {
    std::cout << j.dump(1) << "\n";
    return;
  }
  const ev::ClipMeasures& g = c->generated;
  const ev::ClipMeasures& r = c->reference;
  std::printf("%s against %zu reference clip(s), %.1f s vs %.1f s\n", a.file.c_str(), refs.size(), g.duration_s,
              r.duration_s);
  std::printf("  Hellinger wrist speed %.3f, accel %.3f; elbow speed %.3f, accel %.3f\n", c->hellinger_speed,
              c->hellinger_accel, c->hellinger_speed_elbows, c->hellinger_accel_elbows);
  std::printf("  GENEA Hellinger wrist speed %.3f, accel %.3f; AIST++ FID_k %.2f (%d windows of 2 s, reference %d)\n",
              c->genea_hellinger_speed, c->genea_hellinger_accel, c->fid_k, c->fid_windows,
              c->fid_reference_windows);
  std::printf("  kinemo: kinetic Frechet distance %.2f (%d windows, reference %d); 0.5 s hand-speed envelope r %.3f\n",
              c->fd_kinetic, c->windows, c->reference_windows, c->envelope_correlation);
  std::printf("  %-28s %10s %10s\n", "", "generated", "reference");
  auto row = [](const char* name, double x, double y) { std::printf("  %-28s %10.3f %10.3f\n", name, x, y); };
  row("jerk mean m/s^3", g.jerk_mean_m_s3, r.jerk_mean_m_s3);
  row("knee jerk mean m/s^3", g.knee_jerk_mean_m_s3, r.knee_jerk_mean_m_s3);
  row("accel mean m/s^2", g.accel_mean_m_s2, r.accel_mean_m_s2);
  row("hand speed mean m/s", g.hand_speed_mean_m_s, r.hand_speed_mean_m_s);
  row("hand speed p95 m/s", g.hand_speed_p95_m_s, r.hand_speed_p95_m_s);
  row("hands moving fraction", g.hands_moving_fraction, r.hands_moving_fraction);
  row("hands raised fraction", g.hands_raised_fraction, r.hands_raised_fraction);
  row("max joint speed m/s", g.max_joint_speed_m_s, r.max_joint_speed_m_s);
  row("foot slide p95 m/s", j["foot_slide_p95_m_s"].get<double>(), ref_slide);
  row("ankle lift share", g.ankle_lift_share, r.ankle_lift_share);
  row("L1 diversity m", g.l1_div, r.l1_div);
  if (has_audio) {
    row("beat consistency (EMAGE)", c->beat_consistency, c->reference_beat_consistency);
    row("  (chance)", c->beat_consistency_chance, c->reference_beat_consistency_chance);
    row("kinemo beat alignment", g.kinemo_beat_alignment, r.kinemo_beat_alignment);
    row("  (chance)", g.kinemo_beat_alignment_chance, r.kinemo_beat_alignment_chance);
    row("accent sync fraction", g.accent_sync_fraction, r.accent_sync_fraction);
    row("  (chance)", g.accent_sync_chance, r.accent_sync_chance);
  }
  if (c->has_library) {
    std::printf("  longest copy from the library %.2f s (%.1f %% of the output); %.1f %% in copies >= 1 s\n",
                c->longest_copy_s, 100 * c->longest_copy_fraction, 100 * c->copied_fraction);
    std::printf("  near copies (3 cm, library step 0-2): longest %.2f s, %.1f %% of the output in runs > 2 s\n",
                c->longest_near_copy_s, 100 * c->near_copy_share_over_2s);
    std::printf("  library material shown again after >= 1 s: %.1f %% of the output\n", 100 * c->library_repeat_share);
  }
}

}  // namespace cmd_motion
}  // namespace

void RegisterMotionCommands(CLI::App& app) {
  using namespace cmd_motion;
  CLI::App* motion = app.add_subcommand("motion", "Measure motion: planted feet, floor, hips drift, joint speeds; compare with natural motion");
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

  auto c = std::make_shared<CompareArgs>();
  CLI::App* compare = motion->add_subcommand(
      "compare", "Judge generated motion against natural references (GENEA Hellinger, AIST++ FID_k, EMAGE BC, near copies)");
  compare->add_option("FILE", c->file, "Generated BVH")->required();
  compare->add_option("--reference", c->reference, "Natural reference clips (BVH files or folders)")->required();
  compare->add_option("--audio", c->audio, "The speech (WAV): beat consistency and accent synchrony");
  compare->add_option("--library", c->library,
                      "The motion library the output was made from (BVH files, folders, manifests): near copies");
  compare->add_flag("--json", c->json, "Print one JSON object");
  compare->add_option("--meters-per-unit", c->meters_per_unit,
                      "Scale of FILE (default: estimated from the body, snapped to a standard unit)")
      ->check(CLI::PositiveNumber);
  compare->add_option("--reference-meters-per-unit", c->reference_meters_per_unit,
                      "Scale of the references (default: estimated per clip)")
      ->check(CLI::PositiveNumber);
  compare->callback([c] { RunCompare(*c); });
}

}  // namespace kinemo::cli
