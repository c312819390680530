#include "services/pleo_sim/server.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <thread>

#include "absl/strings/str_cat.h"

namespace kinemo::pleo_sim {

namespace reg = robot::reg;
using robot::SimFault;

namespace {

bool IsWrite(uint8_t fc) {
  return fc == MODBUS_FC_WRITE_SINGLE_REGISTER || fc == MODBUS_FC_WRITE_MULTIPLE_REGISTERS ||
         fc == MODBUS_FC_WRITE_AND_READ_REGISTERS;
}

}  // namespace

PleoSimServer::PleoSimServer(ServerOptions options) : options_(std::move(options)) {
  firmware_ = std::make_unique<PleoFirmware>(options_.firmware, PleoFirmware::Clock::now());
  uint16_t* h = firmware_->mapping()->tab_registers;
  h[reg::kSimFaultMode] = static_cast<uint16_t>(options_.fault);
  h[reg::kSimFaultDelayMs] = static_cast<uint16_t>(std::clamp(options_.fault_delay_ms, 0, 10000));
  h[reg::kSimFaultCount] = static_cast<uint16_t>(std::clamp(options_.fault_count, 0, 65535));
  if (pipe2(wake_, O_CLOEXEC | O_NONBLOCK) != 0) wake_[0] = wake_[1] = -1;
}

PleoSimServer::~PleoSimServer() {
  for (int fd : clients_) close(fd);
  if (listen_fd_ >= 0) close(listen_fd_);
  if (ctx_ != nullptr) {
    if (!options_.tcp) modbus_close(ctx_);
    modbus_free(ctx_);
  }
  if (wake_[0] >= 0) close(wake_[0]);
  if (wake_[1] >= 0) close(wake_[1]);
}

void PleoSimServer::Log(const char* fmt, ...) const {
  if (!options_.verbose) return;
  va_list ap;
  va_start(ap, fmt);
  std::fputs("pleo_sim: ", stderr);
  std::vfprintf(stderr, fmt, ap);
  std::fputc('\n', stderr);
  va_end(ap);
}

void PleoSimServer::Stop() {
  if (wake_[1] >= 0) {
    char c = 'x';
    ssize_t n = write(wake_[1], &c, 1);
    (void)n;
  }
}

Status PleoSimServer::Open() {
  if (wake_[0] < 0) return absl::InternalError("pleo_sim: cannot create wake pipe");
  if (options_.unit_id < 1 || options_.unit_id > 247) {
    return absl::InvalidArgumentError(absl::StrCat("unit: ", options_.unit_id, " is outside 1..247"));
  }
  if (options_.tcp) {
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
    addrinfo* res = nullptr;
    std::string port = std::to_string(options_.port);
    int rc = getaddrinfo(options_.host.c_str(), port.c_str(), &hints, &res);
    if (rc != 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("tcp: cannot resolve '", options_.host, "': ", gai_strerror(rc)));
    }
    int fd = socket(res->ai_family, res->ai_socktype | SOCK_CLOEXEC, res->ai_protocol);
    int one = 1;
    if (fd >= 0) setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
    if (fd < 0 || bind(fd, res->ai_addr, res->ai_addrlen) != 0 || listen(fd, 16) != 0) {
      int err = errno;
      if (fd >= 0) close(fd);
      freeaddrinfo(res);
      return absl::UnavailableError(absl::StrCat("tcp: cannot listen on ", options_.host, ":",
                                                 options_.port, ": ", std::strerror(err)));
    }
    freeaddrinfo(res);
    sockaddr_storage ss{};
    socklen_t len = sizeof(ss);
    getsockname(fd, reinterpret_cast<sockaddr*>(&ss), &len);
    port_ = ntohs(ss.ss_family == AF_INET6 ? reinterpret_cast<sockaddr_in6*>(&ss)->sin6_port
                                           : reinterpret_cast<sockaddr_in*>(&ss)->sin_port);
    listen_fd_ = fd;
    // The context only frames requests and replies; sockets are ours.
    ctx_ = modbus_new_tcp("127.0.0.1", port_);
    if (ctx_ == nullptr) return absl::InternalError("tcp: cannot create libmodbus context");
  } else {
    ctx_ = modbus_new_rtu(options_.device.c_str(), options_.baud, options_.parity, 8, 1);
    if (ctx_ == nullptr) {
      return absl::InvalidArgumentError(
          absl::StrCat("rtu: bad settings for '", options_.device, "': ", modbus_strerror(errno)));
    }
    modbus_set_slave(ctx_, options_.unit_id);
    if (modbus_connect(ctx_) == -1) {
      return absl::UnavailableError(
          absl::StrCat("rtu: cannot open '", options_.device, "': ", modbus_strerror(errno)));
    }
    modbus_flush(ctx_);
  }
  // Frames whose bytes stop arriving are dropped after this gap.
  modbus_set_byte_timeout(ctx_, 0, 100000);
  return absl::OkStatus();
}

