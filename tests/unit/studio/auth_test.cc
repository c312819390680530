// The studio's authentication (services/studio/core/auth.h) and its options
// (StudioAuth in options.proto, resolved by ResolveStudioOptions).
#include "services/studio/core/auth.h"

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>

#include "common/testing/process.h"
#include "services/studio/core/options.h"

namespace kinemo::studio {
namespace {

using Outcome = Authenticator::Outcome;
constexpr char kToken[] = "0123456789abcdef0123456789abcdef";

TEST(ConstantTimeEquals, EqualOnlyForTheSameBytes) {
  EXPECT_TRUE(ConstantTimeEquals(kToken, kToken));
  EXPECT_FALSE(ConstantTimeEquals(kToken, "0123456789abcdef0123456789abcdeF"));
  EXPECT_FALSE(ConstantTimeEquals(kToken, "0123456789abcdef"));
  EXPECT_FALSE(ConstantTimeEquals("0123456789abcdef", kToken));
  EXPECT_FALSE(ConstantTimeEquals(kToken, ""));
  EXPECT_FALSE(ConstantTimeEquals("", kToken));
  EXPECT_TRUE(ConstantTimeEquals("", ""));
}

TEST(NewToken, FortyEightHexDigitsEachTimeDifferent) {
  const std::string a = NewToken(), b = NewToken();
  EXPECT_EQ(a.size(), 48u);
  EXPECT_EQ(a.find_first_not_of("0123456789abcdef"), std::string::npos);
  EXPECT_NE(a, b);
}

TEST(IsLoopbackHost, LoopbackAddressesOnly) {
  for (const char* h : {"127.0.0.1", "127.1.2.3", "::1", "[::1]", "localhost"}) EXPECT_TRUE(IsLoopbackHost(h)) << h;
  for (const char* h : {"0.0.0.0", "::", "10.0.0.1", "192.168.1.2", "studio.example", "", "128.0.0.1"}) {
    EXPECT_FALSE(IsLoopbackHost(h)) << h;
  }
}

TEST(Parsing, CookieAndQueryValues) {
  EXPECT_EQ(CookieValue("a=1; kinemo-studio-8080=xyz; b=2", "kinemo-studio-8080"), "xyz");
  EXPECT_EQ(CookieValue("kinemo-studio-80=xyz", "kinemo-studio-8080"), "");
  EXPECT_EQ(CookieValue("", "x"), "");
  EXPECT_EQ(QueryValue("/?token=abc&x=1", "token"), "abc");
  EXPECT_EQ(QueryValue("/static/a.js?x=1&token=a%2Db", "token"), "a-b");
  EXPECT_EQ(QueryValue("/?tokens=abc", "token"), "");
  EXPECT_EQ(QueryValue("/", "token"), "");
  EXPECT_EQ(WithoutQueryParam("/?token=abc", "token"), "/");
  EXPECT_EQ(WithoutQueryParam("/p?x=1&token=abc&y=2", "token"), "/p?x=1&y=2");
}

TEST(Authenticator, CookieHeaderOrUrlElse401) {
  Authenticator auth(kToken, 10, 8080, false);
  const std::string cookie = std::string("kinemo-studio-8080=") + kToken;
  EXPECT_EQ(auth.Check("127.0.0.1", cookie, "", "/"), Outcome::kAllowed);
  EXPECT_EQ(auth.Check("127.0.0.1", "", std::string("Bearer ") + kToken, "/samples/"), Outcome::kAllowed);
  EXPECT_EQ(auth.Check("127.0.0.1", "", std::string("bearer  ") + kToken, "/ws"), Outcome::kAllowed);
  EXPECT_EQ(auth.Check("127.0.0.1", "", "", std::string("/?token=") + kToken), Outcome::kAllowedFromUrl);
  EXPECT_EQ(auth.Check("127.0.0.1", "", "", "/"), Outcome::kMissing);
  EXPECT_EQ(auth.Check("127.0.0.1", "", std::string("Basic ") + kToken, "/"), Outcome::kMissing);
  // The cookie of a studio on another port is not this one's.
  EXPECT_EQ(auth.Check("127.0.0.1", std::string("kinemo-studio-8081=") + kToken, "", "/"), Outcome::kMissing);
  EXPECT_EQ(auth.Check("127.0.0.1", "", "Bearer wrong", "/"), Outcome::kWrong);
  const std::string set = auth.SetCookieValue();
  EXPECT_EQ(set.rfind(cookie + ";", 0), 0u) << set;
  EXPECT_NE(set.find("HttpOnly"), std::string::npos);
  EXPECT_NE(set.find("SameSite=Strict"), std::string::npos);
  EXPECT_EQ(set.find("Secure"), std::string::npos);
  EXPECT_NE(Authenticator(kToken, 10, 8443, true).SetCookieValue().find("; Secure"), std::string::npos);
}

TEST(Authenticator, FailuresThrottledPerAddressThenForgiven) {
  Authenticator auth(kToken, 10, 8080, false);
  const auto t0 = Authenticator::Clock::now();
  int wrong = 0, throttled = 0;
  for (int i = 0; i < 1000; ++i) {
    const Outcome o = auth.Check("10.0.0.7", "", "Bearer guess" + std::to_string(i), "/", t0);
    wrong += o == Outcome::kWrong;
    throttled += o == Outcome::kThrottled;
  }
  EXPECT_EQ(wrong, 10);
  EXPECT_EQ(throttled, 990);
  // Throttled means not checked: the right token is refused too.
  EXPECT_EQ(auth.Check("10.0.0.7", "", std::string("Bearer ") + kToken, "/", t0), Outcome::kThrottled);
  EXPECT_EQ(auth.RetryAfterSeconds("10.0.0.7", t0), 6);
  // Other addresses are not.
  EXPECT_EQ(auth.Check("10.0.0.8", "", std::string("Bearer ") + kToken, "/", t0), Outcome::kAllowed);
  EXPECT_EQ(auth.RetryAfterSeconds("10.0.0.8", t0), 0);
  // Missing credentials are not failures.
  for (int i = 0; i < 100; ++i) EXPECT_EQ(auth.Check("10.0.0.9", "", "", "/", t0), Outcome::kMissing);
  // One failure is forgiven every 6 s (10 per minute).
  EXPECT_EQ(auth.Check("10.0.0.7", "", std::string("Bearer ") + kToken, "/", t0 + std::chrono::seconds(6)),
            Outcome::kAllowed);
  EXPECT_EQ(auth.Check("10.0.0.7", "", "Bearer nope", "/", t0 + std::chrono::seconds(6)), Outcome::kWrong);
  EXPECT_EQ(auth.Check("10.0.0.7", "", "Bearer nope", "/", t0 + std::chrono::seconds(7)), Outcome::kThrottled);
}

v1::StudioOptions Resolvable() {
  v1::StudioOptions o;
  SetStudioDefaults(&o);
  o.set_static_dir(std::string(KINEMO_SOURCE_DIR) + "/services/studio/web");
  o.set_libs_dir(std::string(KINEMO_SOURCE_DIR) + "/services/studio/web");
  o.add_sample_dirs(std::string(KINEMO_SOURCE_DIR) + "/tests/data/speech");
  return o;
}

TEST(StudioAuthOptions, LoopbackMakesATokenOtherHostsNeedOne) {
  v1::StudioOptions o = Resolvable();
  ASSERT_TRUE(ResolveStudioOptions("/nowhere/bin/studio", "", &o).ok());
  EXPECT_EQ(o.auth().token().size(), 48u);
  EXPECT_EQ(o.auth().max_failures_per_minute(), 10u);

  o = Resolvable();
  o.mutable_server()->set_host("0.0.0.0");
  const Status s = ResolveStudioOptions("/nowhere/bin/studio", "", &o);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message().rfind("auth.token: ", 0), 0u) << s.message();
  EXPECT_NE(s.message().find("auth.token_file"), std::string::npos) << s.message();

