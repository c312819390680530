// The deadline classes of the coordinator's calls (core/deadlines.h).
#include "services/coordinator/core/deadlines.h"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

#include "absl/strings/match.h"

namespace kinemo::coordinator {
namespace {

TEST(Deadlines, DefaultsAndTheirUse) {
  v1::CoordinatorOptions o;
  auto d = Deadlines::Resolve(o);
  ASSERT_TRUE(d.ok()) << d.status();
  EXPECT_EQ(d->short_s, 2);
  EXPECT_EQ(d->build_s, 3600);
  EXPECT_EQ(d->stream_idle_s, 10);
  EXPECT_EQ(d->Analysis(7), 10 + 7);
  EXPECT_EQ(d->ForClass(MethodClass::kAnalysis), 10 + 600);  // forwarded: animate.max_audio_s
  EXPECT_EQ(d->ForClass(MethodClass::kStream), 0);           // streams keep the caller's deadline
  // A service's own deadline_s replaces the short class for it.
  o.mutable_services()->mutable_robot_bridge()->set_deadline_s(0.5);
  EXPECT_EQ(d->Short(o.services().robot_bridge()), 0.5);
  EXPECT_EQ(d->Short(o.services().prosody()), 2);
  // Set values win.
  o.mutable_deadlines()->set_analysis_base_s(1);
  o.mutable_deadlines()->set_analysis_per_audio_s(0.25);
  o.mutable_animate()->set_max_audio_s(20);
  d = Deadlines::Resolve(o);
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(d->Analysis(4), 2);
  EXPECT_EQ(d->ForClass(MethodClass::kAnalysis), 6);
}

TEST(Deadlines, BadValuesAreRefusedNamingTheField) {
  struct Case {
    void (*set)(v1::CoordinatorOptions*);
    const char* field;
  };
  const Case cases[] = {
      {[](v1::CoordinatorOptions* o) { o->mutable_deadlines()->set_short_s(-1); }, "deadlines.short_s"},
      {[](v1::CoordinatorOptions* o) { o->mutable_deadlines()->set_build_s(std::nan("")); }, "deadlines.build_s"},
      {[](v1::CoordinatorOptions* o) { o->mutable_deadlines()->set_stream_idle_s(1e9); },
       "deadlines.stream_idle_s"},
      {[](v1::CoordinatorOptions* o) {
         o->mutable_deadlines()->set_analysis_per_audio_s(std::numeric_limits<double>::infinity());
       },
       "deadlines.analysis_per_audio_s"},
      {[](v1::CoordinatorOptions* o) { o->mutable_services()->mutable_planner()->set_deadline_s(-2); },
       "services.planner.deadline_s"},
  };
  for (const Case& c : cases) {
    v1::CoordinatorOptions o;
    c.set(&o);
    const auto d = Deadlines::Resolve(o);
    EXPECT_EQ(d.status().code(), absl::StatusCode::kInvalidArgument) << c.field;
    EXPECT_TRUE(absl::StartsWith(d.status().message(), c.field)) << d.status();
  }
}

TEST(Deadlines, ClassOfEveryMethodTheCoordinatorCallsOrForwards) {
  EXPECT_EQ(ClassOfMethod("/kinemo.prosody.v1.ProsodyService/Analyze"), MethodClass::kAnalysis);
  EXPECT_EQ(ClassOfMethod("Infer"), MethodClass::kAnalysis);
  EXPECT_EQ(ClassOfMethod("/kinemo.planner.v1.PlannerService/SynthesizeGestures"), MethodClass::kAnalysis);
  EXPECT_EQ(ClassOfMethod("/kinemo.inference.v1.InferenceService/Train"), MethodClass::kBuild);
  EXPECT_EQ(ClassOfMethod("/kinemo.planner.v1.PlannerService/EvaluateLocomotion"), MethodClass::kBuild);
  EXPECT_EQ(ClassOfMethod("/kinemo.cube_tracker.v1.CubeTrackerService/PushArtifact"), MethodClass::kBuild);
  EXPECT_EQ(ClassOfMethod("/kinemo.planner.v1.PlannerService/Control"), MethodClass::kStream);
  EXPECT_EQ(ClassOfMethod("/kinemo.cube_tracker.v1.CubeTrackerService/TrackSource"), MethodClass::kStream);
  EXPECT_EQ(ClassOfMethod("/kinemo.inference.v1.InferenceService/ListModels"), MethodClass::kShort);
  EXPECT_EQ(ClassOfMethod("/kinemo.cube_tracker.v1.CubeTrackerService/ConfigureCube"), MethodClass::kShort);
}

}  // namespace
}  // namespace kinemo::coordinator
