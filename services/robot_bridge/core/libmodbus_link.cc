// libmodbus implementation of ModbusLink (TCP and RTU).
#include <modbus/modbus.h>

#include <cerrno>
#include <charconv>
#include <string>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "services/robot_bridge/core/errors.h"
#include "services/robot_bridge/core/modbus_link.h"

namespace kinemo::robot {

std::string Endpoint::ToString() const {
  // An IPv6 address in brackets, so that the port's colon is the last one.
  if (kind == Kind::kTcp) {
    return host.find(':') != std::string::npos ? absl::StrCat("tcp://[", host, "]:", port)
                                               : absl::StrCat("tcp://", host, ":", port);
  }
  return absl::StrCat("rtu://", device, "?baud=", baud, "&parity=", std::string(1, parity),
                      "&data_bits=", data_bits, "&stop_bits=", stop_bits);
}

namespace {

bool ParseInt(absl::string_view s, int& out) {
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && p == s.data() + s.size();
}

}  // namespace

StatusOr<Endpoint> ParseEndpoint(std::string_view text_in) {
  const absl::string_view text = AV(text_in);
  Endpoint ep;
  if (absl::StartsWith(text, "tcp://")) {
    absl::string_view rest = text.substr(6);
    size_t colon = rest.rfind(':');
    if (colon == absl::string_view::npos || colon == 0) {
      return BadField("endpoint", "'", text, "' must be tcp://HOST:PORT");
    }
    ep.kind = Endpoint::Kind::kTcp;
    ep.host = std::string(rest.substr(0, colon));
    if (ep.host.size() > 2 && ep.host.front() == '[' && ep.host.back() == ']') {
      ep.host = ep.host.substr(1, ep.host.size() - 2);
    }
    // One pair of brackets, around an IPv6 address only: "[[::]]" printed as
    // "[::]" and parsed back as "::", another endpoint.
    if (ep.host.find_first_of("[]") != std::string::npos) {
      return BadField("endpoint", "'", text, "': brackets only around an IPv6 host, once");
    }
    if (!ParseInt(rest.substr(colon + 1), ep.port) || ep.port < 1 || ep.port > 65535) {
      return BadField("endpoint", "'", text, "': port must be 1..65535");
    }
    return ep;
  }
  if (absl::StartsWith(text, "rtu://")) {
    absl::string_view rest = text.substr(6);
    size_t q = rest.find('?');
    ep.kind = Endpoint::Kind::kRtu;
    ep.device = std::string(rest.substr(0, q));
    if (ep.device.empty()) return BadField("endpoint", "'", text, "': empty device path");
    if (q != absl::string_view::npos) {
      for (absl::string_view kv : absl::StrSplit(rest.substr(q + 1), '&')) {
        size_t eq = kv.find('=');
        if (eq == absl::string_view::npos) {
          return BadField("endpoint", "'", text, "': expected key=value, got '", kv, "'");
        }
        absl::string_view k = kv.substr(0, eq), v = kv.substr(eq + 1);
        bool ok = true;
        if (k == "baud") {
          ok = ParseInt(v, ep.baud) && ep.baud > 0;
        } else if (k == "parity") {
          ok = v.size() == 1 && (v[0] == 'N' || v[0] == 'E' || v[0] == 'O');
          if (ok) ep.parity = v[0];
        } else if (k == "data_bits") {
          ok = ParseInt(v, ep.data_bits) && ep.data_bits >= 5 && ep.data_bits <= 8;
        } else if (k == "stop_bits") {
          ok = ParseInt(v, ep.stop_bits) && (ep.stop_bits == 1 || ep.stop_bits == 2);
        } else {
          return BadField("endpoint", "'", text, "': unknown parameter '", k, "'");
        }
        if (!ok) return BadField("endpoint", "'", text, "': bad value for ", k);
      }
    }
    return ep;
  }
  return BadField("endpoint", "'", text,
                      "' must start with tcp:// or rtu:// (e.g. tcp://127.0.0.1:1502, "
                      "rtu:///dev/ttyUSB0?baud=115200)");
}

Status ValidateLinkOptions(const LinkOptions& o) {
  if (o.unit_id < 1 || o.unit_id > 247) {
    return BadField("unit_id", o.unit_id, " is outside 1..247");
  }
  if (o.connect_timeout_ms < 1 || o.connect_timeout_ms > 60000) {
    return BadField("connect_timeout_ms", o.connect_timeout_ms, " is outside 1..60000");
  }
  if (o.response_timeout_ms < 1 || o.response_timeout_ms > 60000) {
    return BadField("response_timeout_ms", o.response_timeout_ms, " is outside 1..60000");
  }
  if (o.byte_timeout_ms < 1 || o.byte_timeout_ms > 10000) {
    return BadField("byte_timeout_ms", o.byte_timeout_ms, " is outside 1..10000");
  }
  if (o.endpoint.kind == Endpoint::Kind::kTcp) {
    if (o.endpoint.host.empty()) return BadField("endpoint.host", "empty");
    if (o.endpoint.port < 1 || o.endpoint.port > 65535) {
      return BadField("endpoint.port", o.endpoint.port, " is outside 1..65535");
    }
  } else if (o.endpoint.device.empty()) {
    return BadField("endpoint.device", "empty");
  }
  return absl::OkStatus();
}

namespace {

void SetTimeout(modbus_t* ctx, int ms, bool response) {
  uint32_t sec = static_cast<uint32_t>(ms / 1000);
  uint32_t usec = static_cast<uint32_t>((ms % 1000) * 1000);
  if (response) {
    modbus_set_response_timeout(ctx, sec, usec);
  } else {
    modbus_set_byte_timeout(ctx, sec, usec);
  }
}

class LibmodbusLink final : public ModbusLink {
 public:
  explicit LibmodbusLink(LinkOptions options) : options_(std::move(options)) {}
  ~LibmodbusLink() override { Free(); }