Status PleoSimServer::Run() {
  if (ctx_ == nullptr) KINEMO_RETURN_IF_ERROR(Open());
  return options_.tcp ? RunTcp() : RunRtu();
}

void PleoSimServer::SendCorrupted(int fd, const uint8_t* req, int length) {
  // Build the correct answer on a socket pair, then damage it: a bad
  // transaction id on TCP, a bad CRC on RTU.
  int sp[2];
  if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sp) != 0) return;
  modbus_set_socket(ctx_, sp[0]);
  int n = modbus_reply(ctx_, req, length, firmware_->mapping());
  modbus_set_socket(ctx_, fd);
  uint8_t buf[MODBUS_MAX_ADU_LENGTH + 16];
  ssize_t got = n > 0 ? recv(sp[1], buf, sizeof(buf), MSG_DONTWAIT) : 0;
  close(sp[0]);
  close(sp[1]);
  if (got <= 0) return;
  if (options_.tcp) {
    buf[0] ^= 0x5A;
    buf[1] ^= 0xA5;
  } else {
    buf[got - 1] ^= 0xFF;
  }
  ssize_t w = options_.tcp ? send(fd, buf, got, MSG_NOSIGNAL) : write(fd, buf, got);
  (void)w;
}

PleoSimServer::Outcome PleoSimServer::Handle(int fd, const uint8_t* req, int length) {
  const int h = modbus_get_header_length(ctx_);
  const uint8_t fc = req[h];
  const auto now = PleoFirmware::Clock::now();
  firmware_->Tick(now);

  // Requests that touch the fault-control block are always answered.
  bool touches_sim = false;
  if (length >= h + 5 && (fc == MODBUS_FC_READ_HOLDING_REGISTERS || IsWrite(fc))) {
    int addr = ModbusWord(req + h + 1);
    if (fc == MODBUS_FC_WRITE_AND_READ_REGISTERS && length >= h + 9) addr = ModbusWord(req + h + 5);
    touches_sim = addr >= reg::kSimBase;
  }
  if (!touches_sim) {
    const SimFault fault = firmware_->fault_mode();
    if (fault != SimFault::kNone) {
      const int delay_ms = firmware_->fault_delay_ms();
      firmware_->ConsumeFault();
      Log("fault %d on function 0x%02x", static_cast<int>(fault), fc);
      switch (fault) {
        case SimFault::kNone:
          break;
        case SimFault::kDelay:
          std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
          break;
        case SimFault::kDrop:
          return options_.tcp ? Outcome::kClose : Outcome::kAnswered;
        case SimFault::kSilent:
          return Outcome::kAnswered;
        case SimFault::kBusy:
          modbus_reply_exception(ctx_, req, MODBUS_EXCEPTION_SLAVE_OR_SERVER_BUSY);
          return Outcome::kAnswered;
        case SimFault::kCorrupt:
          if (firmware_->Check(req, length, h) == 0) {
            SendCorrupted(fd, req, length);
            if (IsWrite(fc)) {
              int addr = ModbusWord(req + h + 1), count = fc == MODBUS_FC_WRITE_SINGLE_REGISTER ? 1 : ModbusWord(req + h + 3);
              if (fc == MODBUS_FC_WRITE_AND_READ_REGISTERS) {
                addr = ModbusWord(req + h + 5);
                count = ModbusWord(req + h + 7);
              }
              firmware_->OnHoldingWritten(addr, count, now);
            }
          }
          return Outcome::kAnswered;
        case SimFault::kNoise: {
          uint8_t noise[16];
          for (uint8_t& b : noise) {
            noise_state_ = noise_state_ * 1103515245u + 12345u;
            b = static_cast<uint8_t>(noise_state_ >> 16);
          }
          ssize_t w = options_.tcp ? send(fd, noise, sizeof(noise), MSG_NOSIGNAL)
                                   : write(fd, noise, sizeof(noise));
          (void)w;
          break;
        }
      }
    }
  }

  int exception = firmware_->Check(req, length, h);
  if (exception != 0) {
    Log("refusing function 0x%02x: exception %d", fc, exception);
    if (IsWrite(fc)) firmware_->OnRefused();
    modbus_reply_exception(ctx_, req, static_cast<unsigned>(exception));
    return Outcome::kAnswered;
  }
  if (modbus_reply(ctx_, req, length, firmware_->mapping()) == -1) {
    Log("reply failed: %s", modbus_strerror(errno));
    return options_.tcp ? Outcome::kClose : Outcome::kAnswered;
  }
  if (IsWrite(fc)) {
    int addr = ModbusWord(req + h + 1);
    int count = fc == MODBUS_FC_WRITE_SINGLE_REGISTER ? 1 : ModbusWord(req + h + 3);
    if (fc == MODBUS_FC_WRITE_AND_READ_REGISTERS) {
      addr = ModbusWord(req + h + 5);
      count = ModbusWord(req + h + 7);
    }
    firmware_->OnHoldingWritten(addr, count, now);
  }
  return Outcome::kAnswered;
}

