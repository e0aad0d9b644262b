#!/bin/bash
# Run tests on arch=vulkan without a GPU, on Mesa 25's lavapipe (software Vulkan).
#
#   tools/vulkan_cpu_suite.sh [pytest node or file ...]     (default: the physics tests)
#
# Debian 12's own lavapipe (Mesa 22.3) runs integer atomics inside nested loops wrongly,
# so taichi_spheres refuses it for simulation (runtime.probe_loops; rendering is fine).
# Mesa 25 from bookworm-backports runs them right. This script fetches that driver into
# .cache/mesa25 (package checked against Debian's signed release files; nothing is
# installed system-wide) and points the Vulkan loader at it for the test processes only.
#
# One pytest process per test: under Taichi 1.7.4, Mesa 25's lavapipe crashes
# (segfault in vkAllocateDescriptorSets) after some tens of thousands of kernel launches in
# one process, which a long test or a whole file reaches. Tests parametrised to f64 are
# left out (slow on lavapipe; Vulkan runs f32 by default); tests that always run f64,
# such as the validation runs, still run. Results go to out/vulkan_suite.txt
# (exit status, seconds, test, pytest's summary line); the logs of failures beside it.
set -u
cd "$(dirname "$0")/.."
PY=${PYTHON:-.venv/bin/python}
# the Debian mirror this machine's apt uses (deb822 .sources or one-line lists;
# DEBIAN_MIRROR overrides it)
apt_mirror() {
    local uri
    uri=$(grep -hE '^URIs:' /etc/apt/sources.list.d/*.sources 2>/dev/null \
        | awk '{print $2}' | grep -v security | head -1)
    [ -n "$uri" ] || uri=$(grep -hE '^deb ' /etc/apt/sources.list /etc/apt/sources.list.d/*.list \
        2>/dev/null | awk '{print $2}' | grep -v security | head -1)
    echo "${uri%/}"
}
DIST=${DEBIAN_MIRROR:-$(apt_mirror)}
[ -n "$DIST" ] || { echo "no Debian mirror in the apt configuration: set DEBIAN_MIRROR" >&2; exit 1; }
SUITE=bookworm-backports
CACHE=.cache/mesa25
LIB=$CACHE/root/usr/lib/x86_64-linux-gnu
mkdir -p "$CACHE" out

fetch_driver() {
    local tmp=$CACHE/dl
    mkdir -p "$tmp"
    curl -fsS -o "$tmp/InRelease" "$DIST/dists/$SUITE/InRelease" || return 1
    gpgv --keyring /usr/share/keyrings/debian-archive-keyring.gpg "$tmp/InRelease" \
        2>/dev/null || { echo "InRelease: bad signature" >&2; return 1; }
    curl -fsS -o "$tmp/Packages.xz" "$DIST/dists/$SUITE/main/binary-amd64/Packages.xz" || return 1
    local want
    want=$(grep -E "^ [0-9a-f]{64} +[0-9]+ main/binary-amd64/Packages.xz$" "$tmp/InRelease" \
        | head -1 | awk '{print $1}')
    [ "$(sha256sum < "$tmp/Packages.xz" | awk '{print $1}')" = "$want" ] \
        || { echo "Packages.xz: checksum mismatch" >&2; return 1; }
    xz -dc "$tmp/Packages.xz" > "$tmp/Packages"
    for pkg in mesa-vulkan-drivers libdrm2 libdrm-amdgpu1; do
        local block file sum
        block=$(awk -v p="$pkg" '$0 == "Package: " p {on=1} on && /^$/ {exit} on' "$tmp/Packages")
        file=$(echo "$block" | awk '/^Filename:/ {print $2}')
        sum=$(echo "$block" | awk '/^SHA256:/ {print $2}')
        curl -fsS -o "$tmp/$pkg.deb" "$DIST/$file" || return 1
        [ "$(sha256sum < "$tmp/$pkg.deb" | awk '{print $1}')" = "$sum" ] \
            || { echo "$pkg: checksum mismatch" >&2; return 1; }
        dpkg-deb -x "$tmp/$pkg.deb" "$CACHE/root"
        echo "$pkg $(echo "$block" | awk '/^Version:/ {print $2}')"
    done
    sed "s#\"library_path\": \"[^\"]*\"#\"library_path\": \"$PWD/$LIB/libvulkan_lvp.so\"#" \
        "$CACHE/root/usr/share/vulkan/icd.d/lvp_icd.json" > "$CACHE/lvp_icd.json"
}

if [ ! -f "$CACHE/lvp_icd.json" ]; then
    fetch_driver || { echo "could not fetch Mesa 25's lavapipe from $DIST" >&2; exit 1; }
fi
export VK_ICD_FILENAMES=$PWD/$CACHE/lvp_icd.json
export LD_LIBRARY_PATH=$PWD/$LIB${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}

targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(tests/test_grid.py tests/test_gas.py tests/test_two_body.py tests/test_stiff.py)
out=out/vulkan_suite.txt
: > "$out"
for target in "${targets[@]}"; do
    for node in $("$PY" -m pytest --collect-only -q --arch vulkan "$target" 2>/dev/null \
                  | grep :: | grep -v f64); do
        t0=$(date +%s)
        # (in a subshell that is not replaced by the command, so that the shell's own
        # "Segmentation fault" goes to the log)
        ( timeout 600 "$PY" -m pytest -q -p no:cacheprovider --arch vulkan "$node"; exit $? ) \
            > out/vulkan_one.log 2>&1
        rc=$?
        summary=$(grep -E "passed|failed|skipped|error" out/vulkan_one.log | tail -1)
        echo "$rc $(( $(date +%s) - t0 ))s $node $summary" | tee -a "$out"
        if [ $rc -ne 0 ] && [ $rc -ne 5 ]; then
            cp out/vulkan_one.log "out/vulkan_fail_$(echo "$node" | tr '/:[]' '____').log"
        fi
    done
done
echo "passed: $(grep -c '^0 .* passed' "$out"), skipped: $(grep -c '^0 .* skipped' "$out"),"\
     "failed: $(grep -c '^1 ' "$out"), crashed or past 600 s: $(grep -cE '^(13[0-9]|12[4-9]) ' "$out")"\
     "(details: $out)"
