// Praat TextGrids: BEAT2's real word/phone alignments, Praat's short layout,
// UTF-16, and malformed files answered with the field that is wrong.
#include "common/audio/textgrid.h"

#include <gtest/gtest.h>

#include <string>

namespace kinemo::audio {
namespace {

std::string Beat2(const std::string& name) {
  return std::string(KINEMO_TEST_DATA_DIR) + "/paired/beat2/" + name;
}

TEST(TextGridTest, ReadsBeat2WordsAndPhones) {
  StatusOr<TextGrid> g = ReadTextGridFile(Beat2("2_scott_0_1_1.TextGrid"));
  ASSERT_TRUE(g.ok()) << g.status();
  EXPECT_DOUBLE_EQ(g->start_s, 0.0);
  EXPECT_NEAR(g->end_s, 64.097375, 1e-9);
  ASSERT_EQ(g->tiers.size(), 2u);
  const TextGridTier* words = g->FindTier("words");
  const TextGridTier* phones = g->FindTier("PHONES");
  ASSERT_NE(words, nullptr);
  ASSERT_NE(phones, nullptr);
  EXPECT_EQ(words->intervals.size(), 220u);
  // The opening words as the file has them: "" 0-1.42, "the", "first", "thing".
  EXPECT_EQ(words->intervals[0].text, "");
  EXPECT_EQ(words->intervals[1].text, "the");
  EXPECT_DOUBLE_EQ(words->intervals[1].start_s, 1.42);
  EXPECT_DOUBLE_EQ(words->intervals[1].end_s, 1.52);
  EXPECT_EQ(words->intervals[3].text, "thing");
  // Intervals tile the recording.
  for (const auto* tier : {words, phones}) {
    for (size_t i = 1; i < tier->intervals.size(); ++i)
      EXPECT_DOUBLE_EQ(tier->intervals[i].start_s, tier->intervals[i - 1].end_s) << tier->name << " " << i;
    EXPECT_NEAR(tier->intervals.back().end_s, g->end_s, 1e-9);
  }
  const auto spoken = NonEmptyIntervals(*words);
  EXPECT_LT(spoken.size(), words->intervals.size());
  EXPECT_GT(spoken.size(), 100u);
  // Phones are finer than words, and every word holds at least one phone.
  EXPECT_GT(NonEmptyIntervals(*phones).size(), spoken.size());
}

constexpr char kShort[] = R"(File type = "ooTextFile"
Object class = "TextGrid"

0
2.5
<exists>
2
"IntervalTier"
"words"
0
2.5
3
0
1
""
1
2
"say ""hi"""
2
2.5
""
"TextTier"
"beats"
0
2.5
2
0.5
"b1"
1.75
"b2"
)";

TEST(TextGridTest, ReadsShortLayoutPointTiersAndQuotes) {
  StatusOr<TextGrid> g = ParseTextGrid(kShort, "short.TextGrid");
  ASSERT_TRUE(g.ok()) << g.status();
  ASSERT_EQ(g->tiers.size(), 2u);
  EXPECT_EQ(g->tiers[0].intervals[1].text, "say \"hi\"");
  EXPECT_FALSE(g->tiers[1].is_interval);
  ASSERT_EQ(g->tiers[1].points.size(), 2u);
  EXPECT_DOUBLE_EQ(g->tiers[1].points[1].time_s, 1.75);
  EXPECT_EQ(g->tiers[1].points[1].mark, "b2");
}

TEST(TextGridTest, ReadsUtf16WithByteOrderMark) {
  const std::string utf8 = kShort;
  std::string utf16 = "\xFF\xFE";
  for (char c : utf8) {
    utf16 += c;
    utf16 += '\0';
  }
  StatusOr<TextGrid> g = ParseTextGrid(utf16, "utf16.TextGrid");
  ASSERT_TRUE(g.ok()) << g.status();
  EXPECT_EQ(g->tiers[0].intervals[1].text, "say \"hi\"");
}

TEST(TextGridTest, MalformedFilesNameTheField) {
  struct Case {
    std::string text, expect;
  };
  const std::string head = "File type = \"ooTextFile\"\nObject class = \"TextGrid\"\n";
  const Case cases[] = {
      {"File type = \"binary\"\n", "File type"},
      {head + "0 1 <exists> 1 \"IntervalTier\" \"words\" 0 1 2 0 0.5 \"a\"", "words.intervals[2].xmin: the file ends early"},
      {head + "0 1 <exists> 1 \"IntervalTier\" \"words\" 0 1 1 0.5 0.2 \"a\"", "words.intervals[1].xmax"},
      {head + "0 1 <exists> 1000000000 \"IntervalTier\"", "size"},
      {head + "0 1 <exists> 1 \"Spline\" \"x\" 0 1 0", "item[1].class"},
      {head + "0 1 <exists> 1 \"IntervalTier\" \"words\" 0 1 1 0 1e999 \"a\"", "not a finite number"},
      {head + "0 1 <exists> 1 \"IntervalTier\" \"words\" 0 1 1 0 1 \"unterminated", "unterminated string"},
  };
  for (const Case& c : cases) {
    StatusOr<TextGrid> g = ParseTextGrid(c.text, "bad.TextGrid");
    ASSERT_FALSE(g.ok()) << c.text;
    EXPECT_EQ(g.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(std::string(g.status().message()).find(c.expect), std::string::npos) << g.status();
    EXPECT_NE(std::string(g.status().message()).find("bad.TextGrid"), std::string::npos) << g.status();
  }
  EXPECT_EQ(ReadTextGridFile("/nonexistent/x.TextGrid").status().code(), absl::StatusCode::kNotFound);
}

}  // namespace
}  // namespace kinemo::audio
