// Mouth-shape classes shared by the face model, its training and evaluation
// and the viseme files: the 18 phone classes the face model predicts (the
// common refinement of the thesis's 15 categories, Table 4.5, and the 15 OVR /
// OpenXR visemes), ARPAbet phones -> class, and class -> category / OVR
// viseme. Plain C++, no dependencies.
//
// Classes (ARPAbet, stress digits ignored):
//   sil: silence, pauses, fillers, noise     r: r
//   k g ng                                   aa: ae ax ah aa
//   f v                                      ch: ch sh jh
//   ao: ao ay aw                             iy: iy ih y ix
//   ow: ow oy                                nl: n l nx
//   dt: d t dx                               ey: ey eh el em en
//   er: er axr                               th: th dh
//   sz: s z zh                               bpm: b p m
//   hh: hh                                   wuw: w uw uh ux
// Each class lies inside one thesis category (ao and iy both in AO; nl and dt
// in N_D_T_L; ey and er in EY) and inside one OVR viseme (ao and ow both in
// oh; er with r in RR), except three rare phones put with their neighbours:
// zh (OVR CH) in sz, el / en (OVR nn) and em (OVR PP) in ey. hh has no OVR
// viseme of its own: it takes the open `aa` (a breathy vowel onset).
#pragma once

#include <array>
#include <string_view>

#include "common/face/face_frame.h"

namespace kinemo::face {

enum class PhoneClass {
  kSil, kR, kKG, kAA, kFV, kCH, kAO, kIY, kOW, kNL, kDT, kEY, kER, kTH, kSZ, kBPM, kHH, kWUW
};
inline constexpr int kNumPhoneClasses = 18;
inline constexpr std::array<std::string_view, kNumPhoneClasses> kPhoneClassNames = {
    "sil", "r", "kg", "aa", "fv", "ch", "ao", "iy", "ow", "nl", "dt", "ey", "er", "th", "sz", "bpm", "hh", "wuw"};

// The thesis's categories (Table 4.5), in kinemo.planner.v1.VisemeCategory
// order minus 1 (FaceFrame::categories).
enum class Category {
  kPau, kR, kKGNg, kAa, kFV, kChShJh, kAo, kOw, kNDTL, kEy, kThDh, kSZZh, kBPM, kHh, kWUw
};
inline constexpr std::array<std::string_view, kNumCategories> kCategoryNames = {
    "PAU", "R", "K_G_NG", "AA", "F_V", "CH_SH_JH", "AO", "OW", "N_D_T_L", "EY", "TH_DH", "S_Z_ZH", "B_P_M", "HH",
    "W_UW"};

// Class -> thesis category.
inline constexpr std::array<Category, kNumPhoneClasses> kClassCategory = {
    Category::kPau, Category::kR,    Category::kKGNg, Category::kAa,   Category::kFV,   Category::kChShJh,
    Category::kAo,  Category::kAo,   Category::kOw,   Category::kNDTL, Category::kNDTL, Category::kEy,
    Category::kEy,  Category::kThDh, Category::kSZZh, Category::kBPM,  Category::kHh,   Category::kWUw};

// Class -> OVR viseme.
inline constexpr std::array<OvrViseme, kNumPhoneClasses> kClassOvr = {
    OvrViseme::kSil, OvrViseme::kRR, OvrViseme::kKK, OvrViseme::kAA, OvrViseme::kFF, OvrViseme::kCH,
    OvrViseme::kOH,  OvrViseme::kIH, OvrViseme::kOH, OvrViseme::kNN, OvrViseme::kDD, OvrViseme::kE,
    OvrViseme::kRR,  OvrViseme::kTH, OvrViseme::kSS, OvrViseme::kPP, OvrViseme::kAA, OvrViseme::kOU};

// ARPAbet phone (any case, stress digits ignored; Sphinx's SIL, fillers such
// as +NSN+ and <sil>, and "" count as silence) -> class. False for a phone
// not in the table (then *out = kSil).
bool PhoneToClass(std::string_view phone, PhoneClass* out);

// Class posteriors -> category weights and OVR weights (sums of the classes
// inside each).
void ClassesToCategories(const std::array<float, kNumPhoneClasses>& classes,
                         std::array<float, kNumCategories>* categories);
void ClassesToOvr(const std::array<float, kNumPhoneClasses>& classes, std::array<float, kNumOvrVisemes>* ovr);

// OVR weights from category weights alone (viseme files written before the
// face track carried OVR weights): each category's weight goes to the OVR
// visemes of its phones, split by how often English speech uses them
// (AO: ih 0.7, oh 0.3; N_D_T_L: nn 0.5, DD 0.5; HH: aa; others one to one).
void CategoriesToOvr(const std::array<float, kNumCategories>& categories, std::array<float, kNumOvrVisemes>* ovr);

// The dominant entry (the first of equal maxima).
template <typename Array>
int Dominant(const Array& weights) {
  int best = 0;
  for (int i = 1; i < static_cast<int>(weights.size()); ++i) {
    if (weights[i] > weights[best]) best = i;
  }
  return best;
}

}  // namespace kinemo::face
