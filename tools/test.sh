#!/bin/sh
# The test command (README): installs what the tests start for real
# (PostgreSQL from Debian's packages, the glTF validator, gltfpack, glTF
# Transform with Google's Draco encoder and the 3D Tiles client from npm,
# the client bundled by esbuild), runs the whole workspace's tests, then the
# service's HTTP tests again on PostgreSQL (the first run has them on SQLite).
set -eu
cd "$(dirname "$0")/.."
tools/install-test-deps.sh
npm ci --prefix tools/gltf-validator
npm ci --prefix tools/gltfpack
npm ci --prefix tools/gltf-draco
npm ci --prefix tools/tiles-client
node tools/tiles-client/build.mjs
npm ci --prefix tools/cesium-client
node tools/cesium-client/build.mjs
cargo test --workspace --release
# `--workspace` as above, so the same build is used (`-p server` alone would
# unify features differently and build everything a second time).
IMPOSTOR_TEST_DATABASE=postgres cargo test --workspace --release --test http --test admission
