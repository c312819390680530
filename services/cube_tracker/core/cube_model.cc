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

// ---- A small reader for the text-proto subset a cube model needs ----------
struct Token {
  enum Kind { kIdent, kNumber, kString, kColon, kOpen, kClose, kEnd } kind;
  std::string text;
  int line;
};

class Lexer {
 public:
  explicit Lexer(std::string_view text) : text_(text) {}
  StatusOr<Token> Next(const std::string& source) {
    while (pos_ < text_.size()) {
      char c = text_[pos_];
      if (c == '\n') {
        ++line_;
        ++pos_;
      } else if (std::isspace(static_cast<unsigned char>(c)) || c == ',' || c == ';') {
        ++pos_;
      } else if (c == '#') {
        while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
      } else {
        break;
      }
    }
    if (pos_ >= text_.size()) return Token{Token::kEnd, "", line_};
    char c = text_[pos_];
    if (c == ':') return Single(Token::kColon);
    if (c == '{' || c == '<') return Single(Token::kOpen);
    if (c == '}' || c == '>') return Single(Token::kClose);
    if (c == '"' || c == '\'') {
      size_t end = text_.find(c, pos_ + 1);
      if (end == std::string_view::npos) {
        return absl::InvalidArgumentError(absl::StrCat(source, ":", line_, ": unterminated string"));
      }
      Token t{Token::kString, std::string(text_.substr(pos_ + 1, end - pos_ - 1)), line_};
      pos_ = end + 1;
      return t;
    }
    if (std::isdigit(static_cast<unsigned char>(c)) || c == '-' || c == '+' || c == '.') {
      size_t start = pos_;
      while (pos_ < text_.size() && (std::isalnum(static_cast<unsigned char>(text_[pos_])) ||
                                     text_[pos_] == '.' || text_[pos_] == '-' || text_[pos_] == '+')) {
        ++pos_;
      }
      return Token{Token::kNumber, std::string(text_.substr(start, pos_ - start)), line_};
    }
    if (std::isalpha(static_cast<unsigned char>(c)) || c == '_') {
      size_t start = pos_;
      while (pos_ < text_.size() &&
             (std::isalnum(static_cast<unsigned char>(text_[pos_])) || text_[pos_] == '_')) {
        ++pos_;
      }
      return Token{Token::kIdent, std::string(text_.substr(start, pos_ - start)), line_};
    }
    return absl::InvalidArgumentError(
        absl::StrCat(source, ":", line_, ": unexpected character '", std::string(1, c), "'"));
  }

 private:
  Token Single(Token::Kind k) { return Token{k, std::string(1, text_[pos_++]), line_}; }
  std::string_view text_;
  size_t pos_ = 0;
  int line_ = 1;
};

StatusOr<double> ToDouble(const Token& t, const std::string& source) {
  double v = 0;
  auto [p, ec] = std::from_chars(t.text.data(), t.text.data() + t.text.size(), v);
  if (ec != std::errc() || p != t.text.data() + t.text.size()) {
    return absl::InvalidArgumentError(absl::StrCat(source, ":", t.line, ": '", t.text, "' is not a number"));
  }
  return v;
}

