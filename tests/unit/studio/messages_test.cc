// Socket messages: the page's JSON -> kinemo.studio.v1.ClientMessage, and the
// errors that name the field at fault (services/studio/core/messages.h).
#include "services/studio/core/messages.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

namespace kinemo::studio {
namespace {

std::string ErrorOf(std::string_view text, std::uint32_t* id = nullptr) {
  auto decoded = DecodeClientMessage(text, id);
  EXPECT_FALSE(decoded.ok()) << text;
  if (decoded.ok()) return "";
  EXPECT_EQ(decoded.status().code(), absl::StatusCode::kInvalidArgument) << decoded.status();
  return std::string(decoded.status().message());
}

TEST(DecodeClientMessage, ReadsACallInCamelCaseOrSnakeCase) {
  auto act = DecodeClientMessage(
      R"({"id": 12, "act": {"sessionId": "s1", "action": "ACTION_KISSES", "intensity": 0.5}})");
  ASSERT_TRUE(act.ok()) << act.status();
  EXPECT_EQ(act->id(), 12u);
  ASSERT_TRUE(act->has_act());
  EXPECT_EQ(act->act().session_id(), "s1");
  EXPECT_EQ(act->act().action(), common::v1::ACTION_KISSES);
  EXPECT_DOUBLE_EQ(act->act().intensity(), 0.5);
  EXPECT_EQ(CallName(*act), "act");

  auto end = DecodeClientMessage(R"({"id": 3, "stream_end": {}})");
  ASSERT_TRUE(end.ok()) << end.status();
  EXPECT_TRUE(end->has_stream_end());
  EXPECT_EQ(CallName(*end), "stream_end");
}

TEST(DecodeClientMessage, ReadsAStreamChunkWithBase64Pcm) {
  auto chunk = DecodeClientMessage(R"({"id": 2, "stream": {"chunk": {"sequenceNumber": "7", "data": "AAEC"}}})");
  ASSERT_TRUE(chunk.ok()) << chunk.status();
  EXPECT_EQ(chunk->stream().chunk().sequence_number(), 7u);
  EXPECT_EQ(chunk->stream().chunk().data(), std::string("\x00\x01\x02", 3));
}

TEST(DecodeClientMessage, ErrorsNameTheField) {
  EXPECT_EQ(ErrorOf("not json").rfind("message: not valid JSON", 0), 0u);
  EXPECT_EQ(ErrorOf("[1, 2]").rfind("message: must be a JSON object", 0), 0u);
  EXPECT_EQ(ErrorOf(R"({"id": 1})").rfind("message: names no call", 0), 0u);
  EXPECT_EQ(ErrorOf(R"({"act": {}, "cancel": {}})").rfind("message: has two calls", 0), 0u);
  EXPECT_EQ(ErrorOf(R"({"dance": {}})").rfind("dance: not a call of the studio", 0), 0u);
  // A key that is no field name (found by studio_message_fuzz) is the message's fault.
  EXPECT_EQ(ErrorOf(R"({"id": 6, "": {"sessionId": "s0"}})").rfind("message: a key that is not a call", 0), 0u);
  EXPECT_EQ(ErrorOf(R"({"a&b, e": {}})").rfind("message: a key that is not a call", 0), 0u);
  EXPECT_EQ(ErrorOf(R"({"id": -1, "cancel": {}})").rfind("id: -1 is outside", 0), 0u);
  EXPECT_EQ(ErrorOf(R"({"id": 4294967296, "cancel": {}})").rfind("id: 4294967296 is outside", 0), 0u);
  EXPECT_EQ(ErrorOf(R"({"id": "one", "cancel": {}})").rfind("id: must be an integer", 0), 0u);
  EXPECT_EQ(ErrorOf(R"({"act": 5})").rfind("act: must be a JSON object", 0), 0u);
  std::uint32_t id = 0;
  const std::string bad_value = ErrorOf(R"({"id": 9, "act": {"intensity": "loud"}})", &id);
  EXPECT_EQ(bad_value.rfind("act.intensity: ", 0), 0u) << bad_value;
  EXPECT_EQ(id, 9u);  // known before the body failed, so the error names the call
  id = 0;
  EXPECT_EQ(ErrorOf(R"({"id": 10, "dance": {}})", &id).rfind("dance: ", 0), 0u);
  EXPECT_EQ(id, 10u);  // "dance" sorts before "id"; the id is still read first
  const std::string unknown = ErrorOf(R"({"act": {"volume": 1}})");
  EXPECT_EQ(unknown.rfind("act.volume: no such field", 0), 0u) << unknown;
  const std::string nested = ErrorOf(R"({"animate": {"audio": {"format": {"encoding": "LOUD"}}}})");
  EXPECT_EQ(nested.rfind("animate.audio.format.encoding", 0), 0u) << nested;
}

TEST(EncodeServerMessage, WritesTheJsonMappingWithTheId) {
  v1::ServerMessage m;
  m.set_id(5);
  m.mutable_act();
  const auto j = nlohmann::json::parse(EncodeServerMessage(m));
  EXPECT_EQ(j["id"], 5);
  EXPECT_TRUE(j.contains("act"));

  const auto e = nlohmann::json::parse(EncodeError(6, absl::InvalidArgumentError("act.intensity: too loud")));
  EXPECT_EQ(e["id"], 6);
  EXPECT_EQ(e["error"]["code"], "INVALID_ARGUMENT");
  EXPECT_EQ(e["error"]["message"], "act.intensity: too loud");
}

}  // namespace
}  // namespace kinemo::studio