  o = Resolvable();
  o.mutable_server()->set_host("0.0.0.0");
  o.mutable_auth()->set_token(kToken);
  EXPECT_TRUE(ResolveStudioOptions("/nowhere/bin/studio", "", &o).ok());
  EXPECT_EQ(o.auth().token(), kToken);
}

TEST(StudioAuthOptions, TokenFileAndBounds) {
  testing::TempDir dir;
  const std::string file = dir.File("token");
  std::ofstream(file) << "  " << kToken << "\n\n";
  v1::StudioOptions o = Resolvable();
  o.mutable_server()->set_host("::");
  o.mutable_auth()->set_token_file(file);
  ASSERT_TRUE(ResolveStudioOptions("/nowhere/bin/studio", "", &o).ok());
  EXPECT_EQ(o.auth().token(), kToken);

  struct Case {
    const char* token;
    const char* token_file;
    std::uint32_t max_failures;
    const char* field;
  };
  const std::string missing = dir.File("missing");
  const std::string empty = dir.File("empty");
  std::ofstream(empty) << "\n";
  const std::string spaced = dir.File("spaced");
  std::ofstream(spaced) << "0123456789 abcdef0123456789\n";
  for (const Case& c : {Case{"short", "", 0, "auth.token"}, Case{"0123456789abcdef;x", "", 0, "auth.token"},
                        Case{"", missing.c_str(), 0, "auth.token_file"}, Case{"", empty.c_str(), 0, "auth.token_file"},
                        Case{"", spaced.c_str(), 0, "auth.token_file"},
                        Case{kToken, "", 10001, "auth.max_failures_per_minute"}}) {
    o = Resolvable();
    o.mutable_auth()->set_token(c.token);
    o.mutable_auth()->set_token_file(c.token_file);
    o.mutable_auth()->set_max_failures_per_minute(c.max_failures);
    const Status s = ResolveStudioOptions("/nowhere/bin/studio", "", &o);
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << c.field;
    EXPECT_EQ(s.message().rfind(std::string(c.field) + ": ", 0), 0u) << s.message();
  }
}

}  // namespace
}  // namespace kinemo::studio
