// Praat TextGrid files: word and phone alignments of a recording (BEAT2,
// Montreal Forced Aligner and Praat itself write them).
//
// Both of Praat's text layouts are read: the long one ("ooTextFile" with
// `xmin = 0` labels, `item [1]:` headers) and the short one (values only).
// Like Praat, the reader takes the values in order and skips the labels:
// numbers, "quoted strings" ("" is a quote inside one) and <flags>.
// UTF-8 (with or without a byte-order mark) and UTF-16 with a byte-order mark
// are accepted. Interval tiers and point tiers ("TextTier") are kept.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "common/status/status.h"

namespace kinemo::audio {

struct TextGridInterval {
  double start_s = 0;
  double end_s = 0;
  std::string text;  // "" for silence
};

struct TextGridPoint {
  double time_s = 0;
  std::string mark;
};

struct TextGridTier {
  std::string name;
  bool is_interval = true;                  // IntervalTier, else TextTier (points)
  std::vector<TextGridInterval> intervals;  // IntervalTier: contiguous, ascending
  std::vector<TextGridPoint> points;        // TextTier: ascending
};

struct TextGrid {
  double start_s = 0;
  double end_s = 0;
  std::vector<TextGridTier> tiers;

  // The first tier with this name (case-insensitive), or nullptr.
  const TextGridTier* FindTier(std::string_view name) const;
};

// Limits on untrusted files.
inline constexpr size_t kMaxTextGridBytes = 64u << 20;

// Parses a TextGrid; errors name `source_name` and the tier/interval
// (`words.intervals[3].xmax: 1.2 is before xmin 1.5`).
StatusOr<TextGrid> ParseTextGrid(std::string_view bytes, std::string_view source_name);
StatusOr<TextGrid> ReadTextGridFile(const std::string& path);

// The non-empty intervals of an interval tier (words or phones without the
// silences), trimmed of surrounding white space.
std::vector<TextGridInterval> NonEmptyIntervals(const TextGridTier& tier);

}  // namespace kinemo::audio
