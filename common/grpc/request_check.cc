#include "common/grpc/request_check.h"

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/stubs/common.h>
#include <google/protobuf/wire_format_lite.h>

namespace kinemo {
namespace {

namespace pb = google::protobuf;
using pb::FieldDescriptor;
using pb::internal::WireFormatLite;

// Deeper than any kinemo message; protobuf's own recursion limit is 100.
constexpr int kMaxDepth = 100;

std::string Join(std::string_view path, std::string_view name) {
  return path.empty() ? std::string(name) : kinemo::StrCat(path, ".", name);
}

// Walks the wire form of one `type` message up to the stream's limit. Returns
// false when the bytes are not a message at all; sets *error (and returns
// true) at the first string field with invalid UTF-8.
bool WalkWire(pb::io::CodedInputStream* in, const pb::Descriptor* type, const std::string& path, int depth,
              std::string* error) {
  std::vector<std::pair<int, int>> seen;  // field number -> occurrences so far (repeated index)
  auto next_index = [&seen](int number) {
    for (auto& [n, count] : seen) {
      if (n == number) return count++;
    }
    seen.emplace_back(number, 1);
    return 0;
  };
  while (true) {
    const std::uint32_t tag = in->ReadTag();
    if (tag == 0) return in->ConsumedEntireMessage();
    const FieldDescriptor* field = type->FindFieldByNumber(WireFormatLite::GetTagFieldNumber(tag));
    const bool delimited =
        WireFormatLite::GetTagWireType(tag) == WireFormatLite::WIRETYPE_LENGTH_DELIMITED;
    if (field == nullptr || !delimited ||
        (field->type() != FieldDescriptor::TYPE_STRING && field->type() != FieldDescriptor::TYPE_MESSAGE)) {
      if (!WireFormatLite::SkipField(in, tag)) return false;
      continue;
    }
    std::string field_path = Join(path, field->name());
    if (field->is_repeated()) field_path += kinemo::StrCat("[", next_index(field->number()), "]");
    std::uint32_t length = 0;
    if (!in->ReadVarint32(&length)) return false;
    if (field->type() == FieldDescriptor::TYPE_STRING) {
      std::string value;
      if (!in->ReadString(&value, static_cast<int>(length))) return false;
      if (field->file()->syntax() == pb::FileDescriptor::SYNTAX_PROTO3 &&
          !pb::internal::IsStructurallyValidUTF8(value)) {
        *error = field_path + ": invalid UTF-8";
        return true;
      }
      continue;
    }
    if (depth >= kMaxDepth) return false;
    const auto limit = in->PushLimit(static_cast<int>(length));
    if (!WalkWire(in, field->message_type(), field_path, depth + 1, error)) return false;
    if (!error->empty()) return true;
    in->PopLimit(limit);
  }
}

Status Invalid(const std::string& path, std::string_view what) {
  return absl::InvalidArgumentError(kinemo::StrCat(path, ": ", what));
}

Status CheckEnum(const FieldDescriptor* field, int value, const std::string& path) {
  if (field->enum_type()->FindValueByNumber(value) != nullptr) return absl::OkStatus();
  return Invalid(path, kinemo::StrCat(value, " is not a defined ", field->enum_type()->name(), " value"));
}

Status CheckFinite(double value, const std::string& path) {
  if (std::isfinite(value)) return absl::OkStatus();
  return Invalid(path, "not a finite number");
}

Status CheckValues(const pb::Message& message, const std::string& path, int depth) {
  if (depth >= kMaxDepth) return Invalid(path.empty() ? "request" : path, "nested too deeply");
  const pb::Reflection* reflection = message.GetReflection();
  std::vector<const FieldDescriptor*> fields;
  reflection->ListFields(message, &fields);
  for (const FieldDescriptor* field : fields) {
    const std::string name = Join(path, field->name());
    const bool repeated = field->is_repeated();
    const int count = repeated ? reflection->FieldSize(message, field) : 1;
    for (int i = 0; i < count; ++i) {
      const std::string at = repeated ? kinemo::StrCat(name, "[", i, "]") : name;
      Status status;
      switch (field->cpp_type()) {
        case FieldDescriptor::CPPTYPE_ENUM:
          status = CheckEnum(field,
                             repeated ? reflection->GetRepeatedEnumValue(message, field, i)
                                      : reflection->GetEnumValue(message, field),
                             at);
          break;
        case FieldDescriptor::CPPTYPE_DOUBLE:
          status = CheckFinite(repeated ? reflection->GetRepeatedDouble(message, field, i)
                                        : reflection->GetDouble(message, field),
                               at);
          break;
        case FieldDescriptor::CPPTYPE_FLOAT:
          status = CheckFinite(repeated ? reflection->GetRepeatedFloat(message, field, i)
                                        : reflection->GetFloat(message, field),
                               at);
          break;
        case FieldDescriptor::CPPTYPE_MESSAGE:
          status = CheckValues(repeated ? reflection->GetRepeatedMessage(message, field, i)
                                        : reflection->GetMessage(message, field),
                               at, depth + 1);
          break;
        default:
          i = count;  // other types hold no value a request can get wrong here
          break;
      }
      KINEMO_RETURN_IF_ERROR(status);
    }
  }
  return absl::OkStatus();
}

}  // namespace

std::string DescribeUnparseable(std::string_view bytes, const pb::Descriptor* type) {
  pb::io::CodedInputStream in(reinterpret_cast<const std::uint8_t*>(bytes.data()), static_cast<int>(bytes.size()));
  std::string error;
  if (WalkWire(&in, type, "", 0, &error) && !error.empty()) return error;
  return kinemo::StrCat("request: not a valid ", type->full_name(), " message");
}

Status CheckFitsInt(const pb::Message& message, std::string_view prefix) {
  const pb::Reflection* reflection = message.GetReflection();
  const pb::Descriptor* type = message.GetDescriptor();
  for (int i = 0; i < type->field_count(); ++i) {
    const FieldDescriptor* field = type->field(i);
    if (field->cpp_type() != FieldDescriptor::CPPTYPE_UINT32 || field->is_repeated()) continue;
    const std::uint32_t value = reflection->GetUInt32(message, field);
    if (value > static_cast<std::uint32_t>(std::numeric_limits<std::int32_t>::max())) {
      return Invalid(Join(prefix, field->name()), kinemo::StrCat(value, " is too large"));
    }
  }
  return absl::OkStatus();
}

Status CheckRequestValues(const pb::Message& message, std::string_view prefix) {
  return CheckValues(message, std::string(prefix), 0);
}

}  // namespace kinemo
