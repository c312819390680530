// RPC metrics of every kinemo server, in one place: a server interceptor that
// ServiceHost installs on each server it builds (so every service, the
// all-in-one's included, counts its calls the same way). Per method (the
// full path, "/kinemo.planner.v1.PlannerService/Plan"):
//   kinemo_rpc_started_total{method}
//   kinemo_rpc_handled_total{method,code}          calls finished, by status code
//   kinemo_rpc_handling_seconds{method,code}       histogram: call start → status sent
//   kinemo_rpc_in_flight{method}                   calls running now
// Method labels are bounded: past kMaxMethods distinct paths (a generic
// service receives whatever a client names), calls count under "other".
#pragma once

#include <memory>

#include <grpcpp/support/server_interceptor.h>

namespace kinemo::server {

inline constexpr int kMaxMethods = 512;

// A factory for ServerBuilder::experimental().SetInterceptorCreators().
std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> MakeRpcMetricsInterceptorFactory();

}  // namespace kinemo::server