  Status Connect() override {
    if (connected_) return absl::OkStatus();
    KINEMO_RETURN_IF_ERROR(ValidateLinkOptions(options_));
    Free();
    const Endpoint& ep = options_.endpoint;
    if (ep.kind == Endpoint::Kind::kTcp) {
      std::string port = std::to_string(ep.port);
      ctx_ = modbus_new_tcp_pi(ep.host.c_str(), port.c_str());
    } else {
      ctx_ = modbus_new_rtu(ep.device.c_str(), ep.baud, ep.parity, ep.data_bits, ep.stop_bits);
    }
    if (ctx_ == nullptr) {
      return absl::InvalidArgumentError(
          absl::StrCat(Describe(), ": cannot create libmodbus context: ", modbus_strerror(errno)));
    }
    modbus_set_error_recovery(ctx_, MODBUS_ERROR_RECOVERY_NONE);
    modbus_set_slave(ctx_, options_.unit_id);
    // libmodbus bounds the TCP connect by the response timeout.
    SetTimeout(ctx_, options_.connect_timeout_ms, /*response=*/true);
    if (modbus_connect(ctx_) == -1) {
      int err = errno;
      Free();
      return absl::UnavailableError(
          absl::StrCat(Describe(), ": connect failed: ", modbus_strerror(err)));
    }
    SetTimeout(ctx_, options_.response_timeout_ms, /*response=*/true);
    SetTimeout(ctx_, options_.byte_timeout_ms, /*response=*/false);
    if (ep.kind == Endpoint::Kind::kRtu) modbus_flush(ctx_);
    connected_ = true;
    return absl::OkStatus();
  }

  void Close() override { Free(); }
  bool IsConnected() const override { return connected_; }

