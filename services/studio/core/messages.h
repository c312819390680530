// The studio's socket messages (proto/kinemo/studio/v1/studio.proto): JSON
// text frames <-> ClientMessage / ServerMessage. Plain functions with no I/O,
// so that a fuzzer can drive DecodeClientMessage directly.
#pragma once

#include <string>
#include <string_view>

#include "common/status/status.h"
#include "kinemo/studio/v1/studio.pb.h"

namespace kinemo::studio {

// Decodes one text frame from the page. The frame must be a JSON object with
// an optional "id" (0..4294967295) and exactly one call field of
// ClientMessage (lowerCamelCase or snake_case), whose value is that
// request's proto3 JSON mapping. INVALID_ARGUMENT otherwise, with a message
// that starts with the field at fault: "message" (not JSON, not an object,
// no or several calls), "id", or the call's own path
// ("animate.audio.format.encoding: ..."). `id`, when given, receives the
// message's id as soon as it is read (so that an error can name its call).
StatusOr<v1::ClientMessage> DecodeClientMessage(std::string_view text, std::uint32_t* id = nullptr);

// The snake_case name of the message's call ("animate", "stream_end", ...);
// "message" when none is set.
std::string CallName(const v1::ClientMessage& message);

// The proto3 JSON mapping of `message` (lowerCamelCase names, defaults
// omitted): one text frame for the page.
std::string EncodeServerMessage(const v1::ServerMessage& message);

// An error frame for call `id`: {"id": id, "error": {"code": ..., "message": ...}}.
// `status` must not be OK; its message should start with the field at fault.
std::string EncodeError(std::uint32_t id, const Status& status);

// The canonical name of a status code ("INVALID_ARGUMENT").
std::string StatusCodeName(absl::StatusCode code);

}  // namespace kinemo::studio
