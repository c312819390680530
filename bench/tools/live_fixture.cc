// live_fixture — loads a Gesture Controller into a running stack for live
// measurements (`kinemo bench e2e`, `kinemo animate --stream`) while no
// bundled controller exists: the planner builds controller CONTROLLER over
// its library LIBRARY from the inference service's model MODEL (GetModel
// with parameters -> BuildController), as the tests do
// (tests/service/coordinator/gc_models.h).
//
//   live_fixture --inference ADDR --planner ADDR --model ID --controller ID [--library bundled]
//
// Put the model in the inference service first (`kinemo crf train --out
// M.kmodel`, copied to <model_dir>/<ID>/v1.kmodel before it starts).
#include <CLI/CLI.hpp>

#include <iostream>

#include <grpcpp/grpcpp.h>

#include "tests/service/coordinator/gc_models.h"

int main(int argc, char** argv) {
  CLI::App app("Build a Gesture Controller on a running planner from a running inference service's model");
  std::string inference, planner, model, controller, library = "bundled";
  app.add_option("--inference", inference, "inference service address")->required();
  app.add_option("--planner", planner, "planner service address")->required();
  app.add_option("--model", model, "inference model id")->required();
  app.add_option("--controller", controller, "controller id to build")->required();
  app.add_option("--library", library, "planner library id")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  auto inference_stub = kinemo::inference::v1::InferenceService::NewStub(
      grpc::CreateChannel(inference, grpc::InsecureChannelCredentials()));
  auto planner_stub = kinemo::planner::v1::PlannerService::NewStub(
      grpc::CreateChannel(planner, grpc::InsecureChannelCredentials()));
  const kinemo::Status s = kinemo::coordinator::testing::BuildController(inference_stub.get(), planner_stub.get(),
                                                                        model, controller, library);
  if (!s.ok()) {
    std::cerr << "live_fixture: " << s.message() << "\n";
    return 1;
  }
  std::cout << "controller '" << controller << "' built on " << planner << " from model '" << model << "'\n";
  return 0;
}
