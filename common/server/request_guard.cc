#include "common/server/request_guard.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <mutex>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include <grpc/byte_buffer.h>
#include <grpc/byte_buffer_reader.h>
#include <grpc/slice.h>
#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>
#include <grpcpp/impl/rpc_service_method.h>
#include <grpcpp/server_context.h>

#include "common/grpc/request_check.h"

namespace kinemo::server {
namespace {

namespace pb = google::protobuf;
using grpc::internal::MethodHandler;
using grpc::internal::RpcServiceMethod;

// gRPC 1.51 has no public way to wrap the handler of a registered method:
// grpc::Service::methods_ and RpcServiceMethod::handler_ are private, and the
// protected setters change the method's API type or delete the old handler.
// An explicit instantiation may name private members ([temp.explicit]/12);
// the compiler checks their names and types, so a gRPC whose layout differs
// fails to build instead of misbehaving.
template <typename Tag, typename Tag::type kMember>
struct PrivateMember {
  friend typename Tag::type Get(Tag) { return kMember; }
};
struct ServiceMethods {
  using type = std::vector<std::unique_ptr<RpcServiceMethod>> grpc::Service::*;
  friend type Get(ServiceMethods);
};
struct MethodHandlerOf {
  using type = std::unique_ptr<MethodHandler> RpcServiceMethod::*;
  friend type Get(MethodHandlerOf);
};
template struct PrivateMember<ServiceMethods, &grpc::Service::methods_>;
template struct PrivateMember<MethodHandlerOf, &RpcServiceMethod::handler_>;

// The error found while parsing a call's request, until its interceptor
// takes it (right after, in the same call's POST_RECV_MESSAGE).
class ErrorsByCall {
 public:
  void Put(grpc_call* call, std::string error) {
    std::lock_guard<std::mutex> lock(mu_);
    errors_[call] = std::move(error);
  }
  std::string Take(grpc_call* call) {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = errors_.find(call);
    if (it == errors_.end()) return {};
    std::string error = std::move(it->second);
    errors_.erase(it);
    return error;
  }

 private:
  std::mutex mu_;
  std::unordered_map<grpc_call*, std::string> errors_;
};

ErrorsByCall& Errors() {
  static auto* errors = new ErrorsByCall();  // used by server threads until exit
  return *errors;
}

std::string ReadAll(grpc_byte_buffer* buffer) {
  grpc_byte_buffer_reader reader;
  if (grpc_byte_buffer_reader_init(&reader, buffer) == 0) return {};
  grpc_slice slice = grpc_byte_buffer_reader_readall(&reader);
  std::string bytes(reinterpret_cast<const char*>(GRPC_SLICE_START_PTR(slice)), GRPC_SLICE_LENGTH(slice));
  grpc_slice_unref(slice);
  grpc_byte_buffer_reader_destroy(&reader);
  return bytes;
}

// Configured roots, longest first (a root inside another is replaced first).
class Roots {
 public:
  void Add(std::string root, std::string name) {
    std::lock_guard<std::mutex> lock(mu_);
    for (const auto& [r, n] : roots_) {
      if (r == root) return;
    }
    roots_.emplace_back(std::move(root), std::move(name));
    std::sort(roots_.begin(), roots_.end(), [](const auto& a, const auto& b) { return a.first.size() > b.first.size(); });
  }
  std::string Redact(std::string message) {
    std::lock_guard<std::mutex> lock(mu_);
    for (const auto& [root, name] : roots_) {
      Replace(root + "/", "", &message);
      Replace(root, name, &message, /*whole=*/true);
    }
    return message;
  }

