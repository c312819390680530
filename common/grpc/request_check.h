// Checks that hold for every request of every service, from the message's
// descriptor alone (no gRPC here; common/server/request_guard.h applies them
// to every RPC before a handler runs):
//  - DescribeUnparseable(): why bytes are not a valid message, naming the
//    field with its path (`header.files[2].name: invalid UTF-8`), or
//    `request: not a valid kinemo.x.v1.YRequest message`.
//  - CheckRequestValues(): enum numbers outside their enum and NaN or
//    infinite floating-point values, refused naming the field
//    (`params.pitch_floor_hz: not a finite number`). Protobuf 3 accepts both
//    on the wire; no kinemo request gives them a meaning. Handlers of client
//    streams (which the guard cannot see) call it on each message.
#pragma once

#include <string>
#include <string_view>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>

#include "common/status/status.h"

namespace kinemo {

// The message for bytes that `type` failed to parse: the first string field
// (at any depth) holding invalid UTF-8, else the generic "not a valid"
// message. Never fails; `type` must not be null.
std::string DescribeUnparseable(std::string_view bytes, const google::protobuf::Descriptor* type);

// INVALID_ARGUMENT naming the first field (depth first, in field order) that
// holds an enum number its enum does not define, or a NaN/infinite
// float/double; OK otherwise. Paths are relative to `message` and start with
// `prefix` when it is not empty (e.g. "requests[3]").
Status CheckRequestValues(const google::protobuf::Message& message, std::string_view prefix = "");

// INVALID_ARGUMENT naming the first uint32 field of `message` (not nested)
// above INT32_MAX, printed as sent (`params.num_states: 4294967295 is too
// large`), for parameter messages whose values become `int`s (a bare cast
// would turn them into negative numbers). OK otherwise.
Status CheckFitsInt(const google::protobuf::Message& message, std::string_view prefix);

}  // namespace kinemo
