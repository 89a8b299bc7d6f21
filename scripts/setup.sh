#!/usr/bin/env bash
# Installs everything mop needs on a fresh Debian 12 / Python 3.11 machine, into ./.venv.
#   bash scripts/setup.sh          the application (demo, capture with the face, hands and pose
#                                  trackers, rendering)
#   bash scripts/setup.sh --test   also what the test suite needs (umockdev, Chromium, test data,
#                                  OpenCV's sample pictures)
# System libraries come from apt-get (as root, or through sudo); Python packages from pip.
set -euo pipefail
cd "$(dirname "$0")/.."

want_tests=0
[ "${1:-}" = "--test" ] && want_tests=1

apt_packages=(python3-venv python3-dev build-essential
              libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri libgles2)   # offscreen OpenGL via EGL
if [ "$want_tests" = 1 ]; then
    apt_packages+=(umockdev libumockdev-dev    # a HID device simulated in user space for end-to-end tests
                   libevdev2                   # loaded by hid-tools (the kernel's emulated gamepads)
                   chromium chromium-driver    # the live preview page, tested in a real browser
                   opencv-doc)                 # real photographs of hands, for the hands tracker
fi

missing=()
for package in "${apt_packages[@]}"; do
    dpkg -s "$package" >/dev/null 2>&1 || missing+=("$package")
done
if [ "${#missing[@]}" -gt 0 ]; then
    sudo=""
    [ "$(id -u)" = 0 ] || sudo="sudo"
    echo "setup: installing system packages: ${missing[*]}"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
extras="all"
[ "$want_tests" = 1 ] && extras="dev"
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".[$extras]"
# mop[vision]'s MediaPipe names the GUI OpenCV, which shares the cv2/ folder with the headless
# one: put the headless files back (same version, no GUI libraries needed)
headless=$(.venv/bin/python -m pip show opencv-contrib-python-headless | sed -n 's/^Version: //p')
.venv/bin/python -m pip install -q --force-reinstall --no-deps "opencv-contrib-python-headless==$headless"
if [ "$want_tests" = 1 ] && git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
    git config core.hooksPath scripts/hooks     # commit subjects under 72 characters
fi
echo "setup: done (.venv/bin/mop is the command)"
