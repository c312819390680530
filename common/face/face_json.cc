#include "common/face/face_json.h"

#include <cmath>
#include <nlohmann/json.hpp>
#include <optional>

#include "common/face/visemes.h"
#include "common/json/json_fields.h"

namespace kinemo::face {
namespace {

constexpr std::string_view kCategoryPrefix = "VISEME_CATEGORY_";

double Round4(double v) { return std::round(v * 1e4) / 1e4; }

// `name` at `index` among `names`, or -1.
template <typename Names>
int IndexOf(const Names& names, std::string_view name) {
  for (int i = 0; i < static_cast<int>(names.size()); ++i) {
    if (names[i] == name) return i;
  }
  return -1;
}

// A list of the 15 names of `names` (each once, any order): out[i] = the
// index in `names` of the file's i-th column.
template <typename Names>
Status ReadColumns(const nlohmann::json& j, const char* key, const Names& names, bool strip_prefix,
                   std::array<int, 15>* out) {
  const auto it = j.find(key);
  if (it == j.end() || !it->is_array() || it->size() != names.size()) {
    return InvalidField(key, "must be a list of the ", names.size(), " names");
  }
  std::array<bool, 15> seen{};
  for (std::size_t i = 0; i < it->size(); ++i) {
    const nlohmann::json& v = (*it)[i];
    const std::string field = kinemo::StrCat(key, "[", i, "]");
    if (!v.is_string()) return InvalidField(field, "must be a name");
    std::string_view s = v.get_ref<const std::string&>();
    if (strip_prefix && s.substr(0, kCategoryPrefix.size()) == kCategoryPrefix) s.remove_prefix(kCategoryPrefix.size());
    const int k = IndexOf(names, s);
    if (k < 0) return InvalidField(field, "'", v.get_ref<const std::string&>(), "' is not one of the names");
    if (seen[k]) return InvalidField(field, "'", v.get_ref<const std::string&>(), "' appears twice");
    seen[k] = true;
    (*out)[i] = k;
  }
  return absl::OkStatus();
}

StatusOr<double> InRange(const nlohmann::json& f, const char* key, double fallback, const std::string& prefix,
                         double lo, double hi) {
  KINEMO_ASSIGN_OR_RETURN(const double v, JsonNumber(f, key, fallback, prefix));
  if (!(v >= lo && v <= hi)) return InvalidField(kinemo::StrCat(prefix, key), "must be in [", lo, ", ", hi, "], got ", v);
  return v;
}

// 15 weights in [0, 1], stored at out[columns[i]].
Status ReadWeights(const nlohmann::json& f, const char* key, const std::string& prefix,
                   const std::array<int, 15>& columns, std::array<float, 15>* out) {
  const auto it = f.find(key);
  const std::string field = kinemo::StrCat(prefix, key);
  if (it == f.end() || !it->is_array() || it->size() != 15) return InvalidField(field, "must be a list of 15 weights");
  for (std::size_t i = 0; i < 15; ++i) {
    const nlohmann::json& v = (*it)[i];
    if (!v.is_number() || !std::isfinite(v.get<double>())) {
      return InvalidField(kinemo::StrCat(field, "[", i, "]"), "must be a finite number, got ",
                          json_internal::Shown(v));
    }
    const double w = v.get<double>();
    if (!(w >= 0 && w <= 1)) return InvalidField(kinemo::StrCat(field, "[", i, "]"), "must be in [0, 1], got ", w);
    (*out)[columns[i]] = static_cast<float>(w);
  }
  return absl::OkStatus();
}

StatusOr<FaceTrack> Parse(std::string_view text) {
  nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) return absl::InvalidArgumentError("not valid JSON");
  if (!j.is_object()) return absl::InvalidArgumentError("must be a JSON object");
  FaceTrack track;
  KINEMO_ASSIGN_OR_RETURN(track.frame_time_s, JsonNumber(j, "frame_time_s", std::nullopt, ""));
  if (!(track.frame_time_s > 0 && track.frame_time_s <= 1)) {
    return InvalidField("frame_time_s", "must be in (0, 1] s, got ", track.frame_time_s);
  }
  std::array<int, 15> cat_columns{}, ovr_columns{};
  KINEMO_RETURN_IF_ERROR(ReadColumns(j, "categories", kCategoryNames, true, &cat_columns));
  const bool has_ovr = j.contains("ovr_visemes");
  if (has_ovr) KINEMO_RETURN_IF_ERROR(ReadColumns(j, "ovr_visemes", kOvrVisemeNames, false, &ovr_columns));
  const auto frames = j.find("frames");
  if (frames == j.end() || !frames->is_array()) return InvalidField("frames", "must be a list");
  if (frames->size() > kMaxFaceFrames) {
    return InvalidField("frames", frames->size(), " frames, more than ", kMaxFaceFrames);
  }
  track.frames.resize(frames->size());
  double last_t = 0;
  for (std::size_t i = 0; i < frames->size(); ++i) {
    const nlohmann::json& f = (*frames)[i];
    const std::string prefix = kinemo::StrCat("frames[", i, "].");
    if (!f.is_object()) return InvalidField(kinemo::StrCat("frames[", i, "]"), "must be an object");
    FaceFrame& out = track.frames[i];
    if (!f.contains("time_s")) return InvalidField(prefix + "time_s", "missing");
    KINEMO_ASSIGN_OR_RETURN(out.time_s, InRange(f, "time_s", 0, prefix, 0, kMaxFaceTrackS));
    if (out.time_s < last_t) return InvalidField(prefix + "time_s", out.time_s, " is before the previous frame's ", last_t);
    last_t = out.time_s;
    if (!f.contains("weights")) return InvalidField(prefix + "weights", "missing");
    KINEMO_RETURN_IF_ERROR(ReadWeights(f, "weights", prefix, cat_columns, &out.categories));
    if (has_ovr && f.contains("ovr")) {
      KINEMO_RETURN_IF_ERROR(ReadWeights(f, "ovr", prefix, ovr_columns, &out.ovr));
    } else if (f.contains("ovr")) {
      return InvalidField(prefix + "ovr", "needs the file's ovr_visemes");
    } else {
      CategoriesToOvr(out.categories, &out.ovr);
    }
    KINEMO_ASSIGN_OR_RETURN(const double emphasis, InRange(f, "emphasis", 0, prefix, -1, 1));
    KINEMO_ASSIGN_OR_RETURN(const double jaw, InRange(f, "jaw_deg", 0, prefix, -kMaxJawDeg, kMaxJawDeg));
    KINEMO_ASSIGN_OR_RETURN(const double blink, InRange(f, "blink", 0, prefix, 0, 1));
    KINEMO_ASSIGN_OR_RETURN(const double left, InRange(f, "blink_left", blink, prefix, 0, 1));
    KINEMO_ASSIGN_OR_RETURN(const double right, InRange(f, "blink_right", blink, prefix, 0, 1));
    KINEMO_ASSIGN_OR_RETURN(const double brow, InRange(f, "brow", 0, prefix, 0, 1));
    KINEMO_ASSIGN_OR_RETURN(const double weight, InRange(f, "expression_weight", 0, prefix, 0, 1));
    out.emphasis = static_cast<float>(emphasis);
    out.jaw_open_deg = static_cast<float>(jaw);
    out.jaw_known = f.contains("jaw_deg");
    out.blink_left = static_cast<float>(left);
    out.blink_right = static_cast<float>(right);
    out.brow_raise = static_cast<float>(brow);
    out.expression_weight = static_cast<float>(weight);
    if (const auto e = f.find("expression"); e != f.end()) {
      const int k = e->is_string() ? IndexOf(kExpressionNames, e->get_ref<const std::string&>()) : -1;
      if (k < 0) {
        return InvalidField(prefix + "expression", "must be one of neutral, happy, angry, sad, surprised, got ",
                            json_internal::Shown(*e));
      }
      out.expression = static_cast<Expression>(k);
    }
  }
  return track;
}

}  // namespace

