#!/usr/bin/env bash
# The cog-gpu test command (README "Testing"): installs what the tests need, then runs the whole suite,
# GPU tests included, on the machine's Vulkan adapter (Mesa lavapipe on a machine without a GPU).
#
#   bash tests/run.sh            # everything
#   bash tests/run.sh frame_io   # extra arguments go to `cargo test`
set -euo pipefail
cd "$(dirname "$0")/.."

# True when any Vulkan driver manifest (ICD) is installed.
have_vulkan_icd() {
    local icd
    for icd in /usr/share/vulkan/icd.d/*.json /etc/vulkan/icd.d/*.json; do
        [ -e "$icd" ] && return 0
    done
    return 1
}

if ! have_vulkan_icd; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "tests/run.sh: no Vulkan driver found; installing mesa-vulkan-drivers (lavapipe)"
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq
        apt-get install -y -qq mesa-vulkan-drivers >/dev/null
    else
        echo "tests/run.sh: no Vulkan driver and cannot apt-get install mesa-vulkan-drivers (need root + apt)." >&2
        echo "tests/run.sh: install a Vulkan driver, or set COG_GPU_SKIP_GPU_TESTS=1 to skip the GPU tests." >&2
        [ "${COG_GPU_SKIP_GPU_TESTS:-0}" = 1 ] || exit 1
    fi
fi

if [ ! -d ../shared/data/sunrgbd ]; then
    echo "tests/run.sh: ../shared/data/sunrgbd (the real SUN RGB-D sample frames) must sit beside the checkout" >&2
    exit 1
fi

# lavapipe's device-select layer warns about XDG_RUNTIME_DIR on headless machines; harmless.
export NODEVICE_SELECT=1
cargo test --locked "$@"
