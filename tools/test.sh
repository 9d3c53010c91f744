#!/bin/sh
# The test command (README): installs what the tests start for real
# (PostgreSQL from Debian's packages, the glTF validator and gltfpack from npm), runs
# the whole workspace's tests, then the service's HTTP tests again on
# PostgreSQL (the first run has them on SQLite).
set -eu
cd "$(dirname "$0")/.."
tools/install-test-deps.sh
npm ci --prefix tools/gltf-validator
npm ci --prefix tools/gltfpack
cargo test --workspace --release
IMPOSTOR_TEST_DATABASE=postgres cargo test --release -p server --test http --test admission
