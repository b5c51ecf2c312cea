#!/bin/sh
# Headless rendering needs libEGL + Mesa's software rasteriser (llvmpipe) or a GPU driver.
# On Debian/Ubuntu as root, install them; otherwise say exactly what to install.
PKGS="libegl1 libgl1-mesa-dri libgles2"
if ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1' && \
   { ls /usr/lib/*/dri/swrast_dri.so /usr/lib/*/dri/*_dri.so >/dev/null 2>&1 || ldconfig -p | grep -q libEGL_nvidia; }; then
  exit 0
fi
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
  echo "Installing headless OpenGL libraries: $PKGS"
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $PKGS >/dev/null && exit 0
fi
echo "Serenity needs headless OpenGL (EGL + Mesa). Install: sudo apt-get install $PKGS" >&2
exit 1