Status PleoSimServer::RunTcp() {
  uint8_t query[MODBUS_TCP_MAX_ADU_LENGTH];
  for (;;) {
    fd_set rfds;
    FD_ZERO(&rfds);
    FD_SET(wake_[0], &rfds);
    FD_SET(listen_fd_, &rfds);
    int maxfd = std::max(wake_[0], listen_fd_);
    for (int fd : clients_) {
      FD_SET(fd, &rfds);
      maxfd = std::max(maxfd, fd);
    }
    timeval tv{0, TickTimeoutMs() * 1000};
    int n = select(maxfd + 1, &rfds, nullptr, nullptr, &tv);
    if (n < 0 && errno != EINTR) {
      return absl::InternalError(absl::StrCat("select: ", std::strerror(errno)));
    }
    if (n > 0) {
      if (FD_ISSET(wake_[0], &rfds)) return absl::OkStatus();
      if (FD_ISSET(listen_fd_, &rfds)) {
        int fd = accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
        if (fd >= 0) {
          if (fd >= FD_SETSIZE) {
            close(fd);
          } else {
            int one = 1;
            setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
            clients_.push_back(fd);
            Log("client %d connected (%zu open)", fd, clients_.size());
          }
        }
      }
      std::vector<int> closed;
      for (int fd : clients_) {
        if (!FD_ISSET(fd, &rfds)) continue;
        modbus_set_socket(ctx_, fd);
        int rc = modbus_receive(ctx_, query);
        if (rc == -1) {
          closed.push_back(fd);  // peer closed, or a malformed frame on a stream
          continue;
        }
        if (rc == 0) continue;
        if (Handle(fd, query, rc) == Outcome::kClose) closed.push_back(fd);
      }
      for (int fd : closed) {
        close(fd);
        clients_.erase(std::find(clients_.begin(), clients_.end(), fd));
        Log("client %d closed (%zu open)", fd, clients_.size());
      }
    }
    firmware_->Tick(PleoFirmware::Clock::now());
  }
}

Status PleoSimServer::RunRtu() {
  uint8_t query[MODBUS_RTU_MAX_ADU_LENGTH];
  const int fd = modbus_get_socket(ctx_);
  for (;;) {
    fd_set rfds;
    FD_ZERO(&rfds);
    FD_SET(wake_[0], &rfds);
    FD_SET(fd, &rfds);
    timeval tv{0, TickTimeoutMs() * 1000};
    int n = select(std::max(fd, wake_[0]) + 1, &rfds, nullptr, nullptr, &tv);
    if (n < 0 && errno != EINTR) {
      return absl::InternalError(absl::StrCat("select: ", std::strerror(errno)));
    }
    if (n > 0) {
      if (FD_ISSET(wake_[0], &rfds)) return absl::OkStatus();
      if (FD_ISSET(fd, &rfds)) {
        int rc = modbus_receive(ctx_, query);
        if (rc > 0) {
          (void)Handle(fd, query, rc);
        } else if (rc == -1) {
          int err = errno;
          if (err == EIO || err == EBADF || err == ENXIO) {
            return absl::UnavailableError(
                absl::StrCat("rtu: ", options_.device, ": ", modbus_strerror(err)));
          }
          // Garbage, a bad CRC or a truncated frame: resynchronise on silence.
          Log("rtu: dropped bad frame: %s", modbus_strerror(err));
          modbus_flush(ctx_);
        }
      }
    }
    firmware_->Tick(PleoFirmware::Clock::now());
  }
}

}  // namespace kinemo::pleo_sim
