#include "services/planner/controller/segments.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <thread>

#include "common/gesture/kinematics.h"
#include "common/motion/body_regions.h"
#include "common/parallel/parallel.h"
#include "common/motion/kinematics.h"
#include "services/planner/library/feet.h"

namespace kinemo::planner::controller {
namespace {

::kinemo::gesture::KinematicOptions ToKinematic(const SegmentOptions& o) {
  ::kinemo::gesture::KinematicOptions k;
  k.speed_threshold_heights_per_s = o.speed_threshold_heights_per_s;
  k.min_segment_s = o.min_segment_s;
  return k;
}

// Body height (head above the lower foot in frame 0), in skeleton units.
StatusOr<double> BodyHeight(const motion::Clip& clip, const motion::BodyRegionMap& regions,
                            const Eigen::MatrixXd& world) {
  KINEMO_ASSIGN_OR_RETURN(motion::KeyJoints keys, motion::FindKeyJoints(clip.skeleton, regions));
  const double floor = std::min(world(0, 3 * keys.left_foot + 1), world(0, 3 * keys.right_foot + 1));
  const double h = world(0, 3 * keys.head + 1) - floor;
  if (!(h > 0)) return InvalidField("clip", "head is not above the feet in frame 0 (Y-up expected)");
  return h;
}

}  // namespace

Status ValidateSegmentOptions(const SegmentOptions& o) {
  if (!(o.speed_threshold_heights_per_s > 0) || !std::isfinite(o.speed_threshold_heights_per_s))
    return InvalidField("speed_threshold_heights_per_s", "must be > 0");
  if (!(o.min_segment_s >= 0) || o.min_segment_s > 10) return InvalidField("min_segment_s", "must be in [0, 10]");
  if (o.interruption_frames < 0 || o.interruption_frames > 16)
    return InvalidField("interruption_frames", "must be in [0, 16]");
  if (!(o.transition_weight >= 0) || !std::isfinite(o.transition_weight))
    return InvalidField("transition_weight", "must be >= 0");
  if (!(o.interruption_penalty >= 0) || !std::isfinite(o.interruption_penalty))
    return InvalidField("interruption_penalty", "must be >= 0");
  return absl::OkStatus();
}

double MaxJointAngularSpeedDps(const motion::Skeleton& skeleton, std::span<const double> prev,
                               std::span<const double> cur, double frame_time_s) {
  double best = 0;
  for (const auto& j : skeleton.joints()) best = std::max(best, motion::JointAngularSpeedDps(j, prev, cur, frame_time_s));
  return best;
}

double SegmentLibrary::PoseDistance(int a, int f, int b, int g) const {
  const auto x = pose.row(ClipFrameRow(a, f)), y = pose.row(ClipFrameRow(b, g));
  const double joints = static_cast<double>(pose.cols()) / 6.0;
  return std::sqrt(static_cast<double>((x - y).squaredNorm()) / joints);
}

double SegmentLibrary::InterruptCost(int e, int b, int g) const {
  const EndPoint& ep = end_points[static_cast<size_t>(e)];
  return options.transition_weight * PoseDistance(ep.segment, ep.frame, b, g) +
         (ep.last ? 0.0 : options.interruption_penalty);
}

StatusOr<int> CountSegments(const motion::Clip& clip, const SegmentOptions& options) {
  KINEMO_RETURN_IF_ERROR(ValidateSegmentOptions(options));
  KINEMO_ASSIGN_OR_RETURN(auto segs, ::kinemo::gesture::ComputeKinematicSegments(clip, ToKinematic(options)));
  return static_cast<int>(segs.size());
}

StatusOr<std::shared_ptr<const SegmentLibrary>> BuildSegmentLibrary(std::shared_ptr<const Library> library,
                                                                    const SegmentOptions& options) {
  KINEMO_RETURN_IF_ERROR(ValidateSegmentOptions(options));
  if (library == nullptr || library->clips.empty()) return InvalidField("library", "has no clips");
  auto out = std::make_shared<SegmentLibrary>();
  out->library = library;
  out->options = options;
  out->tones = library->tones();
  out->keywords = library->keywords();
  const int joints = library->skeleton.num_joints();
  if (joints < 2) return InvalidField("library", "skeleton needs at least 2 joints");
  const int cols = 6 * (joints - 1);
  int total_frames = 0;
  for (const auto& c : library->clips) {
    out->clip_row.push_back(total_frames);
    total_frames += c.clip.num_frames();
  }
  out->pose.resize(total_frames, cols);
  std::vector<double> speeds;
  for (size_t ci = 0; ci < library->clips.size(); ++ci) {
    const LibraryClip& lc = library->clips[ci];
    const motion::Clip& clip = lc.clip;
    auto segs = ::kinemo::gesture::ComputeKinematicSegments(clip, ToKinematic(options));
    if (!segs.ok()) return Annotate(segs.status(), kinemo::StrCat("clips[", ci, "] '", lc.name, "'"));
    KINEMO_ASSIGN_OR_RETURN(Eigen::MatrixXd world, motion::ComputeWorldPositions(clip));
    auto height = BodyHeight(clip, library->regions, world);
    if (!height.ok()) return Annotate(height.status(), kinemo::StrCat("clips[", ci, "] '", lc.name, "'"));
    const int n = clip.num_frames();
    const double dt = clip.frame_time_s;
    for (int f = 0; f < n; ++f) {
      const int fa = std::max(0, f - 1), fb = std::min(n - 1, f + 1);
      auto row = out->pose.row(out->clip_row[ci] + f);
      for (int j = 1; j < joints; ++j) {
        const Eigen::Vector3d p = (world.row(f).segment<3>(3 * j) - world.row(f).segment<3>(0)).transpose() / *height;
        const Eigen::Vector3d v = ((world.row(fb).segment<3>(3 * j) - world.row(fb).segment<3>(0)) -
                                   (world.row(fa).segment<3>(3 * j) - world.row(fa).segment<3>(0)))
                                      .transpose() /
                                  (std::max(1, fb - fa) * dt) / *height * 0.1;
        for (int k = 0; k < 3; ++k) {
          row(6 * (j - 1) + k) = static_cast<float>(p(k));
          row(6 * (j - 1) + 3 + k) = static_cast<float>(v(k));
        }
      }
      if (f > 0) speeds.push_back(MaxJointAngularSpeedDps(clip.skeleton, clip.frame(f - 1), clip.frame(f), dt));
    }
    // Stroke of a keyword clip: the segment with the largest V.
    int stroke = -1;
    if (!lc.keywords.empty()) {
      double best = -1e300;
      for (size_t k = 0; k < segs->size(); ++k) {
        if ((*segs)[k].params(2) > best) {
          best = (*segs)[k].params(2);
          stroke = static_cast<int>(k);
        }
      }
    }
    const int tone = static_cast<int>(std::lower_bound(out->tones.begin(), out->tones.end(), lc.tone) - out->tones.begin());
    const int base = out->num_segments();
    for (size_t k = 0; k < segs->size(); ++k) {
      const auto& ks = (*segs)[k];
      GestureSegment g;
      g.clip = static_cast<int>(ci);
      g.first_frame = static_cast<int>(std::lround(ks.start_s / dt));
      const int last = std::min(n, static_cast<int>(std::lround(ks.end_s / dt)));
      g.num_frames = std::max(1, last - g.first_frame);
      g.params = ks.params;
      g.tone = tone;
      g.prev = k > 0 ? base + static_cast<int>(k) - 1 : -1;
      g.next = k + 1 < segs->size() ? base + static_cast<int>(k) + 1 : -1;
      std::set<int> ends;
      for (int r = 1; r <= options.interruption_frames; ++r) {
        const int f = static_cast<int>(std::lround(static_cast<double>(g.num_frames) * r / (options.interruption_frames + 1)));
        if (f >= 1 && f <= g.num_frames - 2) ends.insert(f);
      }
      ends.insert(g.num_frames - 1);
      g.ends.assign(ends.begin(), ends.end());
      g.first_end = out->num_end_points();
      for (size_t e = 0; e < g.ends.size(); ++e) {
        EndPoint ep;
        ep.segment = out->num_segments();
        ep.k = static_cast<int>(e);
        ep.frame = g.ends[e];
        ep.last = e + 1 == g.ends.size();
        ep.block_in = e == 0 ? g.ends[0] + 1 : g.ends[e] - g.ends[e - 1];
        out->end_points.push_back(ep);
      }
      if (static_cast<int>(k) == stroke) {
        g.stroke = true;
        for (const auto& w : lc.keywords) {
          g.keywords.push_back(static_cast<int>(std::lower_bound(out->keywords.begin(), out->keywords.end(), w) -
                                                out->keywords.begin()));
        }
      }
      out->segments.push_back(std::move(g));
    }
  }
  if (!speeds.empty()) {
    std::sort(speeds.begin(), speeds.end());
    out->angular_speed_p99_dps = speeds[static_cast<size_t>(0.99 * static_cast<double>(speeds.size() - 1))];
    out->angular_speed_max_dps = speeds.back();
  }

  out->rest = FindRestFrame(*library);
  out->ground_height_m = LibraryGroundHeight(*library);

  // D_seg between segment starts, then S(e, b).
  const int N = out->num_segments(), E = out->num_end_points();
  const double w = options.transition_weight;
  const int threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  std::vector<float> dseg(static_cast<size_t>(N) * N);
  const SegmentLibrary& L = *out;
  parallel::ParallelForRanges(N, threads, [&](int lo, int hi, int) {
    for (int a = lo; a < hi; ++a) {
      const auto& sa = L.segments[static_cast<size_t>(a)];
      for (int b = 0; b < N; ++b) {
        const auto& sb = L.segments[static_cast<size_t>(b)];
        const double d = w * L.PoseDistance(a, 0, b, 0) + std::abs(sa.params(0) - sb.params(0)) +
                         std::abs(sa.params(2) - sb.params(2)) + std::abs(sa.params(1) - sb.params(1));
        dseg[static_cast<size_t>(a) * N + b] = static_cast<float>(d);
      }
    }
  });
  out->transition.assign(static_cast<size_t>(E) * N, 0.f);
  parallel::ParallelForRanges(E, threads, [&](int lo, int hi, int) {
    for (int e = lo; e < hi; ++e) {
      const EndPoint& ep = L.end_points[static_cast<size_t>(e)];
      const auto& sa = L.segments[static_cast<size_t>(ep.segment)];
      float* row = out->transition.data() + static_cast<size_t>(e) * N;
      for (int b = 0; b < N; ++b) {
        if (!ep.last) {
          row[b] = static_cast<float>(L.InterruptCost(e, b, 0));
          continue;
        }
        const auto& sb = L.segments[static_cast<size_t>(b)];
        const double end_to_b = w * L.PoseDistance(ep.segment, ep.frame, b, 0);
        const double succ = sa.next >= 0 ? dseg[static_cast<size_t>(sa.next) * N + b] : end_to_b;
        const double pred = sb.prev >= 0 ? dseg[static_cast<size_t>(ep.segment) * N + sb.prev] : end_to_b;
        row[b] = static_cast<float>(succ + pred);
      }
    }
  });
  return std::shared_ptr<const SegmentLibrary>(std::move(out));
}

}  // namespace kinemo::planner::controller
