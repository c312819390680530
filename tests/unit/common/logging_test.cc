#include "common/logging/log.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace kinemo::log {
namespace {

TEST(Logging, JsonLineIsValidJsonWithAllFields) {
  const std::string line =
      FormatLine(Level::kInfo, "listening",
                 {{"address", "127.0.0.1:4000"}, {"port", 4000}, {"tls", false}, {"ratio", 0.5}},
                 Format::kJson, "prosody", "2026-11-21T15:00:00.000Z");
  const auto j = nlohmann::json::parse(line);
  EXPECT_EQ(j["level"], "info");
  EXPECT_EQ(j["component"], "prosody");
  EXPECT_EQ(j["event"], "listening");
  EXPECT_EQ(j["address"], "127.0.0.1:4000");
  EXPECT_EQ(j["port"], 4000);
  EXPECT_EQ(j["tls"], false);
  EXPECT_DOUBLE_EQ(j["ratio"].get<double>(), 0.5);
  EXPECT_EQ(j["ts"], "2026-11-21T15:00:00.000Z");
}

TEST(Logging, HostileStringsAreEscaped) {
  const std::string nasty = "quote\" backslash\\ newline\n tab\t ctrl\x01 end";
  const std::string line =
      FormatLine(Level::kError, "bad\"event", {{"msg", nasty}}, Format::kJson, "x", "t");
  EXPECT_EQ(line.find('\n'), std::string::npos);
  const auto j = nlohmann::json::parse(line);
  EXPECT_EQ(j["msg"], nasty);
  EXPECT_EQ(j["event"], "bad\"event");
}

TEST(Logging, NonFiniteNumbersStayValidJson) {
  const std::string line = FormatLine(Level::kWarn, "e", {{"v", std::nan("")}}, Format::kJson, "x", "t");
  EXPECT_TRUE(nlohmann::json::parse(line)["v"].is_null());
}

TEST(Logging, TextFormatIsKeyValue) {
  const std::string line = FormatLine(Level::kWarn, "retry", {{"robot", "pleo-1"}, {"attempt", 2},
                                                              {"why", "timed out"}},
                                      Format::kText, "robot_bridge", "t");
  EXPECT_EQ(line, "t warn robot_bridge retry robot=pleo-1 attempt=2 why=\"timed out\"");
}

TEST(Logging, LevelsAndFormatsParse) {
  EXPECT_EQ(*ParseLevel("debug"), Level::kDebug);
  EXPECT_EQ(*ParseLevel(""), Level::kInfo);
  EXPECT_EQ(*ParseLevel("error"), Level::kError);
  const auto bad = ParseLevel("loud");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("server.log_level"), std::string::npos);
  EXPECT_EQ(*ParseFormat("text"), Format::kText);
  EXPECT_FALSE(ParseFormat("xml").ok());
}

}  // namespace
}  // namespace kinemo::log