 private:
  // `whole`: only where `from` is not followed by more of a file name.
  static void Replace(const std::string& from, const std::string& to, std::string* s, bool whole = false) {
    std::size_t at = s->find(from);
    while (at != std::string::npos) {
      const std::size_t end = at + from.size();
      const bool more = end < s->size() && (std::isalnum(static_cast<unsigned char>((*s)[end])) ||
                                            (*s)[end] == '.' || (*s)[end] == '_' || (*s)[end] == '-');
      if (whole && more) {
        at = s->find(from, end);
        continue;
      }
      s->replace(at, from.size(), to);
      at = s->find(from, at + to.size());
    }
  }
  std::mutex mu_;
  std::vector<std::pair<std::string, std::string>> roots_;
};

Roots& ConfiguredRoots() {
  static auto* roots = new Roots();  // used by server threads until exit
  return *roots;
}

bool EndsWith(const std::string& s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

class GuardedHandler final : public MethodHandler {
 public:
  GuardedHandler(std::unique_ptr<MethodHandler> inner, const pb::Descriptor* request_type, bool sync)
      : inner_(std::move(inner)), request_type_(request_type), sync_(sync) {}

  void RunHandler(const HandlerParameter& param) override { inner_->RunHandler(param); }

  void* Deserialize(grpc_call* call, grpc_byte_buffer* req, grpc::Status* status, void** handler_data) override {
    // A reference to the bytes (the slices are shared, not copied): the
    // inner handler consumes `req`.
    grpc_byte_buffer* bytes = req == nullptr ? nullptr : grpc_byte_buffer_copy(req);
    void* request = inner_->Deserialize(call, req, status, handler_data);
    std::string error;
    if (request == nullptr) {
      error = bytes == nullptr ? "request: no message was sent" : DescribeUnparseable(ReadAll(bytes), request_type_);
    } else {
      // The handler's request is a generated message (single inheritance
      // from pb::Message), handed over as void*.
      auto* message = static_cast<pb::Message*>(request);
      if (Status checked = CheckRequestValues(*message); !checked.ok()) {
        error = std::string(checked.message());
        // A synchronous handler owns the request only once the call runs; a
        // callback handler's message holder (in *handler_data) frees it.
        if (sync_) message->~Message();
        request = nullptr;
      }
    }
    if (bytes != nullptr) grpc_byte_buffer_destroy(bytes);
    if (!error.empty()) {
      *status = grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, error);
      Errors().Put(call, std::move(error));
    }
    return request;
  }

 private:
  const std::unique_ptr<MethodHandler> inner_;
  const pb::Descriptor* const request_type_;
  const bool sync_;
};

class RequestGuard final : public grpc::experimental::Interceptor {
 public:
  explicit RequestGuard(grpc::experimental::ServerRpcInfo* info) : info_(info) {}

  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    using grpc::experimental::InterceptionHookPoints;
    if (methods->QueryInterceptionHookPoint(InterceptionHookPoints::POST_RECV_MESSAGE) &&
        methods->GetRecvMessage() == nullptr && info_->server_context() != nullptr) {
      error_ = Errors().Take(info_->server_context()->c_call());
    }
    if (methods->QueryInterceptionHookPoint(InterceptionHookPoints::PRE_SEND_STATUS)) {
      if (!error_.empty()) {
        methods->ModifySendStatus(grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, error_));
      } else if (const grpc::Status status = methods->GetSendStatus(); !status.ok()) {
        std::string message = RedactServerPaths(status.error_message());
        if (message != status.error_message()) {
          methods->ModifySendStatus(grpc::Status(status.error_code(), message, status.error_details()));
        }
      }
    }
    methods->Proceed();
  }

 private:
  grpc::experimental::ServerRpcInfo* const info_;
  std::string error_;
};

class RequestGuardFactory final : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  grpc::experimental::Interceptor* CreateServerInterceptor(grpc::experimental::ServerRpcInfo* info) override {
    return new RequestGuard(info);
  }
};

// "/kinemo.prosody.v1.Prosody/Analyze" -> its request type, or null.
const pb::Descriptor* RequestTypeOf(const char* method_name) {
  std::string name = method_name == nullptr ? "" : method_name;
  if (name.size() < 2 || name[0] != '/') return nullptr;
  name.erase(0, 1);
  const auto slash = name.find('/');
  if (slash == std::string::npos) return nullptr;
  name[slash] = '.';
  const pb::MethodDescriptor* method = pb::DescriptorPool::generated_pool()->FindMethodByName(name);
  return method == nullptr ? nullptr : method->input_type();
}

}  // namespace

void GuardRequests(grpc::Service* service) {
  for (std::unique_ptr<RpcServiceMethod>& method : service->*Get(ServiceMethods{})) {
    if (method == nullptr || method->handler() == nullptr) continue;  // generic or async
    const auto api = method->api_type();
    if (api != RpcServiceMethod::ApiType::SYNC && api != RpcServiceMethod::ApiType::CALL_BACK) continue;
    const pb::Descriptor* request_type = RequestTypeOf(method->name());
    if (request_type == nullptr || dynamic_cast<GuardedHandler*>(method->handler()) != nullptr) continue;
    std::unique_ptr<MethodHandler>& handler = (*method).*Get(MethodHandlerOf{});
    handler = std::make_unique<GuardedHandler>(std::move(handler), request_type,
                                               api == RpcServiceMethod::ApiType::SYNC);
  }
}

void RedactPathsUnder(const std::string& root, const std::string& name) {
  if (root.empty()) return;
  std::error_code ec;
  std::string absolute = std::filesystem::absolute(root, ec).lexically_normal().string();
  if (ec) return;
  while (absolute.size() > 1 && absolute.back() == '/') absolute.pop_back();
  if (absolute == "/") return;
  ConfiguredRoots().Add(absolute, name);
  // Also the path as configured (e.g. relative) and as the file system resolves it.
  if (root != absolute && root.front() == '/') ConfiguredRoots().Add(root, name);
  const auto canonical = std::filesystem::weakly_canonical(absolute, ec).string();
  if (!ec && canonical != absolute && canonical != "/") ConfiguredRoots().Add(canonical, name);
}

void RedactOptionPaths(const pb::Message& options) {
  const pb::Reflection* reflection = options.GetReflection();
  std::vector<const pb::FieldDescriptor*> fields;
  reflection->ListFields(options, &fields);
  for (const pb::FieldDescriptor* field : fields) {
    if (field->is_repeated()) continue;
    if (field->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE) {
      RedactOptionPaths(reflection->GetMessage(options, field));
    } else if (field->cpp_type() == pb::FieldDescriptor::CPPTYPE_STRING &&
               (EndsWith(field->name(), "_dir") || EndsWith(field->name(), "_root"))) {
      RedactPathsUnder(reflection->GetString(options, field), field->name());
    }
  }
}

std::string RedactServerPaths(std::string message) { return ConfiguredRoots().Redact(std::move(message)); }

std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> MakeRequestGuardFactory() {
  return std::make_unique<RequestGuardFactory>();
}

}  // namespace kinemo::server