std::string FaceTrackToJson(const FaceTrack& track) {
  nlohmann::json j;
  j["frame_time_s"] = track.frame_time_s;
  nlohmann::json cats = nlohmann::json::array();
  for (std::string_view c : kCategoryNames) cats.push_back(kinemo::StrCat(kCategoryPrefix, c));
  j["categories"] = std::move(cats);
  nlohmann::json ovr_names = nlohmann::json::array();
  for (std::string_view v : kOvrVisemeNames) ovr_names.push_back(std::string(v));
  j["ovr_visemes"] = std::move(ovr_names);
  nlohmann::json frames = nlohmann::json::array();
  for (const FaceFrame& f : track.frames) {
    nlohmann::json w = nlohmann::json::array(), ovr = nlohmann::json::array();
    for (float x : f.categories) w.push_back(Round4(x));
    for (float x : f.ovr) ovr.push_back(Round4(x));
    frames.push_back({{"time_s", Round4(f.time_s)},
                      {"weights", std::move(w)},
                      {"emphasis", Round4(f.emphasis)},
                      {"ovr", std::move(ovr)},
                      {"jaw_deg", Round4(f.jaw_open_deg)},
                      {"blink", Round4(0.5 * (f.blink_left + f.blink_right))},
                      {"blink_left", Round4(f.blink_left)},
                      {"blink_right", Round4(f.blink_right)},
                      {"brow", Round4(f.brow_raise)},
                      {"expression", std::string(kExpressionNames[static_cast<int>(f.expression)])},
                      {"expression_weight", Round4(f.expression_weight)}});
  }
  j["frames"] = std::move(frames);
  return j.dump();
}

StatusOr<FaceTrack> FaceTrackFromJson(std::string_view text, std::string_view name) {
  auto track = Parse(text);
  if (!track.ok()) return Annotate(track.status(), name);
  return track;
}

}  // namespace kinemo::face
