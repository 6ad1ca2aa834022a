#!/usr/bin/env bash
# Re-fetches the pinned three.js files `soda view` serves (web/vendor/three-VERSION/) from the
# npm registry and checks the package's checksum. The files are committed, so neither the
# build nor the tests need this script; run it only to verify or to move to another version
# (then change VERSION, SHA256 and the paths in src/cli/view/assets.rs and web/index.html).
set -euo pipefail
cd "$(dirname "$0")/.."
VERSION=0.170.0
SHA256=4a608a355dcaba72e0e5383cdc814303f5b6060b43c238cdf6932dceb699238d
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
(cd "$work" && npm pack --silent "three@$VERSION" >/dev/null)
echo "$SHA256  $work/three-$VERSION.tgz" | sha256sum --check --quiet
tar xzf "$work/three-$VERSION.tgz" -C "$work"
dest=web/vendor/three-$VERSION
mkdir -p "$dest"
cp "$work/package/build/three.module.min.js" "$work/package/examples/jsm/controls/OrbitControls.js" \
   "$work/package/LICENSE" "$dest/"
echo "three.js $VERSION in $dest"
