// `kinemo audio ...`: audio subcommands.
//
//   kinemo audio info FILE [--json] [--allow-truncated]
//   kinemo audio info FILE.raw --raw-rate 16000 [--raw-channels 1] [--raw-encoding s16le]
//
// Prints format, subtype, sample rate, channels, frames, duration and the
// peak and RMS level (dBFS, over every sample of every channel). Errors go to
// stderr; exit code 2 for bad input or usage, 1 for other failures.
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "common/audio/audio.h"
#include "common/audio/decode.h"
#include "services/cli/commands.h"

namespace kinemo::cli {
namespace {

struct AudioInfoArgs {
  std::string file;
  bool json = false;
  bool allow_truncated = false;
  int raw_rate_hz = 0;
  int raw_channels = 1;
  std::string raw_encoding = "s16le";
};

[[noreturn]] void Fail(const absl::Status& status) {
  std::cerr << "kinemo audio info: " << status.message() << "\n";
  const bool bad_input = absl::IsInvalidArgument(status) || absl::IsNotFound(status) ||
                         absl::IsPermissionDenied(status) || absl::IsFailedPrecondition(status);
  throw CliExit{bad_input ? 2 : 1};
}

bool LooksRaw(const std::string& path) {
  const auto dot = path.rfind('.');
  if (dot == std::string::npos) return false;
  const std::string ext = path.substr(dot);
  return ext == ".raw" || ext == ".pcm";
}

nlohmann::json DbfsJson(double linear) {
  const double db = audio::ToDbfs(linear);
  if (!std::isfinite(db)) return nullptr;  // silence: -inf has no JSON form
  return db;
}

std::string DbfsText(double linear) {
  const double db = audio::ToDbfs(linear);
  if (!std::isfinite(db)) return "-inf";
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.2f", db);
  return buf;
}

void RunInfo(const AudioInfoArgs& args, bool raw_requested) {
  audio::DecodeOptions options;
  options.allow_truncated = args.allow_truncated;
  absl::StatusOr<audio::DecodedAudio> decoded;
  if (raw_requested || LooksRaw(args.file)) {
    if (args.raw_rate_hz <= 0) {
      Fail(absl::InvalidArgumentError(
          args.file + ": --raw-rate: headerless PCM needs its sample rate (e.g. --raw-rate 16000)"));
    }
    auto encoding = audio::ParsePcmEncoding(args.raw_encoding);
    if (!encoding.ok()) Fail(encoding.status());
    audio::RawPcmFormat format;
    format.encoding = *encoding;
    format.sample_rate_hz = args.raw_rate_hz;
    format.channels = args.raw_channels;
    decoded = audio::DecodeRawPcmFile(args.file, format, options);
  } else {
    decoded = audio::DecodeAudioFile(args.file, options);
  }
  if (!decoded.ok()) Fail(decoded.status());
  const audio::DecodedAudio& a = *decoded;

  if (args.json) {
    nlohmann::json j;
    j["file"] = args.file;
    j["format"] = a.format;
    j["format_description"] = a.format_description;
    j["subtype"] = a.subtype;
    j["subtype_description"] = a.subtype_description;
    j["sample_rate_hz"] = a.sample_rate_hz;
    j["channels"] = a.channels;
    j["frames"] = a.frames();
    j["duration_s"] = a.duration_s;
    j["peak_dbfs"] = DbfsJson(a.peak);
    j["rms_dbfs"] = DbfsJson(a.rms);
    std::cout << j.dump(2) << "\n";
    return;
  }
  char duration[32];
  std::snprintf(duration, sizeof(duration), "%.3f", a.duration_s);
  std::cout << "file:          " << args.file << "\n"
            << "format:        " << a.format << " (" << a.format_description << ")\n"
            << "subtype:       " << a.subtype << " (" << a.subtype_description << ")\n"
            << "sample_rate:   " << a.sample_rate_hz << " Hz\n"
            << "channels:      " << a.channels << "\n"
            << "frames:        " << a.frames() << "\n"
            << "duration_s:    " << duration << "\n"
            << "peak_dbfs:     " << DbfsText(a.peak) << "\n"
            << "rms_dbfs:      " << DbfsText(a.rms) << "\n";
}

}  // namespace

void RegisterAudioCommands(CLI::App& app) {
  CLI::App* audio_cmd =
      app.add_subcommand("audio", "Inspect audio files: WAV, FLAC, OGG (Vorbis, Opus), MP3, AIFF, raw PCM");
  audio_cmd->require_subcommand(1);

  auto args = std::make_shared<AudioInfoArgs>();
  CLI::App* info = audio_cmd->add_subcommand(
      "info", "Format, rate, channels, frames, duration, peak and RMS level (dBFS) of FILE");
  info->add_option("FILE", args->file,
                   "Audio file: WAV (8-32 bit, float), FLAC, OGG (Vorbis, Opus), MP3, AIFF (up to 512 MiB), or "
                   "headerless PCM (.raw/.pcm)")
      ->required();
  info->add_flag("--json", args->json, "Print one JSON object");
  info->add_flag("--allow-truncated", args->allow_truncated,
                 "Accept a WAV whose data chunk is shorter than its header says");
  CLI::Option* rate = info->add_option("--raw-rate", args->raw_rate_hz,
                                       "Headerless PCM: sample rate in Hz (required for raw)");
  CLI::Option* channels = info->add_option("--raw-channels", args->raw_channels,
                                           "Headerless PCM: interleaved channels (default 1)");
  CLI::Option* encoding =
      info->add_option("--raw-encoding", args->raw_encoding,
                       "Headerless PCM: s16le (default), s24le, s32le, f32le, f64le, u8");
  info->callback([args, rate, channels, encoding] {
    const bool raw_requested = rate->count() > 0 || channels->count() > 0 || encoding->count() > 0;
    RunInfo(*args, raw_requested);
  });
}

}  // namespace kinemo::cli
