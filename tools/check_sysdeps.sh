#!/bin/sh
# Headless rendering needs libEGL + Mesa's software rasteriser (llvmpipe) or a GPU driver; the
# viewer's tests (serenity view under a virtual X server) need Xvfb (xvfb-run, xauth), GLX and the
# X libraries GLFW loads, and xdotool to send real key and mouse events.
# On Debian/Ubuntu as root, install them; otherwise say exactly what to install.
PKGS="libegl1 libgl1-mesa-dri libgles2"
VIEW_PKGS="xvfb xauth xdotool libgl1 libglx-mesa0 libx11-6 libxrandr2 libxinerama1 libxcursor1 libxi6"
have_gl() {
  ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1' && \
    { ls /usr/lib/*/dri/swrast_dri.so /usr/lib/*/dri/*_dri.so >/dev/null 2>&1 || ldconfig -p | grep -q libEGL_nvidia; }
}
have_view() {
  command -v xvfb-run >/dev/null 2>&1 && command -v xauth >/dev/null 2>&1 && command -v xdotool >/dev/null 2>&1 && \
    ldconfig -p 2>/dev/null | grep -q 'libGLX_mesa.so.0\|libGLX_nvidia.so.0' && ldconfig -p | grep -q 'libXrandr.so.2'
}
if have_gl && have_view; then
  exit 0
fi
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
  echo "Installing headless OpenGL libraries and the virtual X server: $PKGS $VIEW_PKGS"
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $PKGS $VIEW_PKGS >/dev/null && exit 0
fi
if have_gl; then
  echo "The viewer's test needs a virtual X server (it is skipped without one). Install: sudo apt-get install $VIEW_PKGS" >&2
  exit 0
fi
echo "Serenity needs headless OpenGL (EGL + Mesa). Install: sudo apt-get install $PKGS $VIEW_PKGS" >&2
exit 1
