#include "services/cube_tracker/core/cube_model.h"

#include <cctype>
#include <charconv>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <opencv2/aruco.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "common/config/options.h"
#include <google/protobuf/text_format.h>

namespace kinemo::cube {
namespace {

const std::map<std::string, int, std::less<>>& Dictionaries() {
  static const auto* dicts = new std::map<std::string, int, std::less<>>{
      {"DICT_4X4_50", cv::aruco::DICT_4X4_50},
      {"DICT_4X4_100", cv::aruco::DICT_4X4_100},
      {"DICT_4X4_250", cv::aruco::DICT_4X4_250},
      {"DICT_4X4_1000", cv::aruco::DICT_4X4_1000},
      {"DICT_5X5_50", cv::aruco::DICT_5X5_50},
      {"DICT_5X5_100", cv::aruco::DICT_5X5_100},
      {"DICT_5X5_250", cv::aruco::DICT_5X5_250},
      {"DICT_5X5_1000", cv::aruco::DICT_5X5_1000},
      {"DICT_6X6_50", cv::aruco::DICT_6X6_50},
      {"DICT_6X6_100", cv::aruco::DICT_6X6_100},
      {"DICT_6X6_250", cv::aruco::DICT_6X6_250},
      {"DICT_6X6_1000", cv::aruco::DICT_6X6_1000},
      {"DICT_7X7_50", cv::aruco::DICT_7X7_50},
      {"DICT_7X7_100", cv::aruco::DICT_7X7_100},
      {"DICT_7X7_250", cv::aruco::DICT_7X7_250},
      {"DICT_7X7_1000", cv::aruco::DICT_7X7_1000},
      {"DICT_ARUCO_ORIGINAL", cv::aruco::DICT_ARUCO_ORIGINAL},
  };
  return *dicts;
}

// Bits per side of a dictionary's markers (from its name).
int MarkerBits(std::string_view dict) {
  if (dict.size() > 5 && dict.substr(0, 5) == "DICT_" && std::isdigit(dict[5])) return dict[5] - '0';
  return 5;  // DICT_ARUCO_ORIGINAL
}

}  // namespace

const char* ActionName(Action a) {
  switch (a) {
    case Action::kIdle:
      return "idle";
    case Action::kThrowingKisses:
      return "throwing_kisses";
    case Action::kShouting:
      return "shouting";
    case Action::kUnknown:
      break;
  }
  return "unknown";
}

int CubeModel::FaceOfMarker(int marker_id) const {
  for (int f = 0; f < kNumFaces; ++f) {
    if (faces[f].marker_id == marker_id) return f;
  }
  return -1;
}

CubeModel DefaultVleoCube() {
  CubeModel m;
  m.name = "vleo";
  const Action actions[kNumFaces] = {Action::kIdle,     Action::kIdle,     Action::kThrowingKisses,
                                     Action::kThrowingKisses, Action::kShouting, Action::kShouting};
  for (int f = 0; f < kNumFaces; ++f) m.faces[f] = FaceSpec{f, actions[f]};
  return m;
}

StatusOr<int> DictionaryId(const std::string& name) {
  auto it = Dictionaries().find(name);
  if (it == Dictionaries().end()) {
    return InvalidField("dictionary", "'", name, "' is not a predefined ArUco dictionary (e.g. DICT_4X4_50)");
  }
  return it->second;
}

StatusOr<int> DictionarySize(const std::string& name) {
  KINEMO_ASSIGN_OR_RETURN(int id, DictionaryId(name));
  cv::Ptr<cv::aruco::Dictionary> d = cv::aruco::getPredefinedDictionary(id);
  return d->bytesList.rows;
}

Status ValidateCubeModel(const CubeModel& m) {
  KINEMO_ASSIGN_OR_RETURN(int dict_size, DictionarySize(m.dictionary));
  if (!(m.cube_size_m > 0.005 && m.cube_size_m < 2.0)) {
    return InvalidField("cube_size_m", m.cube_size_m, " is outside (0.005, 2) metres");
  }
  if (!(m.marker_size_m > 0 && m.marker_size_m < m.cube_size_m)) {
    return InvalidField("marker_size_m", m.marker_size_m, " must be positive and smaller than cube_size_m ",
                        m.cube_size_m);
  }
  // ArUco needs a white quiet zone of about one module around the marker.
  const double module = m.marker_size_m / (MarkerBits(m.dictionary) + 2);
  if ((m.cube_size_m - m.marker_size_m) / 2 < 0.75 * module) {
    return InvalidField("marker_size_m", m.marker_size_m, " leaves a white margin of ",
                        (m.cube_size_m - m.marker_size_m) / 2, " m, less than one marker module (", module,
                        " m)");
  }
  std::set<int> ids;
  std::map<Action, int> per_action;
  for (int f = 0; f < kNumFaces; ++f) {
    const FaceSpec& s = m.faces[f];
    if (s.marker_id < 0 || s.marker_id >= dict_size) {
      return InvalidField(absl::StrCat("face[", f, "].marker_id"), s.marker_id, " is not in ", m.dictionary,
                          " (0..", dict_size - 1, ")");
    }
    if (!ids.insert(s.marker_id).second) {
      return InvalidField(absl::StrCat("face[", f, "].marker_id"), s.marker_id, " is used by another face");
    }
    if (s.action == Action::kUnknown) {
      return InvalidField(absl::StrCat("face[", f, "].action"), "missing");
    }
    ++per_action[s.action];
  }
  for (Action a : {Action::kIdle, Action::kThrowingKisses, Action::kShouting}) {
    if (per_action[a] != 2) {
      return InvalidField("face.action", ActionName(a), " is on ", per_action[a],
                          " faces; each action needs exactly two");
    }
  }
  return absl::OkStatus();
}

namespace {

using ProtoFace = cube_tracker::v1::CubeFace;

constexpr ProtoFace kProtoFaces[kNumFaces] = {
    cube_tracker::v1::CUBE_FACE_POS_Z, cube_tracker::v1::CUBE_FACE_NEG_Z, cube_tracker::v1::CUBE_FACE_POS_X,
    cube_tracker::v1::CUBE_FACE_NEG_X, cube_tracker::v1::CUBE_FACE_POS_Y, cube_tracker::v1::CUBE_FACE_NEG_Y};

}  // namespace

int FaceFromProto(cube_tracker::v1::CubeFace face) {
  for (int f = 0; f < kNumFaces; ++f) {
    if (kProtoFaces[f] == face) return f;
  }
  return -1;
}

cube_tracker::v1::CubeFace FaceToProto(int face) {
  return face >= 0 && face < kNumFaces ? kProtoFaces[face] : cube_tracker::v1::CUBE_FACE_UNSPECIFIED;
}

Action ActionFromProto(common::v1::Action action) {
  switch (action) {
    case common::v1::ACTION_IDLE:
      return Action::kIdle;
    case common::v1::ACTION_KISSES:
      return Action::kThrowingKisses;
    case common::v1::ACTION_SHOUTING:
      return Action::kShouting;
    default:
      return Action::kUnknown;
  }
}

common::v1::Action ActionToProto(Action action) {
  switch (action) {
    case Action::kIdle:
      return common::v1::ACTION_IDLE;
    case Action::kThrowingKisses:
      return common::v1::ACTION_KISSES;
    case Action::kShouting:
      return common::v1::ACTION_SHOUTING;
    case Action::kUnknown:
      break;
  }
  return common::v1::ACTION_UNSPECIFIED;
}

StatusOr<CubeModel> CubeModelFromProto(const cube_tracker::v1::CubeModel& p) {
  CubeModel m;
  m.name = p.cube_id();
  if (m.name.empty() || m.name.size() > 64 ||
      m.name.find_first_not_of("abcdefghijklmnopqrstuvwxyz0123456789_-") != std::string::npos) {
    return InvalidField("cube_id", "'", m.name, "' is not [a-z0-9_-]{1,64}");
  }
  m.dictionary = p.dictionary();
  m.cube_size_m = p.cube_size_m();
  m.marker_size_m = p.marker_size_m();
  for (auto& f : m.faces) f = FaceSpec{};
  std::array<bool, kNumFaces> given{};
  for (int i = 0; i < p.faces_size(); ++i) {
    const auto& fm = p.faces(i);
    const int f = FaceFromProto(fm.face());
    if (f < 0) return InvalidField(absl::StrCat("faces[", i, "].face"), "missing or unknown");
    if (given[f]) {
      return InvalidField(absl::StrCat("faces[", i, "].face"), cube_tracker::v1::CubeFace_Name(fm.face()),
                          " is given twice");
    }
    given[f] = true;
    if (fm.marker_id() > 1000000u) {
      return InvalidField(absl::StrCat("faces[", i, "].marker_id"), fm.marker_id(), " is out of range");
    }
    m.faces[f].marker_id = static_cast<int>(fm.marker_id());
    m.faces[f].action = ActionFromProto(fm.action());
  }
  if (p.faces_size() != kNumFaces) {
    return InvalidField("faces", p.faces_size(), " faces given, the cube needs all 6");
  }
  // Re-run the checks with the proto's field names.
  Status s = ValidateCubeModel(m);
  if (!s.ok()) {
    std::string msg(s.message());
    for (int i = 0; i < p.faces_size(); ++i) {
      const std::string core = absl::StrCat("face[", FaceFromProto(p.faces(i).face()), "]");
      if (msg.rfind(core, 0) == 0) msg = absl::StrCat("faces[", i, "]", msg.substr(core.size()));
    }
    if (msg.rfind("face.action", 0) == 0) msg = absl::StrCat("faces.action", msg.substr(11));
    return Status(s.code(), msg);
  }
  return m;
}

cube_tracker::v1::CubeModel CubeModelToProto(const CubeModel& m) {
  cube_tracker::v1::CubeModel p;
  p.set_cube_id(m.name);
  p.set_dictionary(m.dictionary);
  p.set_cube_size_m(m.cube_size_m);
  p.set_marker_size_m(m.marker_size_m);
  for (int f = 0; f < kNumFaces; ++f) {
    auto* fm = p.add_faces();
    fm->set_face(FaceToProto(f));
    fm->set_marker_id(static_cast<uint32_t>(std::max(0, m.faces[f].marker_id)));
    fm->set_action(ActionToProto(m.faces[f].action));
  }
  return p;
}

StatusOr<CubeModel> ParseCubeModel(std::string_view text, const std::string& source) {
  cube_tracker::v1::CubeModel p;
  KINEMO_RETURN_IF_ERROR(config::ParseTextProto(text, source, &p));
  auto m = CubeModelFromProto(p);
  if (!m.ok()) return Annotate(m.status(), source);
  return m;
}

StatusOr<CubeModel> LoadCubeModel(const std::string& path) {
  cube_tracker::v1::CubeModel p;
  KINEMO_RETURN_IF_ERROR(config::LoadTextProtoFile(path, &p));
  auto m = CubeModelFromProto(p);
  if (!m.ok()) return Annotate(m.status(), path);
  return m;
}

std::string FormatCubeModel(const CubeModel& m) {
  std::string body;
  google::protobuf::TextFormat::PrintToString(CubeModelToProto(m), &body);
  return absl::StrCat("# kinemo cube model: a text proto of kinemo.cube_tracker.v1.CubeModel\n", body);
}

const FaceFrame& FaceFrameOf(int face) {
  static const FaceFrame kFrames[kNumFaces] = {
      {{0, 0, 1}, {1, 0, 0}, {0, -1, 0}},    // +Z
      {{0, 0, -1}, {1, 0, 0}, {0, 1, 0}},    // -Z
      {{1, 0, 0}, {0, 1, 0}, {0, 0, -1}},    // +X
      {{-1, 0, 0}, {0, -1, 0}, {0, 0, -1}},  // -X
      {{0, 1, 0}, {-1, 0, 0}, {0, 0, -1}},   // +Y
      {{0, -1, 0}, {1, 0, 0}, {0, 0, -1}},   // -Y
  };
  return kFrames[face];
}

namespace {
std::array<cv::Point3f, 4> SquareOnFace(const CubeModel& m, int face, double side) {
  const FaceFrame& fr = FaceFrameOf(face);
  const cv::Vec3d c = fr.normal * (m.cube_size_m / 2);
  const double h = side / 2;
  auto p = [&](double sx, double sy) {
    cv::Vec3d v = c + fr.right * (sx * h) + fr.down * (sy * h);
    return cv::Point3f(static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2]));
  };
  return {p(-1, -1), p(1, -1), p(1, 1), p(-1, 1)};
}
}  // namespace

