#include "common/audio/sndfile_memory.h"

#include <algorithm>
#include <cstdio>
#include <cstring>

namespace kinemo::audio::internal {
namespace {

// --- reader ---------------------------------------------------------------
sf_count_t ReaderLength(void* user) {
  return static_cast<MemoryReader*>(user)->size;
}

sf_count_t ReaderSeek(sf_count_t offset, int whence, void* user) {
  auto* r = static_cast<MemoryReader*>(user);
  sf_count_t base = 0;
  switch (whence) {
    case SEEK_SET: base = 0; break;
    case SEEK_CUR: base = r->pos; break;
    case SEEK_END: base = r->size; break;
    default: return -1;
  }
  // Reject overflow and negative positions; positions past the end are
  // allowed (reads there return 0 bytes), as with a real file.
  if ((offset > 0 && base > INT64_MAX - offset) || base + offset < 0) return -1;
  r->pos = base + offset;
  return r->pos;
}

sf_count_t ReaderRead(void* ptr, sf_count_t count, void* user) {
  auto* r = static_cast<MemoryReader*>(user);
  if (count <= 0 || r->pos >= r->size) return 0;
  const sf_count_t n = std::min(count, r->size - r->pos);
  std::memcpy(ptr, r->data + r->pos, static_cast<std::size_t>(n));
  r->pos += n;
  return n;
}

sf_count_t ReaderWrite(const void*, sf_count_t, void*) { return 0; }

sf_count_t ReaderTell(void* user) { return static_cast<MemoryReader*>(user)->pos; }

// --- writer ---------------------------------------------------------------
sf_count_t WriterLength(void* user) {
  return static_cast<sf_count_t>(static_cast<MemoryWriter*>(user)->bytes->size());
}

sf_count_t WriterSeek(sf_count_t offset, int whence, void* user) {
  auto* w = static_cast<MemoryWriter*>(user);
  sf_count_t base = 0;
  switch (whence) {
    case SEEK_SET: base = 0; break;
    case SEEK_CUR: base = w->pos; break;
    case SEEK_END: base = static_cast<sf_count_t>(w->bytes->size()); break;
    default: return -1;
  }
  if ((offset > 0 && base > INT64_MAX - offset) || base + offset < 0) return -1;
  w->pos = base + offset;
  return w->pos;
}

sf_count_t WriterRead(void* ptr, sf_count_t count, void* user) {
  auto* w = static_cast<MemoryWriter*>(user);
  const auto size = static_cast<sf_count_t>(w->bytes->size());
  if (count <= 0 || w->pos >= size) return 0;
  const sf_count_t n = std::min(count, size - w->pos);
  std::memcpy(ptr, w->bytes->data() + w->pos, static_cast<std::size_t>(n));
  w->pos += n;
  return n;
}

sf_count_t WriterWrite(const void* ptr, sf_count_t count, void* user) {
  auto* w = static_cast<MemoryWriter*>(user);
  if (count <= 0) return 0;
  const auto end = static_cast<std::size_t>(w->pos + count);
  if (end > w->bytes->size()) w->bytes->resize(end);
  std::memcpy(w->bytes->data() + w->pos, ptr, static_cast<std::size_t>(count));
  w->pos += count;
  return count;
}

sf_count_t WriterTell(void* user) { return static_cast<MemoryWriter*>(user)->pos; }

SF_FORMAT_INFO Info(int format, int command) {
  SF_FORMAT_INFO info{};
  info.format = format;
  if (sf_command(nullptr, command, &info, sizeof(info)) != 0 || info.name == nullptr) {
    info.name = nullptr;
  }
  return info;
}

std::string Hex(int value) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "0x%x", static_cast<unsigned>(value));
  return buf;
}

}  // namespace

SF_VIRTUAL_IO* ReaderIo() {
  static SF_VIRTUAL_IO io{ReaderLength, ReaderSeek, ReaderRead, ReaderWrite, ReaderTell};
  return &io;
}

