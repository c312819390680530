// Fuzzes the studio's decoder of WebSocket text frames (services/studio/core
// DecodeClientMessage): whatever a page (or anyone reaching the socket)
// sends. Refusals are INVALID_ARGUMENT naming the field at fault ("message",
// "id" or the call's own path); an accepted message has exactly one call and
// survives proto3 JSON both ways; the id reported for an error is the id the
// frame carried.
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include <google/protobuf/util/json_util.h>

#include "services/studio/core/messages.h"
#include "tests/fuzz/fuzz_check.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text = kinemo::fuzz::Text(data, size);
  std::uint32_t id = 0;
  auto message = kinemo::studio::DecodeClientMessage(text, &id);
  if (!message.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(message.status(), absl::StatusCode::kInvalidArgument);
    const std::string m(message.status().message());
    KINEMO_FUZZ_CHECK(!m.empty() && m.find(": ") != std::string::npos && m.find(": ") > 0,
                      "the error names no field: " + message.status().ToString());
    // The error frame for it is valid JSON the page can read.
    const std::string frame = kinemo::studio::EncodeError(id, message.status());
    kinemo::studio::v1::ServerMessage parsed;
    google::protobuf::util::JsonParseOptions lenient;
    lenient.ignore_unknown_fields = true;
    KINEMO_FUZZ_CHECK(google::protobuf::util::JsonStringToMessage(frame, &parsed, lenient).ok(),
                      "the error frame is not a ServerMessage: " + frame);
    return 0;
  }
  KINEMO_FUZZ_CHECK(message->call_case() != kinemo::studio::v1::ClientMessage::CALL_NOT_SET,
                    "accepted a message with no call");
  KINEMO_FUZZ_CHECK(message->id() == id, "the reported id differs from the message's");
  KINEMO_FUZZ_CHECK(kinemo::studio::CallName(*message) != "message", "accepted call has no name");
  std::string json;
  KINEMO_FUZZ_CHECK(google::protobuf::util::MessageToJsonString(*message, &json).ok(), "cannot print it");
  auto again = kinemo::studio::DecodeClientMessage(json);
  KINEMO_FUZZ_CHECK(again.ok(), "its own JSON is refused: " + again.status().ToString() + " " + json);
  KINEMO_FUZZ_CHECK(again->SerializeAsString() == message->SerializeAsString(),
                    "JSON round trip changed the message");
  return 0;
}