std::array<cv::Point3f, 4> MarkerCorners(const CubeModel& m, int face) {
  return SquareOnFace(m, face, m.marker_size_m);
}
std::array<cv::Point3f, 4> FaceCorners(const CubeModel& m, int face) {
  return SquareOnFace(m, face, m.cube_size_m);
}

StatusOr<cv::Mat> RenderFaceTexture(const CubeModel& m, int face, int pixels) {
  if (face < 0 || face >= kNumFaces) return InvalidField("face", face, " is not in 0..5");
  if (pixels < 16 || pixels > 8192) return InvalidField("pixels", pixels, " is not in 16..8192");
  KINEMO_ASSIGN_OR_RETURN(int dict_id, DictionaryId(m.dictionary));
  try {
    cv::Mat tex(pixels, pixels, CV_8UC1, cv::Scalar(255));
    const int marker_px = static_cast<int>(std::lround(pixels * m.marker_size_m / m.cube_size_m));
    // Draw the marker with exact module boundaries, then scale it with nearest
    // neighbour so module edges stay sharp.
    const int bits = MarkerBits(m.dictionary) + 2;
    if (marker_px < bits) {
      return InvalidField("pixels", pixels, " draw the marker (", m.marker_size_m, " m on a ",
                          m.cube_size_m, " m face) in ", marker_px, " px, fewer than its ", bits,
                          " modules");
    }
    cv::Mat small;
    cv::aruco::drawMarker(cv::aruco::getPredefinedDictionary(dict_id), m.faces[face].marker_id, bits, small, 1);
    cv::Mat marker;
    cv::resize(small, marker, cv::Size(marker_px, marker_px), 0, 0, cv::INTER_NEAREST);
    const int off = (pixels - marker_px) / 2;
    marker.copyTo(tex(cv::Rect(off, off, marker_px, marker_px)));
    return tex;
  } catch (const cv::Exception& e) {
    return absl::InternalError(absl::StrCat("RenderFaceTexture: OpenCV: ", e.what()));
  }
}

