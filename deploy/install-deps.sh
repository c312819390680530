#!/usr/bin/env bash
# Installs kinemo's system dependencies from Debian 12's packages.
#
#   bash deploy/install-deps.sh [--demo | --build | --all]
#
#   --demo  what the build (no tests, no benchmarks) and README command 1
#           (deploy/demo.sh) need
#   --build what building every target needs: --demo plus GoogleTest and
#           Google Benchmark (deploy/test.sh installs these first, then the
#           rest of --all while the build runs)
#   --all   (default) also what running the tests, benchmarks, fuzzing and
#           the deployments needs (README command 2, deploy/test.sh)
#
# Idempotent: skips apt when every package of the set is already installed.
# apt's own output goes to a log; the terminal gets what is being done and how
# far it is (downloaded / unpacked / set up, out of how many).
set -euo pipefail

set_name=all
case "${1:-}" in
  --demo) set_name=demo ;;
  --build) set_name=build ;;
  --all | "") set_name=all ;;
  *) echo "usage: install-deps.sh [--demo | --build | --all]" >&2; exit 2 ;;
esac

# The build and the demo.
DEMO_PKGS=(
  # toolchain
  build-essential cmake ninja-build pkg-config git ca-certificates
  # RPC
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  # live motion out over the VMC protocol: OSC encoding (common/vmc)
  liblo-dev
  # maths, vision, robot link
  libeigen3-dev libopencv-dev libopencv-contrib-dev libmodbus-dev
  # glTF/GLB/VRM characters: read rigs, write animated GLBs (kinemo retarget);
  # compressed glTF (EXT_meshopt_compression, KHR_draco_mesh_compression) is
  # decoded with meshoptimizer and Draco; WebP textures get PNG fallbacks
  libtinygltf-dev libmeshoptimizer-dev libdraco-dev libwebp-dev
  # FBX characters (Mixamo, Character Creator, Blender exports): read and
  # written through assimp (common/retarget/fbx.cc)
  libassimp-dev
  # audio decoding and resampling
  libsndfile1-dev libsoxr-dev
  # PNG plots and previews without OpenCV codecs
  zlib1g-dev
  # the web studio: HTTP + WebSocket (Boost.Beast, header-only in
  # libboost-dev; the build configures it)
  libboost-dev
  # JSON output and CLI parsing
  nlohmann-json3-dev libcli11-dev
  # the coordinator's durable sessions (SQLite in WAL mode)
  libsqlite3-dev
  # speech recognizer (keywords, timed phones; the demo's visemes)
  libpocketsphinx-dev libsphinxbase-dev pocketsphinx-en-us
  # GET /metrics on every service
  prometheus-cpp-dev
  # the demo's summaries of the JSON the CLI prints
  python3
)

# Building the tests and benchmarks: GoogleTest (KINEMO_BUILD_TESTS) and
# Google Benchmark (KINEMO_BUILD_BENCHMARKS); node and npm: the studio's page
# libraries (three.js, @pixiv/three-vrm: services/studio/libs, `npm ci` from
# its lock file at build time), the k8s schema check (npm kubernetes-models)
# and the glTF check of retargeted characters (npm gltf-validator). Debian's,
# unless a node or npm is installed already (NodeSource's nodejs carries its
# own npm and conflicts with Debian's).
BUILD_PKGS=(googletest libgtest-dev libgmock-dev libbenchmark-dev)
command -v node >/dev/null || BUILD_PKGS+=(nodejs)
command -v npm >/dev/null || BUILD_PKGS+=(npm)

# Running the tests, benchmarks, fuzzing, deployments (README command 2).
TEST_PKGS=(
  # coverage-guided fuzzing (deploy/fuzz.sh, ctest -L fuzz): clang with
  # libFuzzer and the ASan/UBSan runtimes
  clang libclang-rt-14-dev libfuzzer-14-dev
  # the studio's browser tests (headless Chromium driven by Selenium) and its
  # socket test
  chromium chromium-driver python3-selenium python3-websocket
  # independent peers and references used by tests and evaluations; test
  # certificates (deploy/certs.sh)
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
  # the Prometheus server and promtool (local stack, tests of deploy/prometheus)
  prometheus
  # an independent glTF reader: Blender's importer reads the GLBs kinemo
  # writes (shape-key and armature animation, tests/integration/retarget)
  blender
  # deploy/k8s under `podman kube play` (tests/integration/k8s reads the
  # rendered manifests)
  python3-yaml
)
# kubectl renders deploy/k8s (kubectl kustomize): Debian's kubernetes-client,
# unless a kubectl is installed already (another package owning /usr/bin/kubectl).
command -v kubectl >/dev/null || TEST_PKGS+=(kubernetes-client)

