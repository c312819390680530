// The viseme file: every channel round-trips; the layout written before the
// face track (categories and weights only) still reads; malformed files are
// refused naming the file and the member.
#include "common/face/face_json.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "common/face/visemes.h"

namespace kinemo::face {
namespace {

FaceTrack SampleTrack() {
  FaceTrack t;
  t.frame_time_s = 1.0 / 30.0;
  for (int i = 0; i < 3; ++i) {
    FaceFrame f;
    f.time_s = i * t.frame_time_s;
    f.categories[static_cast<int>(Category::kBPM)] = 0.75f;
    f.categories[static_cast<int>(Category::kAa)] = 0.25f;
    f.ovr[static_cast<int>(OvrViseme::kPP)] = 0.75f;
    f.ovr[static_cast<int>(OvrViseme::kAA)] = 0.25f;
    f.jaw_open_deg = 1.5f + static_cast<float>(i);
    f.blink_left = 0.5f;
    f.blink_right = 0.25f;
    f.brow_raise = 0.125f;
    f.expression = Expression::kHappy;
    f.expression_weight = 0.5f;
    f.emphasis = -0.5f;
    t.frames.push_back(f);
  }
  return t;
}

TEST(FaceJson, EveryChannelRoundTrips) {
  const FaceTrack t = SampleTrack();
  const std::string text = FaceTrackToJson(t);
  const nlohmann::json j = nlohmann::json::parse(text);
  EXPECT_EQ(j["categories"][0], "VISEME_CATEGORY_PAU");
  EXPECT_EQ(j["ovr_visemes"][1], "PP");
  EXPECT_DOUBLE_EQ(j["frames"][0]["blink"].get<double>(), 0.375);  // both eyes' mean
  EXPECT_EQ(j["frames"][2]["expression"], "happy");
  auto back = FaceTrackFromJson(text, "V.json");
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->frames.size(), 3u);
  EXPECT_NEAR(back->frame_time_s, t.frame_time_s, 1e-12);
  for (std::size_t i = 0; i < 3; ++i) {
    const FaceFrame& a = t.frames[i];
    const FaceFrame& b = back->frames[i];
    EXPECT_NEAR(b.time_s, a.time_s, 1e-4);
    EXPECT_EQ(b.categories, a.categories);
    EXPECT_EQ(b.ovr, a.ovr);
    EXPECT_FLOAT_EQ(b.jaw_open_deg, a.jaw_open_deg);
    EXPECT_TRUE(b.jaw_known);
    EXPECT_FLOAT_EQ(b.blink_left, 0.5f);
    EXPECT_FLOAT_EQ(b.blink_right, 0.25f);
    EXPECT_FLOAT_EQ(b.brow_raise, a.brow_raise);
    EXPECT_EQ(b.expression, Expression::kHappy);
    EXPECT_FLOAT_EQ(b.expression_weight, 0.5f);
    EXPECT_FLOAT_EQ(b.emphasis, -0.5f);
  }
}

TEST(FaceJson, ReadsTheLayoutBeforeTheFaceTrack) {
  // As `kinemo animate --visemes` wrote it before: categories (either
  // spelling, any order) and weights; no OVR, jaw, blinks or expression.
  const std::string old = R"({"frame_time_s": 0.04,
    "categories": ["B_P_M", "PAU", "R", "K_G_NG", "AA", "F_V", "CH_SH_JH", "AO", "OW", "N_D_T_L", "EY",
                   "TH_DH", "S_Z_ZH", "HH", "W_UW"],
    "frames": [{"time_s": 0, "weights": [1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]},
               {"time_s": 0.04, "weights": [0, 0, 0, 0, 0, 0, 0, 0.5, 0, 0.5, 0, 0, 0, 0, 0], "emphasis": 1}]})";
  auto t = FaceTrackFromJson(old, "old.json");
  ASSERT_TRUE(t.ok()) << t.status();
  ASSERT_EQ(t->frames.size(), 2u);
  EXPECT_FLOAT_EQ(t->frames[0].categories[static_cast<int>(Category::kBPM)], 1.0f);
  EXPECT_FLOAT_EQ(t->frames[0].ovr[static_cast<int>(OvrViseme::kPP)], 1.0f);  // from the categories
  EXPECT_FLOAT_EQ(t->frames[1].categories[static_cast<int>(Category::kAo)], 0.5f);
  EXPECT_FLOAT_EQ(t->frames[1].ovr[static_cast<int>(OvrViseme::kIH)], 0.35f);
  EXPECT_FLOAT_EQ(t->frames[1].ovr[static_cast<int>(OvrViseme::kNN)], 0.25f);
  EXPECT_FLOAT_EQ(t->frames[1].emphasis, 1.0f);
  EXPECT_EQ(t->frames[1].jaw_open_deg, 0.0f);
  EXPECT_FALSE(t->frames[1].jaw_known);  // a rig draws its vowels at their weights
  EXPECT_EQ(t->frames[1].expression, Expression::kNeutral);
}

