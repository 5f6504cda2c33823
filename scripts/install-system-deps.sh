#!/usr/bin/env bash
# System packages sot-apps needs on Debian/Ubuntu (only the missing ones are installed):
#  - Mesa's software EGL, for pyrender's offscreen camera rendering (PYOPENGL_PLATFORM=egl);
#  - Chromium, for the test that opens the demo's HTML report headless;
#  - a C compiler (gcc, libc6-dev), for the compiled ray-casting loop that pip install builds
#    (sot_apps/lidar_sim/_embree_trace.c; without it ray casting falls back to embreex, 2x slower).
# Uses sudo when not run as root. On other systems install the equivalents by hand.
set -euo pipefail
PACKAGES="libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri libgbm1 chromium gcc libc6-dev"
if ! command -v dpkg >/dev/null 2>&1 || ! command -v apt-get >/dev/null 2>&1; then
  echo "install-system-deps: not a Debian/Ubuntu system; install Mesa EGL, Chromium and a C compiler yourself" >&2
  exit 0
fi
missing=""
for p in $PACKAGES; do
  dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"
done
[ -z "$missing" ] && exit 0
SUDO=""
[ "$(id -u)" = "0" ] || SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
# Ubuntu ships Chromium as a snap; its apt package is a stub there, so fall back to chromium-browser.
$SUDO apt-get install -y -qq --no-install-recommends $missing || \
  $SUDO apt-get install -y -qq --no-install-recommends ${missing/chromium/chromium-browser}
