// The AR view against the cube renderer's ground truth: a rendered cube video
// (real photograph behind, noise, blur, a hand) is tracked, the Quaternius
// man is drawn beside the cube playing the action of its top face, and his
// soles must land where the true cube position puts them on the table, in
// the geometry (projected sole points) and in the pixels drawn (the bottom of
// the drawn feet).
#include <algorithm>
#include <cmath>
#include <set>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/strings/match.h"

#include "common/motion/bvh.h"
#include "common/retarget/mesh.h"
#include "common/retarget/rig.h"
#include "services/cube_tracker/ar/ar_view.h"
#include "services/cube_tracker/core/tracker.h"
#include "services/cube_tracker/render/renderer.h"

namespace kinemo::cube::ar {
namespace {

const std::string kData = KINEMO_TEST_DATA_DIR;
constexpr double kFacingP50Deg = 12, kFacingP95Deg = 15;

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(std::min<double>(v.size() - 1, std::floor(q * (v.size() - 1) + 0.5)))];
}

std::shared_ptr<const retarget::Rig> Man() {
  auto rig = retarget::LoadGltfRig(kData + "/characters/quaternius_man_casual.glb");
  EXPECT_TRUE(rig.ok()) << rig.status();
  return std::make_shared<const retarget::Rig>(*std::move(rig));
}

StatusOr<ArOverlay> MakeOverlay(const std::shared_ptr<const retarget::Rig>& man, const ArOptions& options) {
  KINEMO_ASSIGN_OR_RETURN(std::unique_ptr<CharacterView> view, CharacterView::Create(man, options.shadow_opacity));
  std::vector<ActionPlayer::Source> sources;
  const std::pair<Action, const char*> clips[] = {{Action::kIdle, "dataset-1_respond_normal_001.bvh"},
                                                  {Action::kThrowingKisses, "dataset-1_byebye_normal_001.bvh"},
                                                  {Action::kShouting, "dataset-1_bye_angry_001.bvh"}};
  for (const auto& [action, file] : clips) {
    KINEMO_ASSIGN_OR_RETURN(motion::Clip clip, motion::ReadBvhFile(kData + "/planner_gesture/" + file));
    sources.push_back({action, std::move(clip), 0});
  }
  KINEMO_ASSIGN_OR_RETURN(ActionPlayer player, ActionPlayer::Create(*man, std::move(sources)));
  return ArOverlay(std::move(view), std::move(player), options);
}

TEST(CharacterMesh, SkinsTheQuaterniusManInItsBindPose) {
  auto man = Man();
  auto mesh = retarget::LoadCharacterMesh(*man);
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  EXPECT_GT(mesh->triangles.size(), 5000u);
  // The bind pose stands on the floor, about 1.7-2 m tall (glTF metres).
  EXPECT_NEAR(mesh->min_corner.y(), 0.0, 0.03);
  EXPECT_GT(mesh->max_corner.y(), 1.5);
  EXPECT_LT(mesh->max_corner.y(), 2.2);
  // The rest frame (zero channels at the bind pose) leaves every vertex in place.
  std::vector<double> rest(static_cast<size_t>(man->skeleton.num_channels()), 0.0);
  for (int j = 0; j < man->skeleton.num_joints(); ++j) {
    const auto& joint = man->skeleton.joint(j);
    for (size_t c = 0; c < joint.channels.size(); ++c) {
      if (joint.channels[c] == motion::ChannelType::kXPosition) rest[static_cast<size_t>(joint.first_channel) + c] = joint.offset.x();
      if (joint.channels[c] == motion::ChannelType::kYPosition) rest[static_cast<size_t>(joint.first_channel) + c] = joint.offset.y();
      if (joint.channels[c] == motion::ChannelType::kZPosition) rest[static_cast<size_t>(joint.first_channel) + c] = joint.offset.z();
    }
  }
  retarget::SkinPose pose;
  ASSERT_TRUE(retarget::ComputeSkinPose(*man, rest, &pose).ok());
  std::vector<Eigen::Vector3f> posed;
  retarget::SkinMesh(*mesh, pose, &posed, nullptr);
  float worst = 0;
  for (size_t v = 0; v < posed.size(); ++v) worst = std::max(worst, (posed[v] - mesh->positions[v]).norm());
  EXPECT_LT(worst, 1e-4f);
}

