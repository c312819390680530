// Retargeting benchmarks (common/retarget): 60 s of BEAT2 SMPL-X motion (55
// joints, 30 fps: 1800 frames) onto the Quaternius man (49 joints) — the
// whole clip, with and without foot planting (target: ≤ 0.2 s of one core
// for the clip) — and the per-frame cost a live stream pays
// (Retargeter::RetargetFrame, planting on). Data from tests/data (the
// characters are there; ../shared/data/characters holds the same files).
// Counters: frames_per_s, ms_per_frame for the per-frame case.
#include <benchmark/benchmark.h>

#include <string>

#include "common/motion/bvh.h"
#include "common/retarget/face_map.h"
#include "common/retarget/gltf.h"
#include "common/retarget/retarget.h"
#include "common/retarget/rig.h"

namespace kinemo::retarget {
namespace {

struct Inputs {
  motion::Clip clip;  // 60 s
  Rig source, man;
  bool ok = false;
};

const Inputs& Data() {
  static const Inputs* const in = [] {
    auto* d = new Inputs;
    const std::string dir = KINEMO_TEST_DATA_DIR;
    auto clip = motion::ReadBvhFile(dir + "/paired/beat2/2_scott_0_1_1.bvh");
    auto man = LoadGltfRig(dir + "/characters/quaternius_man_casual.glb");
    if (!clip.ok() || !man.ok()) return d;
    const int frames = static_cast<int>(60.0 / clip->frame_time_s + 0.5);
    if (clip->num_frames() < frames) return d;
    clip->frames.conservativeResize(frames, clip->frames.cols());
    auto source = RigFromSkeleton(clip->skeleton, 0.01, "smplx");
    if (!source.ok()) return d;
    d->clip = *std::move(clip);
    d->source = *std::move(source);
    d->man = *std::move(man);
    d->ok = true;
    return d;
  }();
  return *in;
}

void BM_RetargetSmplx60sOntoQuaterniusMan(benchmark::State& state) {
  const Inputs& in = Data();
  if (!in.ok) {
    state.SkipWithError("tests/data BEAT2 take or character missing");
    return;
  }
  RetargetOptions options;
  options.plant_feet = state.range(0) != 0;
  for (auto _ : state) {
    auto rt = Retargeter::Create(in.clip.skeleton, in.source, in.man, options);
    auto out = rt->RetargetClip(in.clip);
    benchmark::DoNotOptimize(out->frames.data());
  }
  state.counters["frames_per_s"] =
      benchmark::Counter(static_cast<double>(in.clip.num_frames()) * state.iterations(), benchmark::Counter::kIsRate);
  state.SetLabel(options.plant_feet ? "60 s, 1800 frames, feet planted" : "60 s, 1800 frames, transfer only");
}
BENCHMARK(BM_RetargetSmplx60sOntoQuaterniusMan)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// One frame, as StreamAnimate would pay it.
void BM_RetargetFrame(benchmark::State& state) {
  const Inputs& in = Data();
  if (!in.ok) {
    state.SkipWithError("tests/data BEAT2 take or character missing");
    return;
  }
  auto rt = Retargeter::Create(in.clip.skeleton, in.source, in.man, {});
  std::vector<double> out(static_cast<size_t>(in.man.skeleton.num_channels()));
  int f = 0;
  for (auto _ : state) {
    auto s = rt->RetargetFrame(in.clip.frame(f), out);
    benchmark::DoNotOptimize(s);
    f = (f + 1) % in.clip.num_frames();
  }
  state.counters["frames_per_s"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_RetargetFrame)->Unit(benchmark::kMicrosecond);

// Reading a character as every reader does (ReadGltf: decoding included,
// then the rig and its face map): the plain Quaternius man, its Draco and
// meshopt copies, the VALID man (2.0 MB of meshopt + quantization -> 22 MB).
void BM_ReadCharacter(benchmark::State& state) {
  static const char* const kFiles[] = {"characters/quaternius_man_casual.glb",
                                       "characters/formats/quaternius_man_draco.glb",
                                       "characters/formats/quaternius_man_meshopt.glb",
                                       "characters/valid_white_m_1_casual.glb", "characters/godette.vrm"};
  const std::string path = std::string(KINEMO_TEST_DATA_DIR) + "/" + kFiles[state.range(0)];
  for (auto _ : state) {
    auto src = ReadGltf(path);
    if (!src.ok()) {
      state.SkipWithError(std::string(src.status().message()).c_str());
      return;
    }
    auto rig = RigFromGltf(*src);
    auto face = rig.ok() ? FaceMap::Create(*rig) : StatusOr<FaceMap>(rig.status());
    benchmark::DoNotOptimize(face.ok());
  }
  state.SetLabel(kFiles[state.range(0)]);
}
BENCHMARK(BM_ReadCharacter)->DenseRange(0, 4)->Unit(benchmark::kMillisecond);

// A face frame onto the VALID man's 96 controls and 96 morph weights, as the
// studio (Weights) and the GLB writer (MorphWeights) pay it per frame.
void BM_FaceWeightsValid(benchmark::State& state) {
  static const auto* const map = [] {
    auto rig = LoadGltfRig(std::string(KINEMO_TEST_DATA_DIR) + "/characters/valid_white_m_1_casual.glb");
    auto m = rig.ok() ? FaceMap::Create(*rig) : StatusOr<FaceMap>(rig.status());
    return m.ok() ? new FaceMap(*std::move(m)) : nullptr;
  }();
  if (map == nullptr) {
    state.SkipWithError("the VALID man does not load");
    return;
  }
  face::FaceFrame frame;
  frame.ovr[static_cast<size_t>(face::OvrViseme::kAA)] = 0.7f;
  frame.ovr[static_cast<size_t>(face::OvrViseme::kPP)] = 0.3f;
  frame.jaw_open_deg = 8;
  std::vector<float> weights(map->controls().size()), morphs(static_cast<size_t>(map->num_morph_weights()));
  for (auto _ : state) {
    map->Weights(frame, weights);
    map->MorphWeights(weights, morphs);
    benchmark::DoNotOptimize(morphs.data());
  }
}
BENCHMARK(BM_FaceWeightsValid)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace kinemo::retarget
