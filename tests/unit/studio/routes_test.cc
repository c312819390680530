// The studio's HTTP routes and origin check (services/studio/core/routes.h),
// over the real page folder and sample folders of the source tree.
#include "services/studio/core/routes.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "common/metrics/metrics.h"
#include "common/testing/process.h"
#include "services/studio/core/options.h"

namespace kinemo::studio {
namespace {

v1::StudioOptions RouteOptions() {
  v1::StudioOptions o;
  SetStudioDefaults(&o);
  o.set_static_dir(std::string(KINEMO_SOURCE_DIR) + "/services/studio/web");
  o.add_sample_dirs(std::string(KINEMO_SOURCE_DIR) + "/tests/data/speech");
  o.add_sample_dirs(std::string(KINEMO_SOURCE_DIR) + "/tests/data/planner_gesture");
  return o;
}

TEST(Router, ServesThePageHealthAndTheSocket) {
  const Router router(RouteOptions());
  const HttpReply page = router.Route("GET", "/");
  EXPECT_EQ(page.status, 200u);
  EXPECT_NE(page.file_path.find("services/studio/web/index.html"), std::string::npos);
  EXPECT_EQ(page.content_type, "text/html; charset=utf-8");
  EXPECT_TRUE(router.Route("GET", "/healthz?probe=1").health);
  EXPECT_TRUE(router.Route("GET", "/ws").websocket);
  EXPECT_EQ(router.Route("GET", "/static/studio.js").content_type, "text/javascript; charset=utf-8");
  EXPECT_EQ(router.Route("POST", "/").status, 405u);
  EXPECT_EQ(router.Route("GET", "/nowhere").status, 404u);
  // Prometheus' text format of the process' registry.
  metrics::Counter("kinemo_studio_test_total", "a counter of this test").Increment(3);
  const HttpReply m = router.Route("GET", "/metrics");
  EXPECT_EQ(m.status, 200u);
  EXPECT_EQ(m.content_type.rfind("text/plain; version=0.0.4", 0), 0u);
  EXPECT_NE(m.body.find("kinemo_studio_test_total 3"), std::string::npos) << m.body;
}

TEST(Router, RefusesPathsOutsideItsFolders) {
  const Router router(RouteOptions());
  for (const char* target : {"/static/../CMakeLists.txt", "/static/%2e%2e/CMakeLists.txt", "/static/.hidden",
                             "/static//etc/passwd", "/static/web%00.js", "/samples/..%2fLICENSE.md",
                             "/static/%zz"}) {
    const HttpReply r = router.Route("GET", target);
    EXPECT_TRUE(r.file_path.empty()) << target << " -> " << r.file_path;
    EXPECT_TRUE(r.status == 404u || r.status == 400u) << target << " -> " << r.status;
  }
}

// GET /cube/ar/<kind>/<name>.webm: a drawn AR video of cube_dir, 404 until
// it is there, 400 for anything that is not such a name (no other file).
TEST(Router, ServesTheCubeArVideosByNameOnly) {
  kinemo::testing::TempDir dir;
  v1::StudioOptions o = RouteOptions();
  o.set_cube_dir(dir.path());
  std::filesystem::create_directories(dir.File("bundled"));
  std::ofstream(dir.File("bundled/tone_scenario.ar.webm")) << "\x1a\x45\xdf\xa3";
  std::ofstream(dir.File("secret.webm")) << "x";
  const Router router(o);
  const HttpReply r = router.Route("GET", "/cube/ar/bundled/tone_scenario.webm");
  EXPECT_EQ(r.status, 200u);
  EXPECT_EQ(r.content_type, "video/webm");
  EXPECT_EQ(r.file_path, dir.File("bundled/tone_scenario.ar.webm"));
  EXPECT_EQ(router.Route("HEAD", "/cube/ar/bundled/tone_scenario.webm?t=1").file_path, r.file_path);
  EXPECT_EQ(router.Route("GET", "/cube/ar/bundled/other.webm").status, 404u);
  EXPECT_EQ(router.Route("GET", "/cube/ar/uploads/0123abcd.webm").status, 404u);
  for (const char* target : {"/cube/ar/bundled/../secret.webm", "/cube/ar/bundled/%2e%2e%2fsecret.webm",
                             "/cube/ar/../secret.webm", "/cube/ar/secret.webm", "/cube/ar/bundled/tone_scenario.avi",
                             "/cube/ar/bundled/tone_scenario.ar.webm", "/cube/ar/other/tone_scenario.webm",
                             "/cube/ar/bundled/.webm", "/cube/ar/bundled/a%00.webm", "/cube/ar/bundled/%zz.webm",
                             "/cube/ar/bundled/x/y.webm", "/cube/ar/"}) {
    const HttpReply bad = router.Route("GET", target);
    EXPECT_TRUE(bad.file_path.empty()) << target << " -> " << bad.file_path;
    EXPECT_EQ(bad.status, 400u) << target;
  }
  // Without cube_dir there are none.
  const Router none(RouteOptions());
  EXPECT_EQ(none.Route("GET", "/cube/ar/bundled/tone_scenario.webm").status, 404u);
}

TEST(Router, ListsAndServesTheSamples) {
  const Router router(RouteOptions());
  const auto list = nlohmann::json::parse(router.Route("GET", "/samples/").body)["samples"];
  int wavs = 0, bvhs = 0;
  for (const auto& s : list) (s["kind"] == "wav" ? wavs : bvhs) += 1;
  EXPECT_EQ(wavs, 5);
  EXPECT_GE(bvhs, 5);
  const HttpReply wav = router.Route("GET", "/samples/sense_and_sensibility_01_austen_64kb-0870.wav");
  EXPECT_EQ(wav.content_type, "audio/wav");
  EXPECT_NE(wav.file_path.find("tests/data/speech/"), std::string::npos);
}

TEST(OriginAllowed, SameOriginByDefaultElseTheList) {
  EXPECT_TRUE(OriginAllowed("", "127.0.0.1:8080", {}));  // not a browser
  EXPECT_TRUE(OriginAllowed("http://127.0.0.1:8080", "127.0.0.1:8080", {}));
  EXPECT_TRUE(OriginAllowed("http://LOCALHOST:8080", "localhost:8080", {}));
  EXPECT_FALSE(OriginAllowed("http://evil.example", "127.0.0.1:8080", {}));
  EXPECT_FALSE(OriginAllowed("http://127.0.0.1:9999", "127.0.0.1:8080", {}));
  EXPECT_FALSE(OriginAllowed("null", "127.0.0.1:8080", {}));
  EXPECT_TRUE(OriginAllowed("http://studio.example:8080", "10.0.0.2:8080", {"http://studio.example:8080"}));
  EXPECT_FALSE(OriginAllowed("http://127.0.0.1:8080", "127.0.0.1:8080", {"http://studio.example:8080"}));
  EXPECT_TRUE(OriginAllowed("http://any.example", "127.0.0.1:8080", {"*"}));
}

}  // namespace
}  // namespace kinemo::studio
