#include "services/prosody/core/face_corpus.h"

#include <algorithm>
#include <filesystem>

#include "common/audio/decode.h"
#include "common/audio/resample.h"
#include "common/audio/textgrid.h"
#include "common/face/jaw.h"
#include "common/motion/bvh.h"

namespace kinemo::prosody {

namespace fs = std::filesystem;

StatusOr<std::vector<double>> ReadJawOpenings(const std::string& path, double* frame_time_s) {
  KINEMO_ASSIGN_OR_RETURN(motion::Clip clip, motion::ReadBvhFile(path));
  const int j = clip.skeleton.FindJoint("jaw");
  if (j < 0) return InvalidField(path, "no joint called jaw (an SMPL-X skeleton has one)");
  const motion::Joint& joint = clip.skeleton.joint(j);
  std::array<int, 3> cols = {-1, -1, -1};  // Z, X, Y
  for (int c = 0; c < joint.num_channels(); ++c) {
    if (joint.channels[c] == motion::ChannelType::kZRotation) cols[0] = joint.first_channel + c;
    if (joint.channels[c] == motion::ChannelType::kXRotation) cols[1] = joint.first_channel + c;
    if (joint.channels[c] == motion::ChannelType::kYRotation) cols[2] = joint.first_channel + c;
  }
  if (cols[0] < 0 || cols[1] < 0 || cols[2] < 0) return InvalidField(path, "the jaw has no Z, X and Y rotation channels");
  std::vector<double> out(static_cast<std::size_t>(clip.num_frames()));
  for (int f = 0; f < clip.num_frames(); ++f) {
    const auto v = clip.frame(f);
    out[f] = face::SmplxJawOpeningDeg({v[cols[0]], v[cols[1]], v[cols[2]]});
  }
  *frame_time_s = clip.frame_time_s;
  return out;
}

StatusOr<FaceTrainingTake> ReadFaceTake(const std::string& dir, const std::string& name) {
  FaceTrainingTake t;
  t.name = name;
  const fs::path d(dir);
  KINEMO_ASSIGN_OR_RETURN(audio::DecodedAudio a, audio::DecodeAudioFile((d / (name + ".wav")).string()));
  if (a.sample_rate_hz != kFaceSampleRateHz) {
    KINEMO_ASSIGN_OR_RETURN(t.samples, audio::Resample(a.samples, a.sample_rate_hz, kFaceSampleRateHz));
  } else {
    t.samples = std::move(a.samples);
  }
  KINEMO_ASSIGN_OR_RETURN(t.jaw_open_deg, ReadJawOpenings((d / (name + ".bvh")).string(), &t.jaw_frame_time_s));
  KINEMO_ASSIGN_OR_RETURN(audio::TextGrid grid, audio::ReadTextGridFile((d / (name + ".TextGrid")).string()));
  const audio::TextGridTier* phones = grid.FindTier("phones");
  if (phones == nullptr || !phones->is_interval) return InvalidField(name + ".TextGrid", "no interval tier called phones");
  for (const audio::TextGridInterval& i : phones->intervals) t.phones.push_back({i.start_s, i.end_s, i.text});
  return t;
}

std::vector<std::string> FaceTakeNames(const std::string& dir) {
  std::vector<std::string> out;
  std::error_code ec;
  const fs::path d(dir);
  for (const auto& e : fs::directory_iterator(d, ec)) {
    if (e.path().extension() != ".wav") continue;
    const std::string stem = e.path().stem().string();
    if (fs::exists(d / (stem + ".bvh")) && fs::exists(d / (stem + ".TextGrid"))) out.push_back(stem);
  }
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace kinemo::prosody
