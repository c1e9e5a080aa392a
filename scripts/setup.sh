#!/usr/bin/env bash
# Installs what poseforest needs on Debian 12 with apt-get, only if something is missing.
# Idempotent and fast when everything is there (one dpkg query).
#   scripts/setup.sh            everything (training + runtime + tests)
#   scripts/setup.sh --runtime  just the runtime: compiler, CMake, Eigen, libspng, nlohmann-json, CLI11 (+ Catch2 for its tests,
#                               pybind11 + NumPy for the optional Python module)
set -euo pipefail

runtime_pkgs=(g++ make cmake pkg-config libeigen3-dev catch2
  libspng-dev zlib1g-dev                      # PNG files (libspng over zlib: the runtime library and `poseforest`)
  nlohmann-json3-dev                          # JSON written by the runtime's commands (header-only)
  libcli11-dev                                # every command's options and --help (header-only)
  python3-dev python3-pybind11 python3-numpy  # the optional Python module and its test (consumer_python)
  libcpp-httplib-dev                          # `live --http` (optional here); the coordinator's status server (training)
)
training_pkgs=(
  libprotobuf-dev protobuf-compiler         # job configs and wire messages
  libfastrtps-dev fastdds-tools             # Fast DDS 2.9 (coordinator <-> workers)
  libassimp-dev assimp-testmodels           # rigged meshes (+ CMU BVH test clips)
  libegl-dev libgles-dev libegl-mesa0 libgl1-mesa-dri  # headless EGL/GLES (Mesa llvmpipe on CPU)
  python3 iproute2 bzip2 openssl            # test helpers, network namespaces, PCL trees, DDS-Security certs
  libssl-dev curl                           # HTTPS of the coordinator's status server; test_https's second client
  python3-yaml                              # test_deploy: reads deploy/k8s manifests
  docker-compose                            # test_deploy: `docker-compose config` renders deploy/compose.yaml (no engine needed)
  chromium                                  # the coordinator dashboard's headless-browser test
  prometheus                                # promtool: test_monitoring checks /metrics (its server is not started)
  python3-sklearn python3-matplotlib        # bench/train's side-by-side learner, docs plots (/usr/bin/python3)
  libfreenect-dev libfreenect-bin           # optional Kinect v1 back end + fakenect (its replay library) for test_freenect
  libopenni2-dev                            # optional OpenNI2 back end (test_openni2 uses its Dummy driver)
  g++-aarch64-linux-gnu qemu-user           # scripts/cross-arm64.sh: the runtime for 64-bit ARM, tested under qemu
)

pkgs=("${runtime_pkgs[@]}")
if [[ "${1:-}" != "--runtime" ]]; then
  pkgs+=("${training_pkgs[@]}")
  # test_live_dds decodes `live --dds` with Foxglove's npm packages: Debian's Node.js and npm,
  # unless a node and an npm are already there (another Node.js install conflicts with them).
  if ! command -v node >/dev/null || ! command -v npm >/dev/null; then pkgs+=(nodejs npm); fi
  # test_deploy renders deploy/k8s with `kubectl kustomize`: Debian's kubectl, unless a kubectl
  # is already there (another kubectl package owns /usr/bin/kubectl too).
  if ! command -v kubectl >/dev/null; then pkgs+=(kubernetes-client); fi
fi

missing=()
installed=$(dpkg-query -W -f='${db:Status-Status} ${Package}\n' "${pkgs[@]}" 2>/dev/null || true)
for p in "${pkgs[@]}"; do
  grep -qx "installed $p" <<<"$installed" || missing+=("$p")
done

if ((${#missing[@]} == 0)); then
  echo "setup: all ${#pkgs[@]} packages present"
  exit 0
fi
echo "setup: installing ${missing[*]}"
SUDO=""
if [[ $(id -u) -ne 0 ]]; then
  command -v sudo >/dev/null || { echo "setup: need root (or sudo) to apt-get install: ${missing[*]}" >&2; exit 1; }
  SUDO=sudo
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
