// Conversions between the controller core and its protobuf messages (no
// gRPC): parameters with defaults, state models (from the planner API or an
// inference model's ModelParameters), controller info.
#pragma once

#include "common/status/status.h"
#include "kinemo/inference/v1/inference.pb.h"
#include "kinemo/planner/v1/planner.pb.h"
#include "services/planner/controller/controller.h"

namespace kinemo::planner::controller {

// Zeros in `p` take `defaults`, whose zeros take the ControllerParams defaults.
ControllerParams FromProto(const v1::ControllerParams& p, const v1::ControllerParams& defaults);
v1::ControllerParams ToProto(const ControllerParams& p);
v1::ToneTransform ToneTransformToProto(const ToneTransfer& t);

// State models; errors name the field.
StatusOr<StateModel> FromProto(const v1::StateModel& m);
StatusOr<StateModel> FromProto(const ::kinemo::inference::v1::ModelParameters& m);

// Info of a built controller (ids, version and time set by the caller).
void ToProto(const Controller& c, v1::ControllerInfo* out);

}  // namespace kinemo::planner::controller
