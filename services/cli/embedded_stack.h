// The embedded stack of `kinemo animate` and `kinemo bench e2e`: a
// kinemo_allinone child on an ephemeral loopback port, used when no
// coordinator answers (or when asked).
#pragma once

#include <memory>
#include <string>

#include "common/process/process.h"

namespace kinemo::cli {

// Where a kinemo binary is: beside this one, in the build tree's
// services/<build_dir>, or on PATH. "" if not found.
std::string FindKinemoBinary(const std::string& name, const std::string& build_dir);

// Options of the embedded kinemo_allinone when none are given: the bundled
// gesture library and a BodySpeech gesture graph over it ("bundled").
// `max_streams` > 0 sets animate.max_concurrent_streams and the prosody
// service's max_concurrent_streams.
std::string DefaultAllInOneConfig(const std::string& command, std::uint32_t max_streams = 0);

// A file of the bundled data (the folder holding the bundled gesture
// library, e.g. the source tree's tests/data): "cube/vleo.cube" -> its path,
// or "" if there is none.
std::string BundledDataFile(const std::string& relative);

// True if a gRPC server accepts a connection at `address` within timeout_s.
bool Reachable(const std::string& address, double timeout_s);

// A kinemo_allinone child, ready (health SERVING) when Start returns;
// SIGTERM on scope exit.
class EmbeddedStack {
 public:
  // `config`: the all-in-one's options file; "" = the bundled gesture
  // library and a BodySpeech gesture graph over it ("bundled"). Returns the
  // address, or "" after printing why it could not start ("kinemo
  // <command>: ..."). `max_streams` > 0 sets the default options'
  // animate.max_concurrent_streams and the prosody service's
  // max_concurrent_streams (a given `config` keeps its own).
  std::string Start(const std::string& command, const std::string& config, double timeout_s,
                    std::uint32_t max_streams = 0);
  // The child's process id (after Start).
  pid_t pid() const { return stack_ ? stack_->process().pid() : 0; }

 private:
  process::TempDir dir_;
  std::unique_ptr<process::ServiceProcess> stack_;
};

}  // namespace kinemo::cli
