// kinemo studio: the microphone's AudioWorklet. Runs at the AudioContext's
// rate (the page asks for 16 kHz), mixes to mono, and posts chunks of
// `chunkSamples` samples (20 ms) as S16LE PCM (an ArrayBuffer, transferred)
// to the page, which sends them to StreamAnimate.
class KinemoCapture extends AudioWorkletProcessor {
  constructor(options) {
    super();
    this.chunkSamples = (options.processorOptions && options.processorOptions.chunkSamples) || 320;
    this.buffer = new Int16Array(this.chunkSamples);
    this.filled = 0;
  }

  process(inputs) {
    const input = inputs[0];
    if (!input || input.length === 0) return true;
    const frames = input[0].length;
    for (let i = 0; i < frames; ++i) {
      let v = 0;
      for (let c = 0; c < input.length; ++c) v += input[c][i];
      v /= input.length;
      this.buffer[this.filled++] = Math.max(-32768, Math.min(32767, Math.round(v * 32767)));
      if (this.filled === this.chunkSamples) {
        const out = this.buffer.buffer;
        this.port.postMessage(out, [out]);
        this.buffer = new Int16Array(this.chunkSamples);
        this.filled = 0;
      }
    }
    return true;
  }
}

registerProcessor('kinemo-capture', KinemoCapture);
