// One answer for malformed requests on every RPC of every kinemo server.
//
// gRPC parses a unary (or server-streaming) request before any handler runs;
// when protobuf refuses the bytes (a string field with invalid UTF-8, a body
// that is not a message) gRPC 1.51 answers INTERNAL with an empty message on
// synchronous methods and UNIMPLEMENTED on callback methods, and names the
// field only in the server's log. The guard answers INVALID_ARGUMENT instead:
//   `header.files[2].name: invalid UTF-8`
//   `request: not a valid kinemo.prosody.v1.AnalyzeRequest message`
// and refuses, with the same code, requests that parse but hold an enum
// number outside its enum or a NaN/infinite number (CheckRequestValues in
// common/grpc/request_check.h), before the handler sees them.
//
// Two parts, both installed by ServiceHost for every server it builds (TCP,
// unix socket and in-process alike, so also the all-in-one):
//  - GuardRequests() wraps each method's handler: its Deserialize keeps a
//    reference to the raw bytes, and when parsing fails describes them
//    against the request's descriptor; the error is recorded for the call.
//  - the interceptor from MakeRequestGuardFactory() replaces the status the
//    call ends with by that error (the callback handlers of gRPC 1.51 ignore
//    the deserialisation status and answer UNIMPLEMENTED).
// The interceptor also keeps server paths out of every status a server of
// this process sends: a path under a configured root (RedactPathsUnder,
// RedactOptionPaths) is shown relative to it ("models/x/1/model.kmodel"),
// the root itself by its option's name ("store_dir").
// Client-streaming messages are parsed elsewhere in gRPC (a bad one ends the
// stream as if the client had half-closed); handlers of client streams call
// CheckRequestValues() on each message themselves.
#pragma once

#include <memory>
#include <string>
#include <string_view>

#include <google/protobuf/message.h>

#include <grpcpp/impl/service_type.h>
#include <grpcpp/support/server_interceptor.h>

namespace kinemo::server {

// Wraps the handlers of `service`'s synchronous and callback methods (async,
// raw and generic methods carry no parsed request and are left alone). Call
// once per service, before the server is built.
void GuardRequests(grpc::Service* service);

// Registers `root` (made absolute; `name` is its option, e.g. "store_dir")
// for the path redaction above. Thread-safe; call before serving.
void RedactPathsUnder(const std::string& root, const std::string& name);
// Registers every non-empty string field of `options` (at any depth) whose
// name ends in "_dir" or "_root" (store_dir, seed_store_dir, library_root,
// file_root, corpus_root, model_dir).
void RedactOptionPaths(const google::protobuf::Message& options);
// `message` with the registered roots redacted.
std::string RedactServerPaths(std::string message);

// The interceptor every guarded server installs.
std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> MakeRequestGuardFactory();

}  // namespace kinemo::server
