// The physical cube: which ArUco marker is printed on which face, how big the
// cube and the markers are, and which Vleo action each face selects.
//
// Cube frame: origin at the cube's centre, axes along its edges, metres.
// Faces are numbered by their outward normal:
//   0: +Z   1: -Z   2: +X   3: -X   4: +Y   5: -Y
// Each face's marker is printed centred on the face, upright for a viewer
// looking at the face from outside with the face's `up` vector pointing up
// (see FaceFrame). With +Z on top, the four side faces read upright.
//
// A cube model file is a text proto of kinemo.cube_tracker.v1.CubeModel
// (proto/kinemo/cube_tracker/v1/cube_tracker.proto), the message the gRPC
// API and the server options use too:
//   cube_id: "vleo"
//   dictionary: "DICT_4X4_50"
//   cube_size_m: 0.06
//   marker_size_m: 0.045
//   faces { face: CUBE_FACE_POS_Z marker_id: 0 action: ACTION_IDLE }
//   ... (six faces)
// CubeModel below is the validated runtime form (faces by index).
#pragma once

#include <array>
#include <string>
#include <string_view>

#include <opencv2/core.hpp>

#include "common/status/status.h"
#include "kinemo/common/v1/vleo.pb.h"
#include "kinemo/cube_tracker/v1/cube_tracker.pb.h"

namespace kinemo::cube {

// Vleo's actions (thesis §5.3.2): idle, throwing kisses, shouting.
enum class Action { kUnknown = 0, kIdle = 1, kThrowingKisses = 2, kShouting = 3 };

// "idle", "throwing_kisses", "shouting" ("unknown" for kUnknown).
const char* ActionName(Action a);

inline constexpr int kNumFaces = 6;

struct FaceSpec {
  int marker_id = -1;
  Action action = Action::kUnknown;
};

struct CubeModel {
  std::string name = "cube";               // the proto's cube_id
  std::string dictionary = "DICT_4X4_50";  // a cv::aruco::PREDEFINED_DICTIONARY_NAME
  double cube_size_m = 0.06;               // edge length of the cube
  double marker_size_m = 0.045;            // edge length of each marker (black border included)
  std::array<FaceSpec, kNumFaces> faces;

  // Face index printing `marker_id`, or -1.
  int FaceOfMarker(int marker_id) const;
  Action ActionOfFace(int face) const {
    return face >= 0 && face < kNumFaces ? faces[face].action : Action::kUnknown;
  }
};

// The default Vleo cube: DICT_4X4_50 markers 0..5, 6 cm cube, 4.5 cm markers;
// idle on faces 0 and 1, throwing kisses on 2 and 3, shouting on 4 and 5.
CubeModel DefaultVleoCube();

// Checks sizes, ids (distinct, inside the dictionary), the quiet zone around
// the markers, and that each action is on exactly two faces.
Status ValidateCubeModel(const CubeModel& model);

// The proto message <-> the runtime form. FromProto validates; errors name the
// proto's fields ("faces[2].marker_id: ...").
StatusOr<CubeModel> CubeModelFromProto(const cube_tracker::v1::CubeModel& proto);
cube_tracker::v1::CubeModel CubeModelToProto(const CubeModel& model);
// Face index <-> the proto's CubeFace (-1 / UNSPECIFIED when unknown).
int FaceFromProto(cube_tracker::v1::CubeFace face);
cube_tracker::v1::CubeFace FaceToProto(int face);
Action ActionFromProto(common::v1::Action action);
common::v1::Action ActionToProto(Action action);

// Parses the text-proto form above (with config::ParseTextProto; errors carry
// source:line:column). Validates.
StatusOr<CubeModel> ParseCubeModel(std::string_view text, const std::string& source = "cube model");
StatusOr<CubeModel> LoadCubeModel(const std::string& path);
std::string FormatCubeModel(const CubeModel& model);

// OpenCV's predefined dictionary id for a name such as "DICT_4X4_50".
StatusOr<int> DictionaryId(const std::string& name);
// Number of markers in that dictionary.
StatusOr<int> DictionarySize(const std::string& name);

// Geometry of one face in the cube frame.
struct FaceFrame {
  cv::Vec3d normal;  // outward
  cv::Vec3d right;   // texture +x as seen from outside
  cv::Vec3d down;    // texture +y as seen from outside (right x down = -normal)
};
const FaceFrame& FaceFrameOf(int face);

// The marker's four corners in the cube frame, in ArUco's order
// (top-left, top-right, bottom-right, bottom-left as seen from outside).
std::array<cv::Point3f, 4> MarkerCorners(const CubeModel& model, int face);
// The face's four corners (same order) in the cube frame.
std::array<cv::Point3f, 4> FaceCorners(const CubeModel& model, int face);

// A square texture of one face (white face, marker centred), `pixels` wide, 8-bit grey.
// INVALID_ARGUMENT naming `pixels` when the marker would get fewer pixels
// than it has modules (a marker tiny against its face).
StatusOr<cv::Mat> RenderFaceTexture(const CubeModel& model, int face, int pixels);

// The cube's net (a cross: +Z above -Y; -X, -Y, +X, +Y in a row; -Z below -Y)
// at `dpi`, with cut lines, dashed fold lines and a caption. 8-bit grey.
StatusOr<cv::Mat> RenderNet(const CubeModel& model, double dpi);

}  // namespace kinemo::cube