# npm packages of the test tools, from their committed lock files (--all),
# each into its folder's node_modules (git-ignored): the independent VMC
# receiver of tests/integration/vmc (npm's osc), the VRM Animation reader
# of tests/integration/retarget (three.js, @pixiv/three-vrm-animation) and
# the Khronos glTF validator it checks GLBs with. After the Debian packages
# (node and npm may be among them).
install_npm_tools() {
  [[ "$set_name" == all ]] || return 0
  command -v npm >/dev/null || return 0
  local root tool marker dir
  root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/tests/tools"
  for tool in vmc_receiver:osc vrma_check:@pixiv/three-vrm-animation gltf_validator:gltf-validator; do
    dir="$root/${tool%%:*}"
    marker="${tool#*:}"
    [[ -d "$dir/node_modules/$marker" ]] && continue
    echo "install-deps: npm ci (tests/tools/${tool%%:*}: $marker)"
    (cd "$dir" && npm ci --omit=optional --no-audit --no-fund --loglevel=error) ||
      echo "install-deps: npm ci in $dir failed (its test installs it itself, or skips)" >&2
  done
}

PKGS=("${DEMO_PKGS[@]}")
[[ "$set_name" == demo ]] || PKGS+=("${BUILD_PKGS[@]}")
[[ "$set_name" != all ]] || PKGS+=("${TEST_PKGS[@]}")

# One dpkg-query for the whole set (one per package takes seconds on a busy machine).
declare -A installed=()
while read -r name status; do
  [[ "$status" == "install ok installed" ]] && installed[$name]=1
done < <(dpkg-query -W -f='${Package} ${Status}\n' "${PKGS[@]}" 2>/dev/null || true)
missing=()
for p in "${PKGS[@]}"; do
  [[ -n "${installed[$p]:-}" ]] || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PKGS[@]} packages of the $set_name set present"
  install_npm_tools
  exit 0
fi
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
log="${TMPDIR:-/tmp}/kinemo-install-deps.log"
fail() {
  tail -20 "$log" >&2
  echo "install-deps: $1 failed (full log: $log)" >&2
  exit 1
}
echo "install-deps: ${#missing[@]} of the ${#PKGS[@]} packages of the $set_name set are missing: ${missing[*]}"
# deploy/test.sh runs this twice within minutes (--build, then --all beside
# the build): lists this script fetched in the last 30 minutes are kept (a
# stamp of its own: apt gives the lists the mirror's times, not the fetch's).
stamp="${TMPDIR:-/tmp}/kinemo-apt-updated"
if [[ -n "$(find "$stamp" -newermt '30 minutes ago' 2>/dev/null)" ]]; then
  echo "install-deps: package lists fetched $(( ($(date +%s) - $(stat -c %Y "$stamp")) / 60 )) min ago, no apt-get update"
  : >"$log"
else
  echo "install-deps: apt-get update (log: $log)"
  $SUDO apt-get update -qq >"$log" 2>&1 || fail "apt-get update"
  touch "$stamp" 2>/dev/null || true
fi
# How many packages apt will install with their dependencies, and how much it
# downloads: the denominators of the progress lines below.
plan=$(apt-get install -s --no-install-recommends "${missing[@]}" 2>>"$log") || fail "apt-get install -s"
total=$(grep -c '^Inst ' <<<"$plan" || true)
size=$($SUDO apt-get install --no-install-recommends --print-uris -qq "${missing[@]}" 2>>"$log" |
  awk '{s += $3} END {printf "%.0f", s / 1e6}') || size="?"
echo "install-deps: installing $total packages (the missing ones and their dependencies; $size MB to download)"
# --force-unsafe-io: dpkg skips its fsync after each unpacked file (what
# Debian's own container images do), which is much of the time of unpacking
# ~500 packages on a fresh machine; a power cut mid-install then needs the
# install re-run, which this script does anyway when a package is missing.
$SUDO apt-get install -y -q --no-install-recommends -o Dpkg::Use-Pty=0 -o Dpkg::Options::=--force-unsafe-io \
  "${missing[@]}" >>"$log" 2>&1 &
apt_pid=$!
# One line when the counts change, at most every 5 s.
last=""
while kill -0 "$apt_pid" 2>/dev/null; do
  got=$(grep -c '^Get:' "$log" || true)
  unpacked=$(grep -c '^Unpacking ' "$log" || true)
  setup=$(grep -c '^Setting up ' "$log" || true)
  now="downloaded $got, unpacked $unpacked, set up $setup of $total"
  if [[ "$now" != "$last" ]]; then
    # Nothing matches until apt's first download (a fresh machine): `|| true`
    # keeps set -e -o pipefail from ending the script while apt runs on.
    current=$(grep -E '^(Get:|Unpacking |Setting up )' "$log" | tail -1 | awk '{print ($1 == "Setting" ? $3 : ($1 == "Unpacking" ? $2 : $5))}' || true)
    echo "install-deps: $now${current:+ (now: $current)}"
    last="$now"
  fi
  for _ in 1 2 3 4 5 6 7 8 9 10; do kill -0 "$apt_pid" 2>/dev/null && sleep 0.5; done
done
wait "$apt_pid" || fail "apt-get install"
echo "install-deps: installed $total packages ($set_name set complete)"
install_npm_tools
