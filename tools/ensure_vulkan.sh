#!/bin/sh
# `make demo` renders with offscreen GGUI, which needs a Vulkan loader and driver.
# On a machine without them (no GPU), Mesa's lavapipe renders on the CPU: install it
# when we can (root with apt-get), otherwise say how.
have_icd() {
  for d in /usr/share/vulkan/icd.d /etc/vulkan/icd.d /usr/local/share/vulkan/icd.d; do
    ls "$d"/*.json >/dev/null 2>&1 && return 0
  done
  return 1
}
if ldconfig -p 2>/dev/null | grep -q 'libvulkan.so.1' && have_icd; then
  exit 0
fi
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "Vulkan not found: installing mesa-vulkan-drivers (lavapipe, renders on the CPU)"
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
    mesa-vulkan-drivers libvulkan1 >/dev/null && exit 0
fi
echo "Vulkan not found. Install it with: sudo apt-get install mesa-vulkan-drivers libvulkan1" >&2
echo "(or run without video: .venv/bin/taichi-spheres run SCENE --no-video)" >&2
exit 1
