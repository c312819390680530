#include "common/testing/http.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdlib>

#include "absl/strings/str_cat.h"

namespace kinemo::testing {

StatusOr<std::string> HttpGet(const std::string& host, int port, const std::string& path,
                              std::chrono::milliseconds timeout) {
  addrinfo hints{};
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  if (getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &found) != 0 || found == nullptr) {
    return absl::UnavailableError(absl::StrCat("http: cannot resolve ", host));
  }
  const int fd = socket(found->ai_family, found->ai_socktype, found->ai_protocol);
  const bool connected = fd >= 0 && connect(fd, found->ai_addr, found->ai_addrlen) == 0;
  freeaddrinfo(found);
  if (!connected) {
    if (fd >= 0) close(fd);
    return absl::UnavailableError(absl::StrCat("http: cannot connect to ", host, ":", port));
  }
  const std::string request = absl::StrCat("GET ", path, " HTTP/1.0\r\nHost: ", host, "\r\n\r\n");
  if (send(fd, request.data(), request.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(request.size())) {
    close(fd);
    return absl::UnavailableError("http: send failed");
  }
  std::string response;
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  char buffer[16384];
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    pollfd p{fd, POLLIN, 0};
    if (left.count() <= 0 || poll(&p, 1, static_cast<int>(left.count())) <= 0) {
      close(fd);
      return absl::DeadlineExceededError(absl::StrCat("http: no complete answer from ", host, ":", port));
    }
    const ssize_t n = recv(fd, buffer, sizeof(buffer), 0);
    if (n < 0) {
      close(fd);
      return absl::UnavailableError("http: recv failed");
    }
    if (n == 0) break;
    response.append(buffer, static_cast<std::size_t>(n));
  }
  close(fd);
  const std::size_t header_end = response.find("\r\n\r\n");
  if (header_end == std::string::npos) return absl::InternalError("http: no header in the answer");
  const std::string status_line = response.substr(0, response.find("\r\n"));
  if (status_line.find(" 200") == std::string::npos) {
    return absl::InternalError(absl::StrCat("http: ", status_line));
  }
  return response.substr(header_end + 4);
}

double MetricSum(std::string_view exposition, std::string_view name,
                 const std::vector<std::pair<std::string, std::string>>& labels) {
  double sum = 0;
  std::size_t start = 0;
  while (start < exposition.size()) {
    std::size_t end = exposition.find('\n', start);
    if (end == std::string_view::npos) end = exposition.size();
    const std::string_view line = exposition.substr(start, end - start);
    start = end + 1;
    if (line.empty() || line.front() == '#') continue;
    if (line.substr(0, name.size()) != name) continue;
    const std::string_view rest = line.substr(name.size());
    if (rest.empty() || (rest.front() != '{' && rest.front() != ' ')) continue;  // a longer name
    std::string_view label_text;
    std::string_view value_text = rest;
    if (rest.front() == '{') {
      const std::size_t close = rest.find("} ");
      if (close == std::string_view::npos) continue;
      label_text = rest.substr(1, close - 1);
      value_text = rest.substr(close + 1);
    }
    bool match = true;
    for (const auto& [key, value] : labels) {
      if (label_text.find(key + "=\"" + value + "\"") == std::string_view::npos) match = false;
    }
    if (!match) continue;
    while (!value_text.empty() && value_text.front() == ' ') value_text.remove_prefix(1);
    value_text = value_text.substr(0, value_text.find(' '));
    const std::string number(value_text);
    char* parsed_end = nullptr;
    const double v = std::strtod(number.c_str(), &parsed_end);
    if (parsed_end != number.c_str()) sum += v;
  }
  return sum;
}

}  // namespace kinemo::testing
