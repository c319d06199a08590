#!/usr/bin/env bash
# Make sure the system libraries moderngl needs for headless rendering are present:
# libEGL (the GL vendor-neutral dispatch) and Mesa's EGL/DRI drivers (llvmpipe when there is no GPU).
# Installs them with apt-get when we are root on a Debian/Ubuntu machine; otherwise names what is missing.
set -uo pipefail

have_lib() { ldconfig -p 2>/dev/null | grep -q "$1"; }

missing=()
have_lib 'libEGL.so.1' || missing+=(libegl1)
have_lib 'libEGL_mesa.so.0' || missing+=(libegl-mesa0)
have_lib 'libGL.so.1' || missing+=(libgl1)
if ! ls /usr/lib/*/dri/swrast_dri.so /usr/lib/dri/swrast_dri.so >/dev/null 2>&1 \
   && ! ls /usr/lib/*/dri/kms_swrast_dri.so >/dev/null 2>&1; then
    missing+=(libgl1-mesa-dri)
fi

if [ ${#missing[@]} -eq 0 ]; then
    echo "system-deps: EGL and Mesa present"
    exit 0
fi

echo "system-deps: missing ${missing[*]}"
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq && apt-get install -y -qq "${missing[@]}" >/dev/null \
        && { echo "system-deps: installed ${missing[*]}"; exit 0; }
    echo "system-deps: apt-get could not install ${missing[*]}" >&2
else
    echo "system-deps: not root or no apt-get; install these Debian packages (or your system's EGL + Mesa): ${missing[*]}" >&2
fi
# Rendering commands will fail with a clear message; everything else still works.
exit 0