  Status ReadHoldingRegisters(int address, std::span<uint16_t> out) override {
    return Run("read holding registers", address, static_cast<int>(out.size()), [&] {
      return modbus_read_registers(ctx_, address, static_cast<int>(out.size()), out.data());
    });
  }
  Status ReadInputRegisters(int address, std::span<uint16_t> out) override {
    return Run("read input registers", address, static_cast<int>(out.size()), [&] {
      return modbus_read_input_registers(ctx_, address, static_cast<int>(out.size()), out.data());
    });
  }
  Status WriteRegister(int address, uint16_t value) override {
    return Run("write register", address, 1,
               [&] { return modbus_write_register(ctx_, address, value); });
  }
  Status WriteRegisters(int address, std::span<const uint16_t> values) override {
    return Run("write registers", address, static_cast<int>(values.size()), [&] {
      return modbus_write_registers(ctx_, address, static_cast<int>(values.size()),
                                    values.data());
    });
  }
  Status WriteAndReadRegisters(int write_address, std::span<const uint16_t> values,
                               int read_address, std::span<uint16_t> out) override {
    return Run("write and read registers", write_address, static_cast<int>(values.size()), [&] {
      return modbus_write_and_read_registers(ctx_, write_address, static_cast<int>(values.size()),
                                             values.data(), read_address,
                                             static_cast<int>(out.size()), out.data());
    });
  }
  Status ReadDiscreteInputs(int address, std::span<uint8_t> out) override {
    return Run("read discrete inputs", address, static_cast<int>(out.size()), [&] {
      return modbus_read_input_bits(ctx_, address, static_cast<int>(out.size()), out.data());
    });
  }

  std::string Describe() const override {
    return absl::StrCat(options_.endpoint.ToString(), " unit ", options_.unit_id);
  }

 private:
  template <typename Fn>
  Status Run(std::string_view what, int address, int count, Fn fn) {
    if (!connected_) {
      return absl::UnavailableError(absl::StrCat(Describe(), ": not connected"));
    }
    errno = 0;
    int rc = fn();
    if (rc != -1) return absl::OkStatus();
    int err = errno;
    std::string where = absl::StrCat(Describe(), ": ", AV(what), " at ", address, " (", count,
                                     "): ");
    const bool rtu = options_.endpoint.kind == Endpoint::Kind::kRtu;
    switch (err) {
      case EMBXILFUN:
      case EMBXILADD:
        return absl::FailedPreconditionError(
            absl::StrCat(where, "device refused: ", modbus_strerror(err)));
      case EMBXILVAL:
        return absl::InvalidArgumentError(
            absl::StrCat(where, "device refused the value: ", modbus_strerror(err)));
      case EMBXSFAIL:
      case EMBXSBUSY:
      case EMBXACK:
      case EMBXNACK:
      case EMBXMEMPAR:
      case EMBXGPATH:
      case EMBXGTAR:
        return absl::UnavailableError(
            absl::StrCat(where, "device answered with exception: ", modbus_strerror(err)));
      case EMBBADCRC:
      case EMBBADDATA:
      case EMBBADEXC:
      case EMBMDATA:
      case EMBBADSLAVE:
      case EMBUNKEXC:
        // A garbled frame: the byte stream may be out of step. Resynchronise:
        // flush the serial line, or reconnect TCP.
        if (rtu) {
          modbus_flush(ctx_);
        } else {
          Free();
        }
        return absl::UnavailableError(
            absl::StrCat(where, "corrupted frame: ", modbus_strerror(err)));
      case ETIMEDOUT:
        // A late answer would be taken for the next one; drop it.
        if (rtu) {
          modbus_flush(ctx_);
        } else {
          Free();
        }
        return absl::UnavailableError(absl::StrCat(where, "no response within ",
                                                   options_.response_timeout_ms, " ms"));
      default:
        Free();
        return absl::UnavailableError(
            absl::StrCat(where, "connection lost: ", modbus_strerror(err)));
    }
  }

  void Free() {
    if (ctx_ != nullptr) {
      modbus_close(ctx_);
      modbus_free(ctx_);
      ctx_ = nullptr;
    }
    connected_ = false;
  }

  LinkOptions options_;
  modbus_t* ctx_ = nullptr;
  bool connected_ = false;
};

}  // namespace

std::unique_ptr<ModbusLink> NewLibmodbusLink(const LinkOptions& options) {
  return std::make_unique<LibmodbusLink>(options);
}

}  // namespace kinemo::robot
