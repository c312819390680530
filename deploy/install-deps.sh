#!/usr/bin/env bash
# Installs every system dependency of kinemo from Debian 12's packages.
# Idempotent: skips apt when every package is already installed.
set -euo pipefail

PKGS=(
  # toolchain
  build-essential cmake ninja-build pkg-config git ca-certificates
  # RPC
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  # maths, vision, robot link
  libeigen3-dev libopencv-dev libopencv-contrib-dev libmodbus-dev
  # glTF/GLB/VRM characters: read rigs, write animated GLBs (kinemo retarget)
  libtinygltf-dev
  # tests and benchmarks
  googletest libgtest-dev libgmock-dev libbenchmark-dev
  # coverage-guided fuzzing (deploy/fuzz.sh, ctest -L fuzz): clang with
  # libFuzzer and the ASan/UBSan runtimes
  clang libclang-rt-14-dev libfuzzer-14-dev
  # audio decoding and resampling
  libsndfile1-dev libsoxr-dev
  # PNG plots and previews without OpenCV codecs
  zlib1g-dev
  # the web studio: HTTP + WebSocket (Boost.Beast, header-only in libboost-dev),
  # three.js for the page, and its browser tests (headless Chromium driven by
  # Selenium)
  libboost-dev libjs-three chromium chromium-driver python3-selenium python3-websocket
  # JSON output and CLI parsing
  nlohmann-json3-dev libcli11-dev
  # the coordinator's durable sessions (SQLite in WAL mode)
  libsqlite3-dev
  # speech recognizer (keywords, timed phones)
  libpocketsphinx-dev libsphinxbase-dev pocketsphinx-en-us
  # independent peers and references used by tests and evaluations
  socat mbpoll python3-pymodbus python3-serial-asyncio praat openssl
  # a gRPC client in another language (tests/integration/stores): proto/ is
  # compiled at test time with protoc and protobuf-compiler-grpc's
  # grpc_python_plugin (python3-grpc-tools' bundled protoc predates proto3
  # `optional` and cannot read proto/)
  python3-grpcio python3-protobuf
  # containers without a Docker engine: podman runs deploy/docker-compose.yml
  podman runc docker-compose containernetworking-plugins
  golang-github-containernetworking-plugin-dnsname uidmap slirp4netns fuse-overlayfs curl
  # the pause process of the pods `podman kube play` makes (deploy/k8s test)
  catatonit
  # Prometheus metrics (GET /metrics on every service) and the Prometheus
  # server and promtool (local stack, tests of deploy/prometheus)
  prometheus-cpp-dev prometheus
  # deploy/k8s under `podman kube play` (tests/integration/k8s reads the
  # rendered manifests; its schema check uses node and npm where installed)
  python3-yaml
)
# kubectl renders deploy/k8s (kubectl kustomize): Debian's kubernetes-client,
# unless a kubectl is installed already (another package owning /usr/bin/kubectl).
command -v kubectl >/dev/null || PKGS+=(kubernetes-client)

missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PKGS[@]} packages present"
  exit 0
fi
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
# apt's progress goes to a log; only a summary (or, on failure, the log's
# end) reaches the terminal.
log="${TMPDIR:-/tmp}/kinemo-install-deps.log"
echo "install-deps: installing ${#missing[@]} packages from Debian (log: $log) ..."
if ! { $SUDO apt-get update -qq && $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"; } >"$log" 2>&1; then
  tail -20 "$log" >&2
  echo "install-deps: apt-get failed (full log: $log)" >&2
  exit 1
fi
echo "install-deps: installed ${#missing[@]} packages"
