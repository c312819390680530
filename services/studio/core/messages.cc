// The studio's socket messages (messages.h).
#include "services/studio/core/messages.h"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/util/json_util.h>

#include <cctype>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace kinemo::studio {
namespace {

using google::protobuf::FieldDescriptor;

// The call field of ClientMessage spelled `key` (its name or JSON name).
const FieldDescriptor* FindCall(const std::string& key) {
  const auto* oneof = v1::ClientMessage::descriptor()->FindOneofByName("call");
  for (int i = 0; i < oneof->field_count(); ++i) {
    const FieldDescriptor* f = oneof->field(i);
    if (f->name() == key || f->json_name() == key) return f;
  }
  return nullptr;
}

std::string CallList() {
  const auto* oneof = v1::ClientMessage::descriptor()->FindOneofByName("call");
  std::string out;
  for (int i = 0; i < oneof->field_count(); ++i) {
    if (i > 0) out += ", ";
    out += oneof->field(i)->name();
  }
  return out;
}

// Protobuf's JSON parser says where it failed in three ways:
// "(a.b[2]): invalid value ...", "(a.b) key: Cannot find field." and
// "key: Cannot find field." (at the top). Rewritten to start with the path
// below `call`: "call.a.b[2]: invalid value ...".
std::string RewriteParseError(const std::string& call, const std::string& message) {
  std::string path = call;
  std::string rest = message;
  if (!rest.empty() && rest[0] == '(') {
    const std::size_t close = rest.find(')');
    if (close != std::string::npos) {
      const std::string inner = rest.substr(1, close - 1);
      if (!inner.empty()) path += "." + inner;
      rest = rest.substr(close + 1);
      if (rest.rfind(": ", 0) == 0) {
        rest = rest.substr(2);
      } else if (!rest.empty() && rest[0] == ' ') {
        rest = rest.substr(1);
      }
    }
  }
  // "key: Cannot find field."
  const std::size_t colon = rest.find(": Cannot find field");
  if (colon != std::string::npos && colon > 0 && rest.find(' ') > colon) {
    return path + "." + rest.substr(0, colon) + ": no such field";
  }
  // Multi-line messages (the parser's caret display) keep their first line.
  const std::size_t newline = rest.find('\n');
  if (newline != std::string::npos) rest = rest.substr(0, newline);
  return path + ": " + rest;
}

}  // namespace

namespace {

// [A-Za-z_][A-Za-z0-9_]* of at most 64 characters.
bool IsFieldName(const std::string& key) {
  if (key.empty() || key.size() > 64) return false;
  if (!(std::isalpha(static_cast<unsigned char>(key[0])) || key[0] == '_')) return false;
  for (char c : key) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_')) return false;
  }
  return true;
}

}  // namespace

StatusOr<v1::ClientMessage> DecodeClientMessage(std::string_view text, std::uint32_t* id_out) {
  nlohmann::json json;
  try {
    json = nlohmann::json::parse(text.begin(), text.end());
  } catch (const nlohmann::json::parse_error& e) {
    return InvalidField("message", "not valid JSON at byte ", e.byte);
  } catch (const std::exception& e) {
    return InvalidField("message", "not valid JSON");
  }
  if (!json.is_object()) return InvalidField("message", "must be a JSON object, got ", json.type_name());
  v1::ClientMessage message;
  const FieldDescriptor* call = nullptr;
  std::string call_key;
  // The id first (keys iterate in sorted order), so that every later error
  // can name its call.
  if (const auto found = json.find("id"); found != json.end()) {
    const auto& id = *found;
    if (!id.is_number_integer() && !id.is_number_unsigned()) {
      return InvalidField("id", "must be an integer in [0, 4294967295], got ", id.type_name());
    }
    if (id.is_number_unsigned()) {
      const auto v = id.get<std::uint64_t>();
      if (v > std::numeric_limits<std::uint32_t>::max()) return InvalidField("id", v, " is outside [0, 4294967295]");
      message.set_id(static_cast<std::uint32_t>(v));
    } else {
      const auto v = id.get<std::int64_t>();
      if (v < 0 || v > static_cast<std::int64_t>(std::numeric_limits<std::uint32_t>::max())) {
        return InvalidField("id", v, " is outside [0, 4294967295]");
      }
      message.set_id(static_cast<std::uint32_t>(v));
    }
    if (id_out != nullptr) *id_out = message.id();
  }
  for (auto it = json.begin(); it != json.end(); ++it) {
    const std::string& key = it.key();
    if (key == "id") continue;
    const FieldDescriptor* field = FindCall(key);
    if (field == nullptr) {
      // A key that reads as a field name is named as the field; any other
      // (empty, punctuation, control bytes) is the message's fault.
      if (IsFieldName(key)) return InvalidField(key, "not a call of the studio (one of: ", CallList(), ")");
      return InvalidField("message", "a key that is not a call of the studio (one of: ", CallList(), ")");
    }
    if (call != nullptr) {
      return InvalidField("message", "has two calls, ", call->name(), " and ", field->name(),
                          "; send one per message");
    }
    call = field;
    call_key = key;
  }
  if (call == nullptr) return InvalidField("message", "names no call (one of: ", CallList(), ")");
  const nlohmann::json& body = json[call_key];
  if (!body.is_object()) {
    return InvalidField(call->name(), "must be a JSON object, got ", body.type_name());
  }
  google::protobuf::Message* target = message.GetReflection()->MutableMessage(&message, call);
  google::protobuf::util::JsonParseOptions options;
  options.ignore_unknown_fields = false;
  const auto parsed = google::protobuf::util::JsonStringToMessage(body.dump(), target, options);
  if (!parsed.ok()) {
    return absl::InvalidArgumentError(RewriteParseError(call->name(), std::string(parsed.message())));
  }
  return message;
}

std::string CallName(const v1::ClientMessage& message) {
  const auto* oneof = v1::ClientMessage::descriptor()->FindOneofByName("call");
  const FieldDescriptor* f = message.GetReflection()->GetOneofFieldDescriptor(message, oneof);
  return f == nullptr ? "message" : f->name();
}

std::string EncodeServerMessage(const v1::ServerMessage& message) {
  google::protobuf::util::JsonPrintOptions options;
  options.always_print_primitive_fields = true;
  std::string out;
  const auto printed = google::protobuf::util::MessageToJsonString(message, &out, options);
  if (!printed.ok()) {
    return EncodeError(message.id(), absl::InternalError(kinemo::StrCat(
                                         "message: the answer could not be written as JSON: ",
                                         std::string(printed.message()))));
  }
  return out;
}

std::string EncodeError(std::uint32_t id, const Status& status) {
  // Written by hand (not through the proto) so that it cannot fail.
  nlohmann::json j = {{"id", id},
                      {"error",
                       {{"code", StatusCodeName(status.code())},
                        {"message", std::string(status.message())}}}};
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

std::string StatusCodeName(absl::StatusCode code) {
  std::string name = absl::StatusCodeToString(code);
  for (char& c : name) {
    if (c == ' ') c = '_';
    if (c >= 'a' && c <= 'z') c = static_cast<char>(c - 'a' + 'A');
  }
  return name;
}

}  // namespace kinemo::studio
