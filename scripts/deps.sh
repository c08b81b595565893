#!/usr/bin/env bash
# Installs the Debian 12 packages reshutter builds, tests and plots with; a no-op when all are present.
set -euo pipefail
packages=(
  build-essential cmake ninja-build pkg-config clang
  libopenexr-dev libtbb-dev libglm-dev libzstd-dev libxxhash-dev libcli11-dev zlib1g-dev libpng-dev libtiff-dev
  libosd-dev
  libgtest-dev libbenchmark-dev
  openimageio-tools gnuplot-nox jq time
  slurm-wlm iproute2
  libopenimageio-dev libembree-dev
  libopenvdb-dev libboost-dev
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "reshutter: installing ${missing[*]}" >&2
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  # Slurm's and munge's packages start their daemons on installation; the farm tests start their
  # own cluster instead, and on a machine without a slurm.conf the start fails and fails the
  # install. A policy-rc.d that denies service starts (Docker images ship one) prevents that.
  policy=""
  if [ ! -e /usr/sbin/policy-rc.d ]; then
    policy=/usr/sbin/policy-rc.d
    printf '#!/bin/sh\nexit 101\n' | $SUDO tee "$policy" >/dev/null && $SUDO chmod +x "$policy"
  fi
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null || { [ -z "$policy" ] || $SUDO rm -f "$policy"; exit 1; }
  [ -z "$policy" ] || $SUDO rm -f "$policy"
fi
