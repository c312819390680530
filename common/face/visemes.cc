#include "common/face/visemes.h"

#include <cctype>
#include <string>

namespace kinemo::face {
namespace {

struct PhoneEntry {
  const char* phone;
  PhoneClass cls;
};

constexpr PhoneEntry kPhones[] = {
    {"SIL", PhoneClass::kSil}, {"SP", PhoneClass::kSil},  {"SPN", PhoneClass::kSil}, {"PAU", PhoneClass::kSil},
    {"R", PhoneClass::kR},     {"K", PhoneClass::kKG},    {"G", PhoneClass::kKG},    {"NG", PhoneClass::kKG},
    {"AE", PhoneClass::kAA},   {"AX", PhoneClass::kAA},   {"AH", PhoneClass::kAA},   {"AA", PhoneClass::kAA},
    {"F", PhoneClass::kFV},    {"V", PhoneClass::kFV},    {"CH", PhoneClass::kCH},   {"SH", PhoneClass::kCH},
    {"JH", PhoneClass::kCH},   {"AO", PhoneClass::kAO},   {"AY", PhoneClass::kAO},   {"AW", PhoneClass::kAO},
    {"IY", PhoneClass::kIY},   {"IH", PhoneClass::kIY},   {"Y", PhoneClass::kIY},    {"IX", PhoneClass::kIY},
    {"OW", PhoneClass::kOW},   {"OY", PhoneClass::kOW},   {"N", PhoneClass::kNL},    {"L", PhoneClass::kNL},
    {"NX", PhoneClass::kNL},   {"D", PhoneClass::kDT},    {"T", PhoneClass::kDT},    {"DX", PhoneClass::kDT},
    {"EY", PhoneClass::kEY},   {"EH", PhoneClass::kEY},   {"EL", PhoneClass::kEY},   {"EM", PhoneClass::kEY},
    {"EN", PhoneClass::kEY},   {"ER", PhoneClass::kER},   {"AXR", PhoneClass::kER},  {"TH", PhoneClass::kTH},
    {"DH", PhoneClass::kTH},   {"S", PhoneClass::kSZ},    {"Z", PhoneClass::kSZ},    {"ZH", PhoneClass::kSZ},
    {"B", PhoneClass::kBPM},   {"P", PhoneClass::kBPM},   {"M", PhoneClass::kBPM},   {"HH", PhoneClass::kHH},
    {"W", PhoneClass::kWUW},   {"UW", PhoneClass::kWUW},  {"UH", PhoneClass::kWUW},  {"UX", PhoneClass::kWUW},
};

}  // namespace

bool PhoneToClass(std::string_view phone, PhoneClass* out) {
  *out = PhoneClass::kSil;
  std::string p;
  for (char c : phone) {
    if (std::isdigit(static_cast<unsigned char>(c)) || std::isspace(static_cast<unsigned char>(c))) continue;
    p.push_back(static_cast<char>(std::toupper(static_cast<unsigned char>(c))));
  }
  if (p.empty() || p.front() == '+' || p.front() == '<' || p.front() == '[') return true;  // silence, fillers
  for (const PhoneEntry& e : kPhones) {
    if (p == e.phone) {
      *out = e.cls;
      return true;
    }
  }
  return false;
}

void ClassesToCategories(const std::array<float, kNumPhoneClasses>& classes,
                         std::array<float, kNumCategories>* categories) {
  categories->fill(0);
  for (int c = 0; c < kNumPhoneClasses; ++c) (*categories)[static_cast<int>(kClassCategory[c])] += classes[c];
}

void ClassesToOvr(const std::array<float, kNumPhoneClasses>& classes, std::array<float, kNumOvrVisemes>* ovr) {
  ovr->fill(0);
  for (int c = 0; c < kNumPhoneClasses; ++c) (*ovr)[static_cast<int>(kClassOvr[c])] += classes[c];
}

void CategoriesToOvr(const std::array<float, kNumCategories>& categories, std::array<float, kNumOvrVisemes>* ovr) {
  ovr->fill(0);
  auto add = [&](OvrViseme v, float w) { (*ovr)[static_cast<int>(v)] += w; };
  auto cat = [&](Category c) { return categories[static_cast<int>(c)]; };
  add(OvrViseme::kSil, cat(Category::kPau));
  add(OvrViseme::kRR, cat(Category::kR));
  add(OvrViseme::kKK, cat(Category::kKGNg));
  add(OvrViseme::kAA, cat(Category::kAa) + cat(Category::kHh));
  add(OvrViseme::kFF, cat(Category::kFV));
  add(OvrViseme::kCH, cat(Category::kChShJh));
  add(OvrViseme::kIH, 0.7f * cat(Category::kAo));
  add(OvrViseme::kOH, 0.3f * cat(Category::kAo) + cat(Category::kOw));
  add(OvrViseme::kNN, 0.5f * cat(Category::kNDTL));
  add(OvrViseme::kDD, 0.5f * cat(Category::kNDTL));
  add(OvrViseme::kE, cat(Category::kEy));
  add(OvrViseme::kTH, cat(Category::kThDh));
  add(OvrViseme::kSS, cat(Category::kSZZh));
  add(OvrViseme::kPP, cat(Category::kBPM));
  add(OvrViseme::kOU, cat(Category::kWUw));
}

}  // namespace kinemo::face
