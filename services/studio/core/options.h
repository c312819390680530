// The studio's options (proto/kinemo/studio/v1/options.proto): defaults,
// bounds, and the folders it serves, resolved once at start.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/status/status.h"
#include "kinemo/studio/v1/options.pb.h"

namespace kinemo::studio {

inline constexpr std::uint32_t kDefaultPort = 8080;
inline constexpr std::uint64_t kDefaultMaxUploadBytes = 48ull << 20;
inline constexpr std::uint64_t kMaxUploadBytesLimit = 512ull << 20;

// Sets the studio's own defaults that a file may override (server.port 8080);
// call before loading the files.
void SetStudioDefaults(v1::StudioOptions* options);

// Fills zero fields with their defaults and checks every bound; messages
// name the field ("max_upload_bytes: ..."). `binary_path` is the running
// binary (/proc/self/exe), from which the page's and the samples' folders
// are found when not given; `source_dir` is the source tree ("" = none).
Status ResolveStudioOptions(const std::string& binary_path, const std::string& source_dir,
                            v1::StudioOptions* options);

}  // namespace kinemo::studio
