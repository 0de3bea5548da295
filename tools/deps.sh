# Sourced by tools/demo.sh and tools/test.sh: makes sure Debian packages are installed.
# As root it installs what is missing with apt-get; otherwise it prints the exact command and fails.
tjepa_ensure_packages() {
  local missing=()
  local p
  for p in "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  if [ "$(id -u)" -eq 0 ]; then
    echo "tjepa: installing ${missing[*]}" >&2
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq >&2
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >&2
  else
    echo "tjepa: missing Debian packages. Install them with:" >&2
    echo "  sudo apt-get install -y ${missing[*]}" >&2
    exit 1
  fi
}

# Packages every build of tjepa's own targets needs.
TJEPA_BUILD_PACKAGES=(cmake ninja-build g++ ccache libeigen3-dev libxsimd-dev nlohmann-json3-dev
  doctest-dev libbenchmark-dev libcli11-dev libboost-dev)

# What the test suite needs beyond a build: Open MPI for the data-parallel tests (label dist).
TJEPA_TEST_PACKAGES=("${TJEPA_BUILD_PACKAGES[@]}" libopenmpi-dev openmpi-bin)