StatusOr<cv::Mat> RenderNet(const CubeModel& m, double dpi) {
  if (!(dpi >= 50 && dpi <= 1200)) return InvalidField("dpi", dpi, " is not in 50..1200");
  const int face_px = static_cast<int>(std::lround(m.cube_size_m / 0.0254 * dpi));
  const int margin = face_px / 4;
  const int caption_h = face_px / 2;
  cv::Mat net(3 * face_px + 2 * margin + caption_h, 4 * face_px + 2 * margin, CV_8UC1, cv::Scalar(255));
  // (column, row) of each face in the cross.
  const cv::Point cell[kNumFaces] = {{1, 0}, {1, 2}, {2, 1}, {0, 1}, {3, 1}, {1, 1}};
  try {
    for (int f = 0; f < kNumFaces; ++f) {
      KINEMO_ASSIGN_OR_RETURN(cv::Mat tex, RenderFaceTexture(m, f, face_px));
      cv::Rect r(margin + cell[f].x * face_px, margin + cell[f].y * face_px, face_px, face_px);
      tex.copyTo(net(r));
    }
    const int thick = std::max(1, face_px / 200);
    // Fold lines (dashed) between adjacent faces, cut lines (solid) on the outline.
    auto dashed = [&](cv::Point a, cv::Point b) {
      const double len = cv::norm(b - a);
      const int n = std::max(2, static_cast<int>(len / (face_px / 20.0)));
      for (int i = 0; i < n; i += 2) {
        cv::Point2d p0 = cv::Point2d(a) + (cv::Point2d(b - a)) * (static_cast<double>(i) / n);
        cv::Point2d p1 = cv::Point2d(a) + (cv::Point2d(b - a)) * (static_cast<double>(i + 1) / n);
        cv::line(net, p0, p1, cv::Scalar(150), thick);
      }
    };
    for (int f = 0; f < kNumFaces; ++f) {
      cv::Rect r(margin + cell[f].x * face_px, margin + cell[f].y * face_px, face_px, face_px);
      const cv::Point tl = r.tl(), tr(r.x + r.width, r.y), br = r.br(), bl(r.x, r.y + r.height);
      const std::pair<cv::Point, cv::Point> edges[4] = {{tl, tr}, {tr, br}, {br, bl}, {bl, tl}};
      const cv::Point neighbour[4] = {{0, -1}, {1, 0}, {0, 1}, {-1, 0}};
      for (int e = 0; e < 4; ++e) {
        cv::Point nc = cell[f] + neighbour[e];
        bool shared = false;
        for (int g = 0; g < kNumFaces; ++g) shared |= (cell[g] == nc);
        if (shared) {
          dashed(edges[e].first, edges[e].second);
        } else {
          cv::line(net, edges[e].first, edges[e].second, cv::Scalar(0), thick);
        }
      }
    }
    std::string caption = absl::StrCat(m.name, "  ", m.dictionary, "  cube ", m.cube_size_m * 100, " cm  marker ",
                                       m.marker_size_m * 100, " cm  |");
    for (int f = 0; f < kNumFaces; ++f) {
      absl::StrAppend(&caption, " ", f, ":", ActionName(m.faces[f].action));
    }
    const double scale = face_px / 500.0;
    cv::putText(net, caption, cv::Point(margin, 3 * face_px + margin + caption_h / 2), cv::FONT_HERSHEY_SIMPLEX,
                scale, cv::Scalar(0), std::max(1, static_cast<int>(scale * 2)));
    cv::putText(net, "cut solid lines, fold dashed lines; print at 100% scale",
                cv::Point(margin, 3 * face_px + margin + caption_h * 9 / 10), cv::FONT_HERSHEY_SIMPLEX, scale,
                cv::Scalar(0), std::max(1, static_cast<int>(scale * 2)));
  } catch (const cv::Exception& e) {
    return absl::InternalError(absl::StrCat("RenderNet: OpenCV: ", e.what()));
  }
  return net;
}

}  // namespace kinemo::cube
