#include "services/cube_tracker/core/cube_model.h"

#include <functional>

#include <gtest/gtest.h>
#include <opencv2/aruco.hpp>
#include <opencv2/imgproc.hpp>

#include "services/cube_tracker/core/camera.h"

namespace kinemo::cube {
namespace {

const std::string kData = KINEMO_TEST_DATA_DIR;

TEST(CubeModel, LoadsTheShippedVleoCube) {
  auto m = LoadCubeModel(kData + "/cube/vleo.cube");
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->name, "vleo");
  EXPECT_DOUBLE_EQ(m->cube_size_m, 0.06);
  EXPECT_EQ(m->faces[4].marker_id, 4);
  EXPECT_EQ(m->ActionOfFace(2), Action::kThrowingKisses);
  EXPECT_EQ(m->FaceOfMarker(5), 5);
  EXPECT_EQ(m->FaceOfMarker(17), -1);
}

TEST(CubeModel, FormatParsesBack) {
  CubeModel m = DefaultVleoCube();
  m.faces[0].marker_id = 7;
  m.faces[3].marker_id = 0;
  auto back = ParseCubeModel(FormatCubeModel(m));
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->faces[0].marker_id, 7);
  EXPECT_EQ(back->faces[3].marker_id, 0);
  EXPECT_EQ(back->faces[5].action, Action::kShouting);
}

TEST(CubeModel, RejectsBadModelsNamingTheField) {
  using Proto = cube_tracker::v1::CubeModel;
  struct Case {
    std::function<void(Proto&)> mutate;
    std::string expect;
  };
  const Case cases[] = {
      {[](Proto& p) { p.mutable_faces(1)->set_marker_id(0); }, "faces[1].marker_id: 0 is used by another face"},
      {[](Proto& p) { p.mutable_faces(5)->set_marker_id(50); }, "faces[5].marker_id: 50 is not in DICT_4X4_50"},
      {[](Proto& p) { p.set_dictionary("DICT_9X9_1"); }, "dictionary:"},
      {[](Proto& p) { p.set_marker_size_m(0.059); }, "marker_size_m:"},
      {[](Proto& p) { p.set_cube_size_m(-1); }, "cube_size_m:"},
      {[](Proto& p) { p.set_cube_id("Vleo Cube"); }, "cube_id:"},
      {[](Proto& p) { p.mutable_faces(5)->set_action(common::v1::ACTION_IDLE); }, "exactly two"},
      {[](Proto& p) { p.mutable_faces(3)->set_action(common::v1::ACTION_UNSPECIFIED); }, "faces[3].action: missing"},
      {[](Proto& p) { p.mutable_faces()->RemoveLast(); }, "faces: 5 faces given"},
      {[](Proto& p) { p.mutable_faces(4)->set_face(cube_tracker::v1::CUBE_FACE_POS_Z); }, "faces[4].face: CUBE_FACE_POS_Z is given twice"},
      {[](Proto& p) { p.mutable_faces(2)->set_face(cube_tracker::v1::CUBE_FACE_UNSPECIFIED); }, "faces[2].face:"},
  };
  for (const Case& c : cases) {
    Proto p = CubeModelToProto(DefaultVleoCube());
    c.mutate(p);
    auto m = CubeModelFromProto(p);
    ASSERT_FALSE(m.ok()) << c.expect;
    EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(std::string(m.status().message()).find(c.expect), std::string::npos) << m.status();
  }
  // Text errors carry the source, line and column.
  auto bad = ParseCubeModel("cube_id: \"vleo\"\ncolour: 3\n", "t.cube");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(std::string(bad.status().message()).find("t.cube:2:"), std::string::npos) << bad.status();
  auto nan = ParseCubeModel("cube_size_m: 0.0x6\n", "t.cube");
  ASSERT_FALSE(nan.ok());
  EXPECT_NE(std::string(nan.status().message()).find("t.cube:1:"), std::string::npos) << nan.status();
  auto invalid = ParseCubeModel(FormatCubeModel(DefaultVleoCube()) + "cube_size_m: -1\n", "t.cube");
  ASSERT_FALSE(invalid.ok());
  EXPECT_NE(std::string(invalid.status().message()).find("t.cube: cube_size_m:"), std::string::npos)
      << invalid.status();
  EXPECT_FALSE(LoadCubeModel("/nonexistent/x.cube").ok());
}