// The text of SampleTrack() with one member replaced.
std::string With(const std::string& path, const nlohmann::json& value) {
  nlohmann::json j = nlohmann::json::parse(FaceTrackToJson(SampleTrack()));
  j[nlohmann::json::json_pointer(path)] = value;
  return j.dump();
}

TEST(FaceJson, RefusesMalformedFilesNamingTheMember) {
  struct Case {
    std::string text, message;
  };
  const std::vector<Case> cases = {
      {"{", "V.json: not valid JSON"},
      {"[]", "V.json: must be a JSON object"},
      {With("/frame_time_s", 0), "V.json: frame_time_s: must be in (0, 1]"},
      {With("/frames/1/ovr/2", 1.5), "V.json: frames[1].ovr[2]: must be in [0, 1], got 1.5"},
      {With("/frames/0/weights", nlohmann::json::array({1, 0})), "V.json: frames[0].weights: must be a list of 15"},
      {With("/frames/2/jaw_deg", 400), "V.json: frames[2].jaw_deg: must be in [-90, 90]"},
      {With("/frames/2/jaw_deg", "wide"), "V.json: frames[2].jaw_deg: must be a finite number"},
      {With("/frames/1/blink_left", -0.1), "V.json: frames[1].blink_left: must be in [0, 1]"},
      {With("/frames/1/emphasis", 2), "V.json: frames[1].emphasis: must be in [-1, 1]"},
      {With("/frames/1/expression", "joyful"), "V.json: frames[1].expression: must be one of"},
      {With("/frames/2/time_s", 0.01), "V.json: frames[2].time_s: 0.01 is before the previous frame's"},
      {With("/categories/3", "SMILE"), "V.json: categories[3]: 'SMILE' is not one of the names"},
      {With("/ovr_visemes/4", "PP"), "V.json: ovr_visemes[4]: 'PP' appears twice"},
  };
  for (const Case& c : cases) {
    auto t = FaceTrackFromJson(c.text, "V.json");
    ASSERT_FALSE(t.ok()) << c.message;
    EXPECT_EQ(t.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_EQ(std::string(t.status().message()).rfind(c.message, 0), 0u) << t.status().message();
  }
}

TEST(FaceClasses, PhonesMapIntoOneCategoryAndOneOvrViseme) {
  PhoneClass c;
  ASSERT_TRUE(PhoneToClass("ah0", &c));
  EXPECT_EQ(c, PhoneClass::kAA);
  ASSERT_TRUE(PhoneToClass("M", &c));
  EXPECT_EQ(kClassCategory[static_cast<int>(c)], Category::kBPM);
  EXPECT_EQ(kClassOvr[static_cast<int>(c)], OvrViseme::kPP);
  ASSERT_TRUE(PhoneToClass("", &c));
  EXPECT_EQ(c, PhoneClass::kSil);
  ASSERT_TRUE(PhoneToClass("+NSN+", &c));
  EXPECT_EQ(c, PhoneClass::kSil);
  EXPECT_FALSE(PhoneToClass("XYZ", &c));
  std::array<float, kNumPhoneClasses> p{};
  p[static_cast<int>(PhoneClass::kAO)] = 0.25f;
  p[static_cast<int>(PhoneClass::kOW)] = 0.5f;
  p[static_cast<int>(PhoneClass::kIY)] = 0.25f;
  std::array<float, kNumCategories> cats;
  std::array<float, kNumOvrVisemes> ovr;
  ClassesToCategories(p, &cats);
  ClassesToOvr(p, &ovr);
  EXPECT_FLOAT_EQ(cats[static_cast<int>(Category::kAo)], 0.5f);
  EXPECT_FLOAT_EQ(cats[static_cast<int>(Category::kOw)], 0.5f);
  EXPECT_FLOAT_EQ(ovr[static_cast<int>(OvrViseme::kOH)], 0.75f);
  EXPECT_FLOAT_EQ(ovr[static_cast<int>(OvrViseme::kIH)], 0.25f);
}

}  // namespace
}  // namespace kinemo::face