StatusOr<int> ToInt(const Token& t, const std::string& source) {
  int v = 0;
  auto [p, ec] = std::from_chars(t.text.data(), t.text.data() + t.text.size(), v);
  if (ec != std::errc() || p != t.text.data() + t.text.size()) {
    return absl::InvalidArgumentError(absl::StrCat(source, ":", t.line, ": '", t.text, "' is not an integer"));
  }
  return v;
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

StatusOr<Action> ParseAction(const std::string& text) {
  std::string t;
  for (char c : text) t.push_back(static_cast<char>(std::tolower(static_cast<unsigned char>(c))));
  if (t.rfind("action_", 0) == 0) t = t.substr(7);
  if (t == "idle") return Action::kIdle;
  if (t == "throwing_kisses" || t == "kisses") return Action::kThrowingKisses;
  if (t == "shouting" || t == "shout") return Action::kShouting;
  return InvalidField("action", "'", text, "' is not one of idle, throwing_kisses, shouting");
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

StatusOr<CubeModel> ParseCubeModel(std::string_view text, const std::string& source) {
  CubeModel m;
  for (auto& f : m.faces) f = FaceSpec{};
  std::set<int> seen_faces;
  Lexer lex(text);
  auto expect = [&](Token::Kind k, const char* what) -> StatusOr<Token> {
    KINEMO_ASSIGN_OR_RETURN(Token t, lex.Next(source));
    if (t.kind != k) {
      return absl::InvalidArgumentError(
          absl::StrCat(source, ":", t.line, ": expected ", what, ", got '", t.text, "'"));
    }
    return t;
  };
  while (true) {
    KINEMO_ASSIGN_OR_RETURN(Token key, lex.Next(source));
    if (key.kind == Token::kEnd) break;
    if (key.kind != Token::kIdent) {
      return absl::InvalidArgumentError(absl::StrCat(source, ":", key.line, ": expected a field name, got '",
                                                     key.text, "'"));
    }
    if (key.text == "face") {
      KINEMO_ASSIGN_OR_RETURN(Token t, lex.Next(source));
      if (t.kind == Token::kColon) {
        KINEMO_ASSIGN_OR_RETURN(t, lex.Next(source));
      }
      if (t.kind != Token::kOpen) {
        return absl::InvalidArgumentError(absl::StrCat(source, ":", t.line, ": expected '{' after face"));
      }
      int index = -1;
      FaceSpec spec;
      while (true) {
        KINEMO_ASSIGN_OR_RETURN(Token k, lex.Next(source));
        if (k.kind == Token::kClose) break;
        if (k.kind != Token::kIdent) {
          return absl::InvalidArgumentError(
              absl::StrCat(source, ":", k.line, ": expected a face field or '}', got '", k.text, "'"));
        }
        KINEMO_RETURN_IF_ERROR(expect(Token::kColon, "':'").status());
        KINEMO_ASSIGN_OR_RETURN(Token v, lex.Next(source));
        if (k.text == "index") {
          KINEMO_ASSIGN_OR_RETURN(index, ToInt(v, source));
        } else if (k.text == "marker_id") {
          KINEMO_ASSIGN_OR_RETURN(spec.marker_id, ToInt(v, source));
        } else if (k.text == "action") {
          auto a = ParseAction(v.text);
          if (!a.ok()) return Annotate(a.status(), absl::StrCat(source, ":", v.line));
          spec.action = *a;
        } else {
          return absl::InvalidArgumentError(absl::StrCat(source, ":", k.line, ": unknown face field '", k.text, "'"));
        }
      }
      if (index < 0 || index >= kNumFaces) {
        return absl::InvalidArgumentError(absl::StrCat(source, ": face.index ", index, " is not in 0..5"));
      }
      if (!seen_faces.insert(index).second) {
        return absl::InvalidArgumentError(absl::StrCat(source, ": face ", index, " is given twice"));
      }
      m.faces[index] = spec;
      continue;
    }
    KINEMO_RETURN_IF_ERROR(expect(Token::kColon, "':'").status());
    KINEMO_ASSIGN_OR_RETURN(Token v, lex.Next(source));
    if (key.text == "name") {
      m.name = v.text;
    } else if (key.text == "dictionary") {
      m.dictionary = v.text;
    } else if (key.text == "cube_size_m") {
      KINEMO_ASSIGN_OR_RETURN(m.cube_size_m, ToDouble(v, source));
    } else if (key.text == "marker_size_m") {
      KINEMO_ASSIGN_OR_RETURN(m.marker_size_m, ToDouble(v, source));
    } else {
      return absl::InvalidArgumentError(absl::StrCat(source, ":", key.line, ": unknown field '", key.text, "'"));
    }
  }
  if (seen_faces.size() != kNumFaces) {
    return absl::InvalidArgumentError(
        absl::StrCat(source, ": face: ", seen_faces.size(), " faces given, the cube needs all 6"));
  }
  Status s = ValidateCubeModel(m);
  if (!s.ok()) return Annotate(s, source);
  return m;
}

StatusOr<CubeModel> LoadCubeModel(const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open cube model"));
  std::stringstream ss;
  ss << in.rdbuf();
  return ParseCubeModel(ss.str(), path);
}

std::string FormatCubeModel(const CubeModel& m) {
  std::string out = absl::StrFormat(
      "# kinemo cube model (faces: 0 +Z, 1 -Z, 2 +X, 3 -X, 4 +Y, 5 -Y)\n"
      "name: \"%s\"\ndictionary: \"%s\"\ncube_size_m: %.6g\nmarker_size_m: %.6g\n",
      m.name, m.dictionary, m.cube_size_m, m.marker_size_m);
  for (int f = 0; f < kNumFaces; ++f) {
    std::string action(ActionName(m.faces[f].action));
    for (char& c : action) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    absl::StrAppendFormat(&out, "face { index: %d marker_id: %d action: ACTION_%s }\n", f, m.faces[f].marker_id,
                          action);
  }
  return out;
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