TEST(CubeModel, ProtoFacesMapToTheCubeFrame) {
  for (int f = 0; f < kNumFaces; ++f) {
    const std::string name = cube_tracker::v1::CubeFace_Name(FaceToProto(f));
    const FaceFrame& fr = FaceFrameOf(f);
    const int axis = name.back() - 'X';
    const double sign = name.find("POS") != std::string::npos ? 1 : -1;
    EXPECT_EQ(fr.normal[axis], sign) << name;
    EXPECT_EQ(FaceFromProto(FaceToProto(f)), f);
  }
}

TEST(CubeModel, FaceFramesAreRightHandedAndOutward) {
  for (int f = 0; f < kNumFaces; ++f) {
    const FaceFrame& fr = FaceFrameOf(f);
    EXPECT_NEAR(cv::norm(fr.right.cross(fr.down) + fr.normal), 0, 1e-12) << f;
  }
}

// The printed texture of every face decodes to its own marker, and the net
// carries all six.
TEST(CubeModel, TexturesAndNetDecode) {
  CubeModel m = DefaultVleoCube();
  auto dict = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_50);
  for (int f = 0; f < kNumFaces; ++f) {
    auto tex = RenderFaceTexture(m, f, 200);
    ASSERT_TRUE(tex.ok());
    cv::Mat padded;
    cv::copyMakeBorder(*tex, padded, 20, 20, 20, 20, cv::BORDER_CONSTANT, cv::Scalar(128));
    std::vector<std::vector<cv::Point2f>> corners;
    std::vector<int> ids;
    cv::aruco::detectMarkers(padded, dict, corners, ids);
    ASSERT_EQ(ids.size(), 1u) << f;
    EXPECT_EQ(ids[0], m.faces[f].marker_id);
    // Corner 0 is the marker's top-left in the texture.
    EXPECT_LT(corners[0][0].x, 100);
    EXPECT_LT(corners[0][0].y, 100);
  }
  auto net = RenderNet(m, 150);
  ASSERT_TRUE(net.ok()) << net.status();
  const int face_px = static_cast<int>(std::lround(0.06 / 0.0254 * 150));
  EXPECT_GE(net->cols, 4 * face_px);
  std::vector<std::vector<cv::Point2f>> corners;
  std::vector<int> ids;
  cv::aruco::detectMarkers(*net, dict, corners, ids);
  std::sort(ids.begin(), ids.end());
  EXPECT_EQ(ids, (std::vector<int>{0, 1, 2, 3, 4, 5}));
  EXPECT_FALSE(RenderNet(m, 5).ok());
}

// Found by tests/fuzz/cube_model_fuzz (corpus: regression-tiny-marker.binpb): a
// valid model whose marker is tiny against its face made OpenCV throw while
// drawing it (INTERNAL); it is the caller's pixel count that is too small.
TEST(CubeModel, TinyMarkerTextureNamesThePixels) {
  CubeModel m = DefaultVleoCube();
  m.cube_size_m = 1.5;
  m.marker_size_m = 1e-6;
  ASSERT_TRUE(ValidateCubeModel(m).ok());
  auto tex = RenderFaceTexture(m, 0, 384);
  ASSERT_FALSE(tex.ok());
  EXPECT_EQ(tex.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(tex.status().message().rfind("pixels: ", 0), 0u) << tex.status();
  m.marker_size_m = 0.1;  // 26 px for 6 modules
  EXPECT_TRUE(RenderFaceTexture(m, 0, 384).ok());
}

TEST(Camera, SavesAndLoadsWithSurface) {
  CameraModel c = PinholeCamera(640, 480, 60);
  c.surface = Pose::FromRvecTvec(cv::Vec3d(0.1, -0.2, 0.3), cv::Vec3d(0.01, 0.02, 0.4));
  const std::string path = ::testing::TempDir() + "/cam.yaml";
  ASSERT_TRUE(SaveCameraModel(c, path).ok());
  auto back = LoadCameraModel(path);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->width, 640);
  EXPECT_NEAR(back->K(0, 0), c.K(0, 0), 1e-9);
  ASSERT_TRUE(back->surface.has_value());
  EXPECT_NEAR(cv::norm(back->surface->t - c.surface->t), 0, 1e-12);
  EXPECT_FALSE(LoadCameraModel(::testing::TempDir() + "/missing.yaml").ok());
}

}  // namespace
}  // namespace kinemo::cube