SF_VIRTUAL_IO* WriterIo() {
  static SF_VIRTUAL_IO io{WriterLength, WriterSeek, WriterRead, WriterWrite, WriterTell};
  return &io;
}

std::string MajorFormatName(int format) {
  switch (format & SF_FORMAT_TYPEMASK) {
    case SF_FORMAT_WAV: return "wav";
    case SF_FORMAT_WAVEX: return "wavex";
    case SF_FORMAT_RF64: return "rf64";
    case SF_FORMAT_W64: return "w64";
    case SF_FORMAT_AIFF: return "aiff";
    case SF_FORMAT_AU: return "au";
    case SF_FORMAT_CAF: return "caf";
    case SF_FORMAT_FLAC: return "flac";
    case SF_FORMAT_OGG: return "ogg";
    case SF_FORMAT_MPEG: return "mpeg";
    case SF_FORMAT_RAW: return "raw";
    case SF_FORMAT_NIST: return "nist";
    case SF_FORMAT_IRCAM: return "ircam";
    case SF_FORMAT_VOC: return "voc";
    case SF_FORMAT_PAF: return "paf";
    case SF_FORMAT_SVX: return "svx";
    case SF_FORMAT_MAT4: return "mat4";
    case SF_FORMAT_MAT5: return "mat5";
    case SF_FORMAT_PVF: return "pvf";
    case SF_FORMAT_XI: return "xi";
    case SF_FORMAT_HTK: return "htk";
    case SF_FORMAT_SDS: return "sds";
    case SF_FORMAT_AVR: return "avr";
    case SF_FORMAT_SD2: return "sd2";
    case SF_FORMAT_WVE: return "wve";
    case SF_FORMAT_MPC2K: return "mpc2k";
    default: return "major_" + Hex(format & SF_FORMAT_TYPEMASK);
  }
}

std::string SubtypeName(int format) {
  switch (format & SF_FORMAT_SUBMASK) {
    case SF_FORMAT_PCM_S8: return "pcm_s8";
    case SF_FORMAT_PCM_U8: return "pcm_u8";
    case SF_FORMAT_PCM_16: return "pcm_16";
    case SF_FORMAT_PCM_24: return "pcm_24";
    case SF_FORMAT_PCM_32: return "pcm_32";
    case SF_FORMAT_FLOAT: return "float";
    case SF_FORMAT_DOUBLE: return "double";
    case SF_FORMAT_ULAW: return "ulaw";
    case SF_FORMAT_ALAW: return "alaw";
    case SF_FORMAT_IMA_ADPCM: return "ima_adpcm";
    case SF_FORMAT_MS_ADPCM: return "ms_adpcm";
    case SF_FORMAT_GSM610: return "gsm610";
    case SF_FORMAT_VORBIS: return "vorbis";
    case SF_FORMAT_OPUS: return "opus";
    case SF_FORMAT_MPEG_LAYER_I: return "mp1";
    case SF_FORMAT_MPEG_LAYER_II: return "mp2";
    case SF_FORMAT_MPEG_LAYER_III: return "mp3";
    case SF_FORMAT_ALAC_16: return "alac_16";
    case SF_FORMAT_ALAC_20: return "alac_20";
    case SF_FORMAT_ALAC_24: return "alac_24";
    case SF_FORMAT_ALAC_32: return "alac_32";
    default: return "subtype_" + Hex(format & SF_FORMAT_SUBMASK);
  }
}

std::string MajorFormatDescription(int format) {
  SF_FORMAT_INFO info = Info(format & SF_FORMAT_TYPEMASK, SFC_GET_FORMAT_INFO);
  return info.name != nullptr ? info.name : MajorFormatName(format);
}

std::string SubtypeDescription(int format) {
  SF_FORMAT_INFO info = Info(format & SF_FORMAT_SUBMASK, SFC_GET_FORMAT_INFO);
  return info.name != nullptr ? info.name : SubtypeName(format);
}

}  // namespace kinemo::audio::internal
