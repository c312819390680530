// The PocketSphinx wiring under SphinxRecognizer and its streams
// (recognizer.cc): samples to 16-bit PCM, one recording through a decoder
// from a given cepstral mean, reading a decoder's segments as phones or
// keywords, the text files Sphinx reads (key phrases, a phone dictionary),
// and the pool of phone decoders (the -allphone phone loop, or the phone
// grammar built from the phone language model).
// Internal to kinemo_prosody_sphinx: it includes PocketSphinx's headers, whose
// include directories are private to that target.
#pragma once

#include <pocketsphinx.h>

#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <mutex>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "common/status/status.h"
#include "services/prosody/core/recognizer.h"

namespace kinemo::prosody {
namespace sphinx {

inline constexpr double kFrameS = 0.01;  // Sphinx's default 100 frames per second

// 16-bit PCM of `samples` into `pcm` (resized; no allocation once large enough).
void ToPcm16(std::span<const float> samples, std::vector<int16>* pcm);

bool IsFiller(const char* w);

// A grammar's null transition ("(NULL)"), not a word.
bool IsNull(const char* w);

// Silence: a filler, or the phone grammar's "sil".
bool IsSilence(const char* w);

std::string CleanWord(const char* w);

// The running cepstral mean of a decoder. Live decoding (audio in pieces)
// normalises by it and updates it as audio flows, from one utterance to the
// next; a decoder that has decoded live once does so for whole recordings
// too. Live decoders and whole-recording decoders are therefore kept apart,
// and every recording or stream starts from the mean of a new decoder (the
// model's -cmninit), so that results do not depend on what a decoder heard
// before.
static_assert(std::is_same_v<mfcc_t, float>, "SphinxRecognizer keeps cepstral means as float");

std::vector<mfcc_t> CepstralMean(ps_decoder_t* ps);

void SetCepstralMean(ps_decoder_t* ps, const std::vector<mfcc_t>& mean);

// Decodes `samples` as one recording, starting from the cepstral mean `start`.
Status Decode(ps_decoder_t* ps, std::span<const float> samples, const std::vector<mfcc_t>& start);

// A text file Sphinx reads (key phrases, a dictionary), removed when this
// goes out of scope.
struct TempTextFile {
  char path[32] = "/tmp/kinemo_sphinx_XXXXXX";
  TempTextFile() = default;
  TempTextFile(TempTextFile&& other) noexcept {
    std::copy(std::begin(other.path), std::end(other.path), path);
    other.path[0] = 0;
  }
  TempTextFile(const TempTextFile&) = delete;
  ~TempTextFile() {
    if (path[0] != 0) unlink(path);
  }
  static StatusOr<TempTextFile> Write(const std::string& text) {
    TempTextFile f;
    const int fd = mkstemp(f.path);
    if (fd < 0) {
      f.path[0] = 0;
      return absl::InternalError("recognizer: cannot create a temporary file");
    }
    const bool ok = write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size());
    close(fd);
    if (!ok) return absl::InternalError("recognizer: cannot write a temporary file");
    return f;
  }
};

// Sphinx reads key phrases from a file: "phrase /threshold/" per line.
StatusOr<TempTextFile> WriteKeywordFile(const std::vector<std::string>& keywords,
                                        double threshold);

// The en-us model's phones (CMUdict's ARPAbet without stress marks).
inline constexpr const char* kPhones[] = {
    "AA", "AE", "AH", "AO", "AW", "AY", "B",  "CH", "D", "DH", "EH", "ER", "EY",
    "F",  "G",  "HH", "IH", "IY", "JH", "K",  "L",  "M", "N",  "NG", "OW", "OY",
    "P",  "R",  "S",  "SH", "T",  "TH", "UH", "UW", "V", "W",  "Y",  "Z",  "ZH"};

std::string Lower(std::string s);

// A dictionary whose words are the phones ("aa AA"), and "sil SIL".
StatusOr<TempTextFile> WritePhoneDictionary(bool with_silence);

std::string Upper(std::string s);

// The phones of the decoder's segments (fillers, sentence marks and "sil"
// are silence; consecutive silences merge; a grammar's null transitions are
// skipped).
std::vector<RecognizedPhone> SegmentPhones(ps_decoder_t* ps);

// Appends the decoder's keyword segments (fillers skipped); returns how many.
int AppendKeywordSegments(ps_decoder_t* ps, std::vector<RecognizedWord>* out);

}  // namespace sphinx

// Idle phone-loop decoders (loading one takes 0.2-0.5 s): taken by a batch
// call or a live stream, given back when it is done. Shared with the streams,
// so that a stream may outlive the recognizer.
class DecoderPool {
 public:
  explicit DecoderPool(RecognizerConfig config) : config_(std::move(config)) {}
  ~DecoderPool();
  StatusOr<ps_decoder_t*> Take();
  // The cepstral mean every recording and stream starts from.
  const std::vector<mfcc_t>& initial_cmn();
  void Give(ps_decoder_t* ps);

 private:
  // The -allphone phone loop.
  StatusOr<ps_decoder_t*> NewLoopDecoder() const;
  // The phone grammar ("sil" is one of its phones, so the voice activity
  // detector, which drops silent frames and moves the frame clock of live
  // partial results, is off): state 0 is the start, state 1 + i follows phone i,
  // the last state is final; phone j leads from state s to state 1 + j with
  // the bigram probability P(j | phone of s) (P(j | <s>) from the start);
  // every state but the start may end the utterance with P(</s> | phone).
  StatusOr<ps_decoder_t*> NewGrammarDecoder() const;

  static constexpr std::size_t kMaxIdle = 4;
  const RecognizerConfig config_;
  std::mutex mu_;
  std::vector<ps_decoder_t*> idle_;
  std::vector<mfcc_t> initial_cmn_;
};

}  // namespace kinemo::prosody