TEST(ArView, TheCharactersFeetStandOnTheTableBesideTheTrueCube) {
  auto model = LoadCubeModel(kData + "/cube/vleo.cube");
  ASSERT_TRUE(model.ok());
  auto script = LoadRenderScript(kData + "/cube/lift_rotate_place.json");
  ASSERT_TRUE(script.ok());
  auto renderer = SequenceRenderer::Create(*model, *script);
  ASSERT_TRUE(renderer.ok());
  const CameraModel& camera = renderer->camera();
  ASSERT_TRUE(camera.surface.has_value());
  auto tracker = CubeTracker::Create(*model, camera);
  ASSERT_TRUE(tracker.ok());
  auto man = Man();
  ArOptions options;
  options.shadow_opacity = 0;  // the drawn pixels are the character's only
  auto overlay = MakeOverlay(man, options);
  ASSERT_TRUE(overlay.ok()) << overlay.status();

  std::vector<double> geometry_px, pixels_px, sole_height_mm, carried_px, facing_deg;
  std::set<Action> actions;
  int drawn = 0;
  cv::Mat frame;
  TruthFrame truth;
  CubeState state;
  for (int64_t i = 0; i < renderer->frame_count(); ++i) {
    ASSERT_TRUE(renderer->Next(&frame, &truth).ok());
    ASSERT_TRUE(tracker->Process(frame, truth.time_s, &state).ok());
    const cv::Mat before = frame.clone();
    DrawInfo info;
    ASSERT_TRUE(overlay->Compose(state, tracker->surface(), camera, truth.time_s, &frame, &info).ok());
    if (!info.drawn) continue;
    ++drawn;
    actions.insert(overlay->action());
    // Judged where the tracker sees the cube standing on the table (elsewhere
    // the character stays where the cube was last seen, by design, and while
    // the cube is carried the tracker's filter lags the true position: that
    // is the tracker's error, reported apart).
    if (!state.visible) continue;
    if (!truth.resting) {
      Placement moving = PlaceBeside(truth.position_m, *camera.surface, overlay->view().height(), options);
      moving.origin = overlay->placement().origin;
      moving.facing_rad = overlay->placement().facing_rad;
      const cv::Vec3d s = ToSurface(moving, info.soles_rig[0]);
      std::vector<cv::Point2d> q;
      cv::projectPoints(std::vector<cv::Point3d>{{s[0], s[1], s[2]}}, camera.surface->Rvec(), camera.surface->t,
                        cv::Mat(camera.K), camera.dist, q);
      carried_px.push_back(cv::norm(q[0] - info.soles_px[0]));
      continue;
    }
    // The standing foot: the lower sole (the other may be lifted by the clip).
    const size_t low = info.soles_surface_m[0][2] <= info.soles_surface_m[1][2] ? 0 : 1;
    // Where the soles belong: the same pose placed beside the true cube.
    Placement expected = PlaceBeside(truth.position_m, *camera.surface, overlay->view().height(), options);
    expected.origin = overlay->placement().origin;
    expected.facing_rad = overlay->placement().facing_rad;
    std::vector<cv::Point3d> soles;
    for (int side = 0; side < 2; ++side) {
      const cv::Vec3d s = ToSurface(expected, info.soles_rig[static_cast<size_t>(side)]);
      soles.emplace_back(s[0], s[1], s[2]);
    }
    sole_height_mm.push_back(1000 * std::abs(info.soles_surface_m[low][2]));
    // Facing the camera (thesis §5.2: the AvatAR turns to the viewer): the
    // body's forward on the table against the direction from the true cube
    // placement to the true camera's foot point on the table.
    {
      const cv::Vec3d eye = camera.surface->Inverse().t;
      const cv::Vec2d to_eye(eye[0] - expected.position_m[0], eye[1] - expected.position_m[1]);
      const double c = info.facing_surface.dot(to_eye) / std::max(1e-12, cv::norm(to_eye));
      facing_deg.push_back(std::acos(std::clamp(c, -1.0, 1.0)) * 180 / M_PI);
    }
    std::vector<cv::Point2d> px;
    cv::projectPoints(soles, camera.surface->Rvec(), camera.surface->t, cv::Mat(camera.K), camera.dist, px);
    for (int side = 0; side < 2; ++side) {
      geometry_px.push_back(cv::norm(px[static_cast<size_t>(side)] - info.soles_px[static_cast<size_t>(side)]));
    }
    // The pixels: the lowest drawn pixel near each sole (a window around its
    // true image point) is at the sole's true image row.
    cv::Mat diff;
    cv::absdiff(frame, before, diff);
    cv::Mat1b mask;
    cv::cvtColor(diff, mask, cv::COLOR_BGR2GRAY);
    {
      const cv::Point2d p = px[low];
      int lowest = -1;
      for (int y = std::max(0, static_cast<int>(p.y) - 30); y < std::min(mask.rows, static_cast<int>(p.y) + 30); ++y) {
        for (int x = std::max(0, static_cast<int>(p.x) - 6); x < std::min(mask.cols, static_cast<int>(p.x) + 7); ++x) {
          if (mask(y, x) > 0) lowest = std::max(lowest, y);
        }
      }
      if (lowest >= 0) pixels_px.push_back(std::abs(lowest + 0.5 - p.y));
    }
  }
  std::printf("[ar] while the cube is carried (%zu frames): sole vs truth p50 %.2f p95 %.2f px\n", carried_px.size(),
              Quantile(carried_px, 0.5), Quantile(carried_px, 0.95));
  std::printf("[ar] %d of %lld frames drawn (%zu with the cube seen at rest); sole vs truth: geometry p50 %.2f p95 %.2f max %.2f px, "
              "drawn feet p50 %.2f p95 %.2f px (%zu samples); sole height p95 %.2f mm; %zu actions\n",
              drawn, static_cast<long long>(renderer->frame_count()), sole_height_mm.size(), Quantile(geometry_px, 0.5),
              Quantile(geometry_px, 0.95), Quantile(geometry_px, 1.0), Quantile(pixels_px, 0.5),
              Quantile(pixels_px, 0.95), pixels_px.size(), Quantile(sole_height_mm, 0.95), actions.size());
  std::printf("[ar] facing: body forward vs towards the true camera p50 %.1f p95 %.1f max %.1f deg (%zu frames)\n",
              Quantile(facing_deg, 0.5), Quantile(facing_deg, 0.95), Quantile(facing_deg, 1.0), facing_deg.size());
  EXPECT_GT(drawn, renderer->frame_count() * 9 / 10);
  // Facing the camera: before the retargeting's per-role rest frames and
  // the clip's facing taken over the whole clip the man stood turned away
  // (p50 45, p95 56 deg); now the angry "bye" sways +-10 deg about it.
  EXPECT_LE(Quantile(facing_deg, 0.5), kFacingP50Deg);
  EXPECT_LE(Quantile(facing_deg, 0.95), kFacingP95Deg);
  // A few pixels: the tracker's cube position error, seen at 0.4 m.
  EXPECT_LE(Quantile(geometry_px, 0.5), 2.0);
  EXPECT_LE(Quantile(geometry_px, 0.95), 4.0);
  EXPECT_GT(pixels_px.size(), sole_height_mm.size() / 2);
  // Facing the camera, the shoe's toe cap (4.8 cm in front of the toe's
  // floor point on the man, 4 mm on the table) draws about 3 px below that
  // point's image row (1.9 px while he stood turned away).
  EXPECT_LE(Quantile(pixels_px, 0.5), 4.0);
  EXPECT_LE(Quantile(pixels_px, 0.95), 5.0);
  // Standing on the table: the standing sole is on its plane (the man is
  // 15 cm tall here: 2 mm on the table is 2.3 cm on him).
  EXPECT_LE(Quantile(sole_height_mm, 0.95), 2.0);
  // The cube's faces select different actions along the video.
  EXPECT_GE(actions.size(), 2u);
}

TEST(ArView, BadOptionsAreNamed) {
  ArOptions o;
  o.character_height_m = 0;
  EXPECT_TRUE(absl::StartsWith(ValidateArOptions(o).message(), "character_height_m"));
  o = ArOptions();
  o.shadow_opacity = 2;
  EXPECT_TRUE(absl::StartsWith(ValidateArOptions(o).message(), "shadow_opacity"));
}

}  // namespace
}  // namespace kinemo::cube::ar
