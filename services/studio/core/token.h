// Studio tokens: the random secret `kinemo studio` writes to its token file
// and the page's URL carries, and the loopback rule (no token file needed). Its own library (no Boost, no server), so the
// CLI that makes one does not build the studio's HTTP server.
#pragma once

#include <string>
#include <string_view>

namespace kinemo::studio {

// A new random token: 48 hex digits from the system's random source.
std::string NewToken();

// True for 127.0.0.0/8, ::1, [::1] and "localhost".
bool IsLoopbackHost(std::string_view host);

}  // namespace kinemo::studio
