// An independent VMC protocol receiver (a "Marionette") for kinemo's tests:
// listens on 127.0.0.1 at a port the system picks, prints
//   ready <port>
// once it listens, and records every OSC bundle it receives, decoded by
// npm's `osc` (not by the OSC encoder kinemo uses): per datagram its arrival
// time (ms, this process's monotonic clock) and its messages [address,
// ...args]. On SIGTERM or SIGINT it writes the recording (JSON) to --out and
// exits 0.
//
//   node receiver.mjs --out RECORDING.json
import { createRequire } from "node:module";
import { writeFileSync } from "node:fs";
import { performance } from "node:perf_hooks";

const require = createRequire(import.meta.url);
const osc = require("osc");

const args = process.argv.slice(2);
const outIndex = args.indexOf("--out");
if (outIndex < 0 || !args[outIndex + 1]) {
  console.error("usage: node receiver.mjs --out RECORDING.json");
  process.exit(2);
}
const out = args[outIndex + 1];

const datagrams = [];
let errors = 0;
const port = new osc.UDPPort({ localAddress: "127.0.0.1", localPort: 0, metadata: false });

function flatten(packet, into) {
  if (packet.packets) {
    for (const p of packet.packets) flatten(p, into);
  } else {
    into.push([packet.address, ...packet.args]);
  }
}

port.on("osc", (packet) => {
  const messages = [];
  flatten(packet, messages);
  datagrams.push({ t_ms: performance.now(), bundle: Boolean(packet.packets), messages });
});
port.on("error", (e) => {
  errors += 1;
  if (errors <= 5) console.error(`receiver: ${e.message ?? e}`);
});
port.on("ready", () => {
  console.log(`ready ${port.socket.address().port}`);
});

function finish() {
  writeFileSync(out, JSON.stringify({ datagrams, decode_errors: errors }));
  port.close();
  process.exit(0);
}
process.on("SIGTERM", finish);
process.on("SIGINT", finish);
port.open();
