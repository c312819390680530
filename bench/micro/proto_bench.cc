// Wire cost of the messages kinemo streams most (protobuf serialization and
// parsing of kinemo_proto): a whole clip (BEAT2 take 1, 75 joints, as a
// MotionClip: the body of an animate reply) and a live batch of three frames
// (MotionFrameBatch, what StreamAnimate sends every 100 ms). The generated
// code compiles at KINEMO_GLUE_OPT (-O1 by default, CMakeLists.txt); this
// bench is how that choice is checked against -O3 (docs/DEVELOPING.md, "Building
// parts"). Counters: bytes per message, frames_per_s.
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <string>

#include "common/motion/bvh.h"
#include "kinemo/common/v1/motion.pb.h"

namespace kinemo {
namespace {

const common::v1::MotionClip& TakeOne() {
  static const common::v1::MotionClip* const clip = [] {
    StatusOr<motion::Clip> c =
        motion::ReadBvhFile(std::string(KINEMO_TEST_DATA_DIR) + "/paired/beat2/2_scott_0_1_1.bvh");
    if (!c.ok()) std::abort();
    auto* out = new common::v1::MotionClip;
    out->set_name("2_scott_0_1_1");
    out->set_frame_time_s(c->frame_time_s);
    for (int j = 0; j < c->skeleton.num_joints(); ++j) {
      const motion::Joint& joint = c->skeleton.joint(j);
      common::v1::Joint* p = out->mutable_skeleton()->add_joints();
      p->set_name(joint.name);
      p->set_parent_index(joint.parent);
      p->mutable_offset()->set_x(joint.offset.x());
      p->mutable_offset()->set_y(joint.offset.y());
      p->mutable_offset()->set_z(joint.offset.z());
    }
    for (int f = 0; f < c->num_frames(); ++f) {
      common::v1::MotionFrame* frame = out->add_frames();
      frame->set_time_s(f * c->frame_time_s);
      for (double v : c->frame(f)) frame->add_values(v);
    }
    return out;
  }();
  return *clip;
}

common::v1::MotionFrameBatch LiveBatch() {
  common::v1::MotionFrameBatch b;
  for (int f = 0; f < 3; ++f) *b.add_frames() = TakeOne().frames(f);
  return b;
}

template <typename Message>
void Serialize(benchmark::State& state, const Message& m, int frames) {
  std::string bytes;
  for (auto _ : state) {
    bytes.clear();
    m.SerializeToString(&bytes);
    benchmark::DoNotOptimize(bytes.data());
  }
  state.counters["bytes"] = static_cast<double>(bytes.size());
  state.counters["frames_per_s"] =
      benchmark::Counter(static_cast<double>(frames) * state.iterations(), benchmark::Counter::kIsRate);
}

template <typename Message>
void Parse(benchmark::State& state, const Message& m, int frames) {
  const std::string bytes = m.SerializeAsString();
  Message out;
  for (auto _ : state) {
    if (!out.ParseFromString(bytes)) state.SkipWithError("parse failed");
    benchmark::DoNotOptimize(out.frames_size());
  }
  state.counters["bytes"] = static_cast<double>(bytes.size());
  state.counters["frames_per_s"] =
      benchmark::Counter(static_cast<double>(frames) * state.iterations(), benchmark::Counter::kIsRate);
}

void BM_ProtoClipSerialize(benchmark::State& state) { Serialize(state, TakeOne(), TakeOne().frames_size()); }
void BM_ProtoClipParse(benchmark::State& state) { Parse(state, TakeOne(), TakeOne().frames_size()); }
void BM_ProtoLiveBatchSerialize(benchmark::State& state) { Serialize(state, LiveBatch(), 3); }
void BM_ProtoLiveBatchParse(benchmark::State& state) { Parse(state, LiveBatch(), 3); }
BENCHMARK(BM_ProtoClipSerialize)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_ProtoClipParse)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_ProtoLiveBatchSerialize);
BENCHMARK(BM_ProtoLiveBatchParse);

}  // namespace
}  // namespace kinemo
