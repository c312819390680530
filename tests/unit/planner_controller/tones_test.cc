// Tones from styled capture (services/planner/controller/tones.h) on real
// Bandai takes (tests/data/tones): estimation, bounds, the transfer to
// another library, and a controller built with transferred tones.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

#include "services/planner/controller/tones.h"
#include "tests/unit/planner_controller/test_util.h"

namespace kinemo::planner::controller {
namespace {

std::string TonesDir() { return std::string(KINEMO_TEST_DATA_DIR) + "/tones"; }

const std::vector<ToneTransfer>& Tones() {
  static const std::vector<ToneTransfer> t = [] {
    auto r = EstimateTones({TonesDir()}, DefaultToneEstimationOptions(), "paths");
    if (!r.ok()) throw std::runtime_error(std::string(r.status().message()));
    return *r;
  }();
  return t;
}

const ToneTransfer& Tone(const std::string& name) {
  for (const auto& t : Tones())
    if (t.name == name) return t;
  throw std::runtime_error("no tone " + name);
}

TEST(Tones, EstimatedFromTheStyledTakesOfTheSameActions) {
  ASSERT_EQ(Tones().size(), 4u);
  EXPECT_EQ(Tones()[0].name, "angry");
  EXPECT_EQ(Tones()[1].name, "energetic");
  EXPECT_EQ(Tones()[2].name, "happy");
  EXPECT_EQ(Tones()[3].name, "subdued");
  for (const auto& t : Tones()) {
    EXPECT_EQ(t.actions, (std::vector<std::string>{"bow", "bye", "byebye", "guide"})) << t.name;
    EXPECT_GE(t.neutral_segments, 12) << t.name;
    EXPECT_GE(t.tone_segments, 4) << t.name;
    EXPECT_TRUE(ValidateToneTransfer(t, "t").ok()) << t.name;
    EXPECT_TRUE(t.shift.isApprox(t.source_tone_mean - t.source_neutral_mean)) << t.name;
  }
  // What the styles look like (log scales: 0 T, 1 D, 2 V mean hand speed,
  // 3 A acceleration, 5 H hand height; docs/planner_controller.md has the
  // table): the active takes move the hands much faster (V ×1.95) and
  // further; the angry ones in shorter, slightly faster, more accelerated
  // strokes; the sad ones slower (V ×0.64), with a fifth of the acceleration
  // and lower hands.
  EXPECT_GT(Tone("energetic").shift(2), std::log(1.5));
  EXPECT_GT(Tone("energetic").shift(1), std::log(1.5));
  EXPECT_GT(Tone("angry").shift(2), 0.0);
  EXPECT_GT(Tone("angry").shift(3), 0.0);
  EXPECT_LT(Tone("angry").shift(0), std::log(0.9));
  EXPECT_LT(Tone("subdued").shift(2), std::log(0.75));
  EXPECT_LT(Tone("subdued").shift(3), std::log(0.5));
  EXPECT_LT(Tone("subdued").shift(5), 0.0);
}

TEST(Tones, TransferShiftsTheTargetMeanAndScalesAboutIt) {
  const ToneTransfer& t = Tone("energetic");
  const Vector6 target = (Vector6() << 0.1, -2.0, -1.0, 0.5, -0.5, 0.3).finished();
  const StyleTransform tr = ApplyTransfer(t, target);
  // The target's neutral mean goes to itself plus the source's styled-normal difference ...
  EXPECT_TRUE((tr.A * target + tr.b).isApprox(target + t.shift, 1e-12));
  // ... and a deviation from it is scaled by A, as on the source corpus.
  const Vector6 d = (Vector6() << 0.2, 0, 0, 0, 0, 0.1).finished();
  EXPECT_TRUE((tr.A * (target + d) + tr.b - (target + t.shift)).isApprox(t.A * d, 1e-12));
}

TEST(Tones, BadInputsNameTheField) {
  auto st = EstimateTones({}, DefaultToneEstimationOptions(), "--tones-from").status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("--tones-from"), std::string::npos) << st;
  st = EstimateTones({"/nonexistent/x"}, DefaultToneEstimationOptions(), "--tones-from").status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("--tones-from[0]"), std::string::npos) << st;
  // A file not named like the dataset.
  const std::string odd = ::testing::TempDir() + "/walk.bvh";
  std::ofstream(odd) << "HIERARCHY\n";
  st = EstimateTones({odd}, DefaultToneEstimationOptions(), "p").status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("p[0]"), std::string::npos) << st;
  // Only neutral takes: no tone to estimate.
  st = EstimateTones({TonesDir() + "/dataset-1_bow_normal_001.bvh"}, DefaultToneEstimationOptions(), "p").status();
  EXPECT_EQ(st.code(), absl::StatusCode::kFailedPrecondition) << st;
  // A styled take without a normal take of its action.
  st = EstimateTones({TonesDir() + "/dataset-1_bow_angry_001.bvh", TonesDir() + "/dataset-1_bye_normal_001.bvh"},
                     DefaultToneEstimationOptions(), "p")
           .status();
  EXPECT_EQ(st.code(), absl::StatusCode::kFailedPrecondition) << st;
  EXPECT_NE(st.message().find("angry"), std::string::npos) << st;

  ToneTransfer t = Tone("happy");
  t.name = "Happy!";
  EXPECT_NE(ValidateToneTransfer(t, "x").message().find("x.name"), std::string::npos);
  t = Tone("happy");
  t.A(0, 1) += 1;
  EXPECT_NE(ValidateToneTransfer(t, "x").message().find("x.a"), std::string::npos);
  t = Tone("happy");
  t.A *= 100;
  EXPECT_NE(ValidateToneTransfer(t, "x").message().find("eigenvalues"), std::string::npos);
  t = Tone("happy");
  t.shift(3) = std::nan("");
  EXPECT_NE(ValidateToneTransfer(t, "x").message().find("x.shift"), std::string::npos);

  ControllerParams p;
  p.tone_transfers = {Tone("happy"), Tone("happy")};
  EXPECT_NE(ValidateControllerParams(p).message().find("params.tone_transforms[1].name"), std::string::npos);
  p.tone_transfers = {Tone("happy")};
  p.tone_transfers[0].name = "neutral";
  EXPECT_NE(ValidateControllerParams(p).message().find("neutral tone"), std::string::npos);
}

