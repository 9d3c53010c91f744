#!/usr/bin/env bash
# Frame rate of the web page's 3D viewer in headless Chromium on a job of
# its own: starts target/release/impostor-server (--no-auth, a temporary
# data folder, a free loopback port), submits SCENE with JOB and a bake,
# waits for it and runs tools/viewer-fps.py on it.
#
#   cargo build --release -p server
#   tools/viewer-fps.sh SCENE.glb JOB.json [FRAMES [TRIANGLES]]
set -euo pipefail
[ $# -ge 2 ] || { echo "usage: tools/viewer-fps.sh SCENE.glb JOB.json [FRAMES [TRIANGLES]]" >&2; exit 2; }
here=$(cd "$(dirname "$0")" && pwd)
server="$here/../target/release/impostor-server"
[ -x "$server" ] || { echo "viewer-fps: build the server first (cargo build --release -p server)" >&2; exit 2; }
data=$(mktemp -d)
port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
"$server" --no-auth --listen "127.0.0.1:$port" --data-dir "$data" >"$data/server.log" 2>&1 &
pid=$!
trap 'kill $pid 2>/dev/null; wait $pid 2>/dev/null; rm -rf "$data"' EXIT
base="http://127.0.0.1:$port"
for _ in $(seq 100); do curl -sf "$base/healthz" >/dev/null && break; sleep 0.2; done
id=$(curl -sf -F "scene=@$1" -F "job=@$2;type=application/json" -F bake=true "$base/v1/jobs" |
  python3 -c 'import json, sys; print(json.load(sys.stdin)["id"])')
echo "viewer-fps: job $id submitted; waiting for it" >&2
while :; do
  state=$(curl -sf "$base/v1/jobs/$id" | python3 -c 'import json, sys; print(json.load(sys.stdin)["state"])')
  case $state in
    succeeded) break ;;
    failed|cancelled) echo "viewer-fps: the job $state" >&2; curl -s "$base/v1/jobs/$id" >&2; exit 1 ;;
  esac
  sleep 1
done
python3 "$here/viewer-fps.py" "$base" "$id" "${3:-100}" ${4:+"$4"}
