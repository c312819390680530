// Fuzzes the VMC receiver's address (`kinemo animate --vmc`,
// StreamAnimateConfig.vmc.address): vmc::ParseEndpoint. Refusals are
// INVALID_ARGUMENT naming the option; an accepted address has a host of 1..253
// characters and a port in 1..65535, and its printed form (HOST:PORT, or
// [HOST]:PORT for a host with a colon) parses back to it.
#include <cstddef>
#include <cstdint>
#include <string>

#include "common/vmc/osc.h"
#include "tests/fuzz/fuzz_check.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using kinemo::fuzz::Text;
  const std::string_view text = Text(data, size);
  auto e = kinemo::vmc::ParseEndpoint(text, "--vmc");
  if (!e.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(e.status(), absl::StatusCode::kInvalidArgument);
    KINEMO_FUZZ_CHECK(e.status().message().substr(0, 7) == "--vmc: ", e.status().ToString());
    return 0;
  }
  KINEMO_FUZZ_CHECK(!e->host.empty() && e->host.size() <= 253, e->host);
  KINEMO_FUZZ_CHECK(e->port >= 1 && e->port <= 65535, std::to_string(e->port));
  const std::string printed = e->host.find(':') != std::string::npos
                                  ? "[" + e->host + "]:" + std::to_string(e->port)
                                  : e->host + ":" + std::to_string(e->port);
  auto again = kinemo::vmc::ParseEndpoint(printed, "--vmc");
  KINEMO_FUZZ_CHECK(again.ok() && again->host == e->host && again->port == e->port, printed);
  return 0;
}