// A library with only neutral clips gets the transferred tones beside its
// neutral one; their δ differ from neutral's, in the direction of the style:
// the segments the energetic tone favours are faster than the subdued ones'.
TEST(Tones, ControllerCarriesTransferredTones) {
  LibrarySources src;
  for (const char* f : {"dataset-1_bow_normal_001.bvh", "dataset-1_bye_normal_001.bvh",
                        "dataset-1_guide_normal_001.bvh", "dataset-1_byebye_normal_001.bvh"})
    src.paths.push_back(TonesDir() + "/" + f);
  auto lib = LoadLibrary("neutral-only", src);
  ASSERT_TRUE(lib.ok()) << lib.status();
  std::shared_ptr<const Library> library = *std::move(lib);
  ASSERT_EQ(library->tones(), std::vector<std::string>{"neutral"});
  const StateModel model = testing::FitStateModel(*library, 4);
  ControllerParams p;
  p.tone_transfers = Tones();
  auto c = Controller::Build(library, model, p, nullptr, nullptr);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ((*c)->style_tones(), (std::vector<std::string>{"angry", "energetic", "happy", "neutral", "subdued"}));
  // The segment each state's δ prefers, per tone: its mean V.
  auto preferred_v = [&](const std::string& tone) {
    const RowMatrix& d = (*c)->delta((*c)->ToneIndex(tone));
    double v = 0;
    for (int i = 0; i < d.cols(); ++i) {
      Eigen::Index best = 0;
      d.col(i).minCoeff(&best);
      v += (*c)->segments().segments[static_cast<size_t>(best)].params(2);
    }
    return v / static_cast<double>(d.cols());
  };
  EXPECT_GT(preferred_v("energetic"), preferred_v("subdued"));
  EXPECT_GT(preferred_v("angry"), preferred_v("subdued"));

  // Saved and loaded, the transfers come back with the tables.
  const std::string path = ::testing::TempDir() + "/tones.kctrl";
  ASSERT_TRUE((*c)->Save(path, src.paths, "model.kmodel").ok());
  auto l = Controller::Load(path);
  ASSERT_TRUE(l.ok()) << l.status();
  EXPECT_EQ((*l)->tones(), (*c)->tones());
  ASSERT_EQ((*l)->params().tone_transfers.size(), 4u);
  EXPECT_TRUE((*l)->params().tone_transfers[1].A.isApprox(Tones()[1].A));
  EXPECT_EQ((*l)->delta(1), (*c)->delta(1));
  std::remove(path.c_str());
}

}  // namespace
}  // namespace kinemo::planner::controller
