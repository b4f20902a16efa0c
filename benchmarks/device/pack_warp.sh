#!/usr/bin/env bash
# warp-lang (MuJoCo Warp's runtime) for a lent GPU machine in two parts, each small enough for one device call's
# carry: the wheel without its CPU compiler (warp-clang.so), examples and tests, as one tar.xz split into
# .warp/a and .warp/b, each with the parts' SHA256SUMS. gpu_benchmarks.sh installs it once both parts are there.
#   bash benchmarks/device/pack_warp.sh [VERSION]     (default 1.19.0; xz takes about 5 minutes on one core)
set -euo pipefail
cd "$(dirname "$0")/../.."
version=${1:-1.19.0}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    --platform manylinux_2_28_x86_64 -d "$tmp" "warp-lang==$version"
(
    cd "$tmp"
    unzip -q warp_lang-*.whl
    tar -cf - --exclude=warp/bin/warp-clang.so --exclude=warp/examples --exclude=warp/tests \
        warp warp_lang-*.dist-info | nice xz -T0 -6 >warp.tar.xz
    # 58 MiB leaves room for the repository in the first call's 64 MiB
    split -b 58M warp.tar.xz warp.tar.xz.
    sha256sum warp.tar.xz.* >SHA256SUMS
)
parts=("$tmp"/warp.tar.xz.*)
[ ${#parts[@]} = 2 ] || { echo "expected 2 parts, got ${#parts[@]}: add a call to benchmarks/device/README.md" >&2; exit 1; }
rm -rf .warp
mkdir -p .warp/a .warp/b
mv "${parts[0]}" .warp/a/
mv "${parts[1]}" .warp/b/
cp "$tmp/SHA256SUMS" .warp/a/
cp "$tmp/SHA256SUMS" .warp/b/
du -sh .warp/a .warp/b
